"""A request's ride (its drive from pickup to drop-off) as decisions time it: the trip's
free-flow ``direct_time``, the drive at this hour under congestion, and for a rider
transferred after a breakdown the drive from where the rider waits now."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dispatch.decide.plan_costs import ride_seconds


class Line:
    """A planner on a line: seconds = distance between integer locations x ``factor``."""

    def __init__(self, factor: float = 1.0) -> None:
        self.factor = factor
        self.free_flow = self if factor == 1.0 else Line()

    def between(self, a, b, pairwise=False):
        return np.abs(np.asarray(a, float) - np.asarray(b, float)) * self.factor


def _task(loc, dropoff, direct, transfers=0):
    return SimpleNamespace(loc=loc, dropoff=dropoff, direct_time=direct, transfers=transfers)


def test_ride_is_the_direct_time_unless_transferred_or_congested():
    # a trip 0 -> 10 (direct 10 s), a point task, and a trip 0 -> 10 whose rider was moved to
    # 4 by a breakdown (transferred): its ride is 6 s from there, its direct_time stays 10
    tasks = [_task(0, 10, 10.0), _task(5, None, float("nan")), _task(4, 10, 10.0, transfers=1)]
    assert ride_seconds(Line(), tasks).tolist() == [10.0, 0.0, 6.0]
    assert ride_seconds(Line(), tasks[:2], congested_only=True) is None
    assert ride_seconds(Line(), tasks, congested_only=True).tolist() == [10.0, 0.0, 6.0]
    # congestion: every trip at this hour's factor
    assert ride_seconds(Line(2.0), tasks).tolist() == [20.0, 0.0, 12.0]
