"""LegTable.where: where driving vehicles are, for many at once, exactly as Leg.next_at says
one at a time (random legs, times before the start, on a node's instant, part-way along an
edge, past the end; legs replaced and longer than the table)."""

from __future__ import annotations

import numpy as np

from dispatch.api.legs import Leg
from dispatch.plan.en_route import LegTable


class _Vehicle:
    def __init__(self, leg, start, loc=None):
        self._leg, self.leg_start, self.loc = leg, start, loc


def _leg(rng) -> Leg:
    n = int(rng.integers(1, 40))
    steps = rng.choice([0.0, 10.0, 20.0, 7.25], size=n)  # repeats make exact instants common
    start = float(rng.choice([0.0, 3.5, 20.0]))  # seconds to the first node (mid-edge start)
    times = start + np.concatenate([[0.0], np.cumsum(steps[1:])])
    nodes = rng.integers(0, 400, size=n).astype(np.int64)
    prev = int(rng.choice([-1, 5])) if start > 0 else -1
    return Leg(nodes, times, times * 10.0, prev)


def test_where_equals_next_at_leg_by_leg():
    rng = np.random.default_rng(3)
    fleet = 30
    vehicles = [_Vehicle(_leg(rng), float(rng.integers(0, 100))) for _ in range(fleet)]
    # what the fleet keeps for the table (the vehicle's leg setter): driving, leg versions
    driving = np.ones(fleet, dtype=bool)
    version = np.zeros(fleet, dtype=np.int64)
    table = LegTable(fleet, driving, version, width=4)  # legs outgrow it

    def stands(loc):  # stopped off a node: a stand-in answer of the space
        return loc, 2.5, True

    for decision in range(300):
        for i, v in enumerate(vehicles):
            if rng.random() < 0.2:  # a new leg (or a stop part-way along an edge)
                v._leg = None if rng.random() < 0.2 else _leg(rng)
                v.leg_start, v.loc = float(rng.integers(0, 100)), int(rng.integers(0, 400))
                driving[i] = v._leg is not None
                version[i] += 1
        now = float(rng.integers(0, 400)) + float(rng.choice([0.0, 0.5, 0.25]))
        idx = np.sort(rng.choice(fleet, size=int(rng.integers(1, fleet)), replace=False))
        looked = sorted(rng.choice(idx.size, size=int(rng.integers(0, idx.size + 1)),
                                   replace=False).tolist())
        node = np.full(idx.size, -7, dtype=np.int64)
        rem = np.full(idx.size, -7.0)
        points = table.where(vehicles, idx, looked, node, rem, now, stands=stands)
        want_points = []
        for k in looked:
            v = vehicles[int(idx[k])]
            if v._leg is None:
                want = (v.loc, 2.5, False)
            else:
                want = v._leg.next_at(now - v.leg_start)
            assert (node[k], rem[k]) == want[:2], (decision, k, want)
            if not want[2]:
                want_points.append(k)
        untouched = np.setdiff1d(np.arange(idx.size), looked)
        assert (node[untouched] == -7).all() and (rem[untouched] == -7.0).all()
        assert points.tolist() == want_points and points.dtype == np.int64
