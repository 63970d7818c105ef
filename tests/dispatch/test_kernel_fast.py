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


def test_recorder_columns_equal_pa_array():
    """The recorder's numpy-built columns are the arrays ``pa.array`` makes, and whatever is
    not a plain float / int / bool / str column still goes through ``pa.array`` (same result,
    same errors)."""
    import pyarrow as pa

    from dispatch.recorder import arrow_column

    nan, inf = float("nan"), float("inf")
    cases = [
        ((1.5, nan, -inf, 0.0, -0.0, 1e308), pa.float64()),
        ((), pa.float64()),
        ((3, -2**63, 2**63 - 1, 0), pa.int64()),
        ((True, False, True, True, False, False, True, False, True), pa.bool_()),
        (("release", "", "dépôt ✓", "x" * 300), pa.string()),
        ((1, 2.5), pa.float64()),  # an int in a float column: pa.array's conversion
        ((None, 1.0), pa.float64()),  # a null
        ((np.float64(2.0), 1.0), pa.float64()),
        ((True, 1), pa.int64()),
    ]
    for values, typ in cases:
        try:
            want = pa.array(values, typ)
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, OverflowError) as e:
            with pytest.raises(type(e)):
                arrow_column(values, typ)
            continue
        got = arrow_column(values, typ)
        got.validate(full=True)
        assert got.type == want.type and got.null_count == want.null_count
        gl, wl = got.to_pylist(), want.to_pylist()
        assert len(gl) == len(wl)
        for a, b in zip(gl, wl):  # equal values, NaN where NaN, the sign of a zero kept
            assert repr(a) == repr(b)
    with pytest.raises(OverflowError):
        arrow_column((2**64,), pa.int64())


@pytest.mark.parametrize("value", ["city_day-fcfs__s0", "", "é ✓"])
@pytest.mark.parametrize("n", [0, 1, 7])
def test_recorder_constant_column(value, n):
    import pyarrow as pa

    from dispatch.recorder import _Same, arrow_column

    got = arrow_column(_Same(value, n), pa.string())
    got.validate(full=True)
    assert got.equals(pa.array([value] * n, pa.string()))
