"""The road space's small types: where a vehicle is, and a drive along a node path.

They stand below the road space (:class:`dispatch.space.roads.RoadNetwork`) and below its parts
(drivers, congestion, vehicles, planners), which hold points and legs without needing the
space. A location on roads is a node index (``int``) or, for a vehicle, a :class:`RoadPoint`.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["Leg", "RoadPoint", "as_point"]


@dataclass(frozen=True, slots=True)
class RoadPoint:
    """Where a vehicle is: at node `node` (prev == -1, remaining == 0), or on the edge prev -> node
    with `remaining` seconds and `remaining_m` metres still to drive to `node`."""

    node: int
    prev: int = -1
    remaining: float = 0.0
    remaining_m: float = 0.0

    @property
    def on_node(self) -> bool:
        """True when the vehicle stands on ``node`` (nothing left to drive)."""
        return self.prev < 0 or self.remaining <= 0.0


def as_point(loc: RoadPoint | int) -> RoadPoint:
    """A node index (any integer type) or a point, as a point."""
    if isinstance(loc, RoadPoint):
        return loc
    return RoadPoint(int(loc))


@dataclass(frozen=True)
class Leg:
    """A drive along a node path: nodes[0] is where it starts (the point's `node`),
    times[i] / metres[i] are the cumulative seconds / metres from the start point to nodes[i]
    (times[0] = point.remaining).

    ``prev`` is the start point's ``prev`` (``-1`` when the leg starts on a node): needed to say
    where a vehicle is before it reaches ``nodes[0]``.
    """

    nodes: np.ndarray  # int64
    times: np.ndarray  # float64
    metres: np.ndarray  # float64
    prev: int = -1

    # cached: the operator reads them several times per leg (a leg's arrays are not written
    # after it is made)
    @cached_property
    def seconds(self) -> float:
        """Seconds from the start point to the last node."""
        return float(self.times[-1])

    @cached_property
    def length(self) -> float:
        """Metres from the start point to the last node."""
        return float(self.metres[-1])

    def _lists(self) -> tuple[list, list, list]:
        # Python lists (made once per leg): a vehicle's position is asked at every decision
        # while it drives, and bisect on a list is ~10x cheaper than numpy calls on scalars;
        # the arithmetic is the same IEEE double operations as on the arrays
        cached = self.__dict__.get("_as_lists")
        if cached is None:
            cached = tuple(np.asarray(a).tolist() for a in (self.times, self.nodes, self.metres))
            object.__setattr__(self, "_as_lists", cached)
        return cached

    def next_at(self, t: float) -> tuple[int, float, bool]:
        """``(node, remaining, on_node)`` of :meth:`point_at` (the node it stands on or drives
        to, the seconds left to it, whether it stands on it; remaining 0 then), without
        building the point: a decision asks it of every driving vehicle."""
        times, nodes, _ = self._lists()
        if t >= times[-1]:
            return nodes[-1], 0.0, True
        t = max(float(t), 0.0)
        i = bisect_right(times, t)
        if i == 0:
            rem = times[0] - t
            on = self.prev < 0 or rem <= 0.0
            return nodes[0], 0.0 if on else rem, on
        if t == times[i - 1]:
            return nodes[i - 1], 0.0, True
        rem = times[i] - t
        return nodes[i], rem if rem > 0.0 else 0.0, rem <= 0.0

    def point_at(self, t: float) -> RoadPoint:
        """Where a vehicle driving the leg is ``t`` seconds after its start: linear in time along
        the edge it is on; the last node from ``t >= seconds`` on; a node when ``t`` is exactly
        the arrival time there."""
        times, nodes, metres = self._lists()
        if t >= times[-1]:
            return RoadPoint(nodes[-1])
        t = max(float(t), 0.0)
        i = bisect_right(times, t)  # times[i-1] <= t < times[i]
        if i == 0:  # still finishing the edge the leg started on
            rem = times[0] - t
            rem_m = metres[0] * rem / times[0]
            return RoadPoint(nodes[0], self.prev, rem, rem_m)
        if t == times[i - 1]:
            return RoadPoint(nodes[i - 1])
        span = times[i] - times[i - 1]
        rem = times[i] - t
        return RoadPoint(nodes[i], nodes[i - 1], rem, (metres[i] - metres[i - 1]) * rem / span)
