"""The kernel's fast paths give the same numbers as the plain code they replace."""

from __future__ import annotations

from itertools import accumulate
from pathlib import Path

import numpy as np
import pytest

from dispatch.roads import RoadPoint, load_network, manhattan


@pytest.fixture(scope="module")
def chicago():
    return load_network("chicago", base=Path("."))


def _python_leg(net, start, nodes):
    """The leg's cumulative seconds and metres summed in Python, edge by edge (scipy's CSR
    lookup), as the kernel did before it had a compiled helper."""
    p = start if isinstance(start, RoadPoint) else RoadPoint(int(start))
    secs = [max(p.remaining, 0.0)] + [float(net.time[a, b]) for a, b in zip(nodes, nodes[1:])]
    mets = [max(p.remaining_m, 0.0)] + [float(net.length[a, b])
                                        for a, b in zip(nodes, nodes[1:])]
    return list(accumulate(secs)), list(accumulate(mets))


@pytest.mark.parametrize("which", ["manhattan", "chicago"])
def test_compiled_legs_equal_python_sums_bit_for_bit(which, chicago):
    net = manhattan(9, 7, block=173.0, speed=7.3) if which == "manhattan" else chicago
    assert net._leg_sums is not None  # the compiled path serves these networks
    rng = np.random.default_rng(3)
    coo = net.time.tocoo()
    for k in range(40):
        src, dst = (int(x) for x in rng.integers(0, net.n, 2))
        route = net.route(src, dst)
        nodes = route.nodes.tolist()
        start = src
        if k % 2:  # start part-way along an edge into the path's first node
            into = np.flatnonzero(coo.col == nodes[0])
            e = int(into[rng.integers(into.size)]) if into.size else None
            if e is not None:
                f = float(rng.uniform(0.1, 0.9))
                start = RoadPoint(nodes[0], int(coo.row[e]), f * coo.data[e],
                                  f * net.length[coo.row[e], coo.col[e]])
        leg = net.leg(start, nodes)
        times, metres = _python_leg(net, start, nodes)
        assert leg.nodes.tolist() == nodes
        assert leg.times.tolist() == times and leg.metres.tolist() == metres  # exact
        assert leg.prev == (start.prev if isinstance(start, RoadPoint) else -1)


def test_compiled_legs_reject_what_the_python_path_rejects():
    net = manhattan(4, 4, block=100.0, speed=10.0)
    with pytest.raises(ValueError, match="no edge 0 -> 5"):
        net.leg(0, [0, 5])  # a diagonal: not an edge
    with pytest.raises(ValueError, match="must start there"):
        net.leg(0, [1, 2])
    with pytest.raises(ValueError, match="no edge"):
        net.leg(0, [0, 1, 99])  # not a node
