"""Congestion on roads: free-flow travel times scaled by a factor per hour of the day.

A network's edge times are free-flow times. With congestion on (``[world] congestion``), a
drive that starts at simulated time ``t`` takes ``factor(t)`` times its free-flow time, where
``factor(t) = factors[floor(t / 3600) mod 24]`` (the run starts at midnight). The scaling is
uniform over the network, so the fastest route is the free-flow one; only its duration changes:

* the planner's costs at a decision at time ``t`` are ``remaining + factor(t) x free-flow``
  (``remaining``: seconds a vehicle still has on the edge it is driving, already real seconds);
* a vehicle's leg (to a pickup, to a drop-off) is timed with the factor of the hour it
  **departs** in, for the whole leg: a leg that crosses an hour boundary keeps its departure
  hour's factor (legs last minutes, hours change slowly; a per-edge time-dependent model
  would break the exact shortest-path costs the dispatcher relies on).

:func:`calibrate` estimates the 24 factors from observed trips: the ratio of each trip's
observed seconds to the network's free-flow shortest-path time between its snapped pickup and
drop-off nodes, robustly (the median) per hour of day; an hour with fewer than ``min_trips``
usable trips is pooled with its neighbours (hours h-1..h+1, then h-2..h+2, ..., circularly)
until the pool has enough. ``dispatch/data/chicago_taxi/congestion.csv`` holds the factors
calibrated from the Chicago taxi sample (``scripts/make_chicago_taxi.py`` writes it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dispatch.roads import Leg, RoadNetwork, RoadPoint
from dispatch.vehicles import RoadDriver

HOURS = 24
#: Fewest usable trips behind one hour's factor before neighbouring hours are pooled in.
MIN_TRIPS = 200


@dataclass(frozen=True)
class HourlyFactors:
    """24 positive factors, one per hour of day (index 0: 00:00-01:00)."""

    factors: tuple[float, ...]

    def __post_init__(self) -> None:
        f = self.factors
        if len(f) != HOURS or any(not (math.isfinite(x) and x > 0) for x in f):
            raise ValueError(f"congestion needs {HOURS} finite factors > 0, got {list(f)!r}")

    def factor(self, t: float) -> float:
        """The factor of the hour of day that simulated time ``t`` (seconds) falls in."""
        return self.factors[math.floor(t / 3600.0) % HOURS]


NO_CONGESTION = HourlyFactors((1.0,) * HOURS)


def free_flow_times(net: RoadNetwork, origin: np.ndarray, dest: np.ndarray) -> np.ndarray:
    """Free-flow shortest-path seconds from node index ``origin[k]`` to ``dest[k]`` (one
    Dijkstra per distinct origin)."""
    origin, dest = np.asarray(origin, np.int64), np.asarray(dest, np.int64)
    src, inv = np.unique(origin, return_inverse=True)
    return net.distances_from(src)[inv, dest] if src.size else np.zeros(0)


def calibrate(net: RoadNetwork, origin: np.ndarray, dest: np.ndarray, hour: np.ndarray,
              seconds: np.ndarray, min_trips: int = MIN_TRIPS
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per hour of day: ``(factors, trips, widths)``: the median of observed / free-flow seconds
    over the trips of that hour (pooled with hours within ``widths[h]`` of it when the hour
    alone has fewer than ``min_trips``), and how many trips the median was taken over.

    Trips with ``origin == dest`` (no drive on the network) or ``seconds <= 0`` (not a
    measured ride) are left out. ``origin``, ``dest`` are node indices; ``hour`` in 0..23.
    ValueError when fewer than ``min_trips`` usable trips exist in the whole day."""
    origin, dest = np.asarray(origin, np.int64), np.asarray(dest, np.int64)
    hour, seconds = np.asarray(hour, np.int64), np.asarray(seconds, np.float64)
    use = (origin != dest) & (seconds > 0)
    ratio = seconds[use] / free_flow_times(net, origin[use], dest[use])
    hour = hour[use]
    if ratio.size < max(min_trips, 1):
        raise ValueError(f"calibrate: {ratio.size} usable trips, need at least {min_trips}")
    factors, trips, widths = np.empty(HOURS), np.empty(HOURS, np.int64), np.empty(HOURS, np.int64)
    for h in range(HOURS):
        for w in range(HOURS // 2 + 1):
            near = np.minimum((hour - h) % HOURS, (h - hour) % HOURS) <= w
            if near.sum() >= min_trips:
                break
        factors[h], trips[h], widths[h] = float(np.median(ratio[near])), int(near.sum()), w
    return factors, trips, widths


# ----------------------------------------------------------------------------- in a run


def scale_leg(leg: Leg, factor: float) -> Leg:
    """``leg`` with its edge times multiplied by ``factor``; the seconds left on the edge it
    starts on (``times[0]``, already real seconds) are kept."""
    if factor == 1.0:
        return leg
    times = leg.times[0] + (leg.times - leg.times[0]) * factor
    return Leg(leg.nodes, times, leg.metres, leg.prev)


class CongestedDriver(RoadDriver):
    """A :class:`~dispatch.vehicles.RoadDriver` whose legs take ``factor(departure time)``
    times their free-flow seconds (see the module docstring)."""

    def __init__(self, network: RoadNetwork, planner: Any, bus: Any, edge_events: bool,
                 congestion: HourlyFactors) -> None:
        super().__init__(network, planner, bus, edge_events)
        self.congestion = congestion

    def plan(self, v: Any, goal: Any, now: float) -> Leg:
        return scale_leg(super().plan(v, goal, now), self.congestion.factor(now))


class CongestedPlanner:
    """Wraps a road planner: its costs at simulated time ``clock()`` become
    ``remaining + factor(clock()) x (free-flow cost - remaining)``; everything else (paths,
    statistics, ``task_closed``) is the wrapped planner's."""

    def __init__(self, inner: Any, congestion: HourlyFactors, clock: Callable[[], float]) -> None:
        self.inner, self.congestion, self.clock = inner, congestion, clock

    def __getattr__(self, name: str) -> Any:  # name, stats, spaces, plan, task_closed, ...
        return getattr(self.inner, name)

    def between(self, sources: Sequence[Any], targets: Sequence[Any],
                pairwise: bool = False) -> np.ndarray:
        """The wrapped planner's travel times at the hour's factor (the remaining part of an
        edge a source is on is not scaled, as in :meth:`costs`)."""
        cost = self.inner.between(sources, targets, pairwise)
        f = self.congestion.factor(self.clock())
        if f == 1.0 or not len(sources):
            return cost
        rem = np.fromiter((max(a.remaining, 0.0) if isinstance(a, RoadPoint) else 0.0
                           for a in sources), np.float64, len(sources))
        if not pairwise:
            rem = rem[:, None]
        return rem + (cost - rem) * f

    def costs(self, agents: Sequence[Any], tasks: Sequence[Any]) -> np.ndarray:
        cost = self.inner.costs(agents, tasks)
        f = self.congestion.factor(self.clock())
        if f == 1.0 or not len(agents):
            return cost
        rem = getattr(agents, "remaining", None)  # AgentViews: the array, no view built
        if rem is None:
            rem = np.fromiter((max(a.loc.remaining, 0.0) if isinstance(a.loc, RoadPoint)
                               else 0.0 for a in agents), np.float64, len(agents))
        rem = rem[:, None]
        return rem + (cost - rem) * f
