"""Congestion on roads in a run: free-flow travel times scaled by the hour's factor.

The factors and their calibration are :mod:`dispatch.files.hourly`'s. A network's
edge times are free-flow times. With congestion on (``[world] congestion``), a drive that starts
at simulated time ``t`` takes ``factor(t)`` times its free-flow time. The scaling is uniform over
the network, so the fastest route is the free-flow one; only its duration changes:

* the planner's costs at a decision at time ``t`` are ``remaining + factor(t) x free-flow``
  (``remaining``: seconds a vehicle still has on the edge it is driving, already real seconds;
  :class:`CongestedPlanner`);
* a vehicle's leg (to a pickup, to a drop-off) is timed with the factor of the hour it
  **departs** in, for the whole leg (:class:`CongestedDriver`): a leg that crosses an hour
  boundary keeps its departure hour's factor (legs last minutes, hours change slowly; a
  per-edge time-dependent model would break the exact shortest-path costs the dispatcher
  relies on).

:func:`road_driver` builds a road run's driver from its ``[world]`` table: the plain
:class:`~dispatch.space.drivers.RoadDriver`, or with congestion these two. The road network
(:class:`dispatch.space.roads.RoadNetwork`) builds its driver here, so this module knows it only as
the :class:`~dispatch.api.space.Space` it is given.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from dispatch.api.contracts import Planner
from dispatch.api.legs import Leg, RoadPoint
from dispatch.api.problem import AgentViews
from dispatch.api.space import Space
from dispatch.files.hourly import HourlyFactors
from dispatch.space.drivers import RoadDriver


def scale_leg(leg: Leg, factor: float) -> Leg:
    """``leg`` with its edge times multiplied by ``factor``; the seconds left on the edge it
    starts on (``times[0]``, already real seconds) are kept."""
    if factor == 1.0:
        return leg
    times = leg.times[0] + (leg.times - leg.times[0]) * factor
    return Leg(leg.nodes, times, leg.metres, leg.prev)


class CongestedDriver(RoadDriver):
    """A :class:`~dispatch.space.drivers.RoadDriver` whose legs take ``factor(departure time)``
    times their free-flow seconds (see the module docstring)."""

    def __init__(self, network: Space, planner: Any, bus: Any, edge_events: bool,
                 congestion: HourlyFactors) -> None:
        super().__init__(network, planner, bus, edge_events)
        self.congestion = congestion

    def plan(self, v: Any, goal: Any, now: float) -> Leg:
        return scale_leg(super().plan(v, goal, now), self.congestion.factor(now))


class CongestedPlanner(Planner):
    """Wraps a road planner: its costs at simulated time ``clock()`` become
    ``remaining + factor(clock()) x (free-flow cost - remaining)``; paths, statistics and
    ``task_closed`` are the wrapped planner's, and so are its name, the spaces it serves and
    its ``travel_times``. Lower bounds and timed routes are not passed on (the wrapped
    planner's would be free-flow ones)."""

    def __init__(self, inner: Planner, congestion: HourlyFactors,
                 clock: Callable[[], float]) -> None:
        self.name, self.spaces = inner.name, inner.spaces
        super().__init__(inner.space)
        self.stats = inner.stats  # one planner's counters: the wrapped one's
        self.travel_times = inner.travel_times
        self.inner, self.congestion, self.clock = inner, congestion, clock
        # a cost is the free-flow one scaled by the hour's factor (the edge part-way driven
        # aside, which only adds): at least the smallest factor times the wrapped one's floor
        self.drive_floor = None if inner.drive_floor is None \
            else inner.drive_floor * min(congestion.factors)

    @property
    def free_flow(self) -> Planner:
        return self.inner

    def plan(self, agent: Any, goal: Any) -> Any:
        return self.inner.plan(agent, goal)

    def task_closed(self, task_id: int) -> None:
        self.inner.task_closed(task_id)

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
        rem = agents.remaining if isinstance(agents, AgentViews) else None
        if rem is None:  # views given by hand (the dispatcher's carry the array)
            rem = np.fromiter((max(a.loc.remaining, 0.0) if isinstance(a.loc, RoadPoint)
                               else 0.0 for a in agents), np.float64, len(agents))
        rem = rem[:, None]
        return rem + (cost - rem) * f


def road_driver(network: Space, planner: Any, bus: Any, cfg: Any, clock) -> RoadDriver:
    """The road driver of a ``[world]`` configuration; with ``[world] congestion`` the
    planner's costs and the legs are scaled by the hour's factor (this module's;
    the driver's ``planner`` is then the wrapped one, and its metadata names the factors)."""
    factors = cfg.roads.congestion
    if not factors:
        return RoadDriver(network, planner, bus, cfg.edge_events)
    import json

    hourly = HourlyFactors(factors)
    driver = CongestedDriver(network, CongestedPlanner(planner, hourly, clock), bus,
                             cfg.edge_events, hourly)
    driver.metadata["dispatch.congestion"] = json.dumps(list(factors), sort_keys=True)
    return driver
