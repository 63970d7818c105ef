"""A vehicle's plan as one object: its stops in order, their planned times, the arrays a
decision reads of them, and every change a plan undergoes.

A :class:`Plan` belongs to one vehicle (:attr:`dispatch.plan.vehicles.Vehicle.plan`) and is
the only thing that changes its stops: the operator drives it
(:class:`dispatch.plan.operator.Operator`), a decision inserts into it (:meth:`Plan.insert`),
a multi-request route or a visit replaces it (:meth:`Plan.replace`), a breakdown, a
re-assignment or the cut of a repositioning move empties it (:meth:`Plan.clear`). Each change
bumps the vehicle's ``plan_version``, which is how the decisions' cached copies of the plan
(:meth:`Plan.arrays`, :class:`dispatch.decide.plan_costs.PlanTable`) know they are stale.
The times follow the one schedule rule (:mod:`dispatch.plan.stops`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from dispatch.plan.kinds import TABLE as KINDS
from dispatch.plan.stops import (DROPOFF, PICKUP, Stop, insert, leave, occupancies, pushed,
                                 schedule)

if TYPE_CHECKING:
    from dispatch.plan.insertion import Insertion
    from dispatch.plan.tasks import Task


def starts_now(heading_none, waiting, free_at, now: float):
    """Whether a plan's times start at ``now`` (the vehicle heads for no stop, or stands at
    its first stop waiting for the stop's ``earliest`` time, and is in no service), for one
    vehicle (bools) or many (numpy arrays): then its arrays are stale at every new ``now``
    even when its ``plan_version`` is not. The one place this rule is written:
    :meth:`Plan.arrays` keys its cache by it, and the decisions' plan table asks for a
    vehicle's arrays by it."""
    return (heading_none | waiting) & (free_at <= now)


def request_stops(task: Task, service: float) -> list[Stop]:
    """The stops of ``task``: its pickup (which completes a point task) and its drop-off (at
    its meeting points where it walks: :mod:`dispatch.decide.meeting`; a booked ride's pickup
    opens at its requested departure: :mod:`dispatch.decide.prebook`). ``service``: the
    seconds the stop that completes it takes."""
    n = task.passengers
    m = task.meeting
    if m is not None and not task.transfers:
        return [Stop(PICKUP, task, m.board, n, task.deadline, False, earliest=m.earliest),
                Stop(DROPOFF, task, m.alight, -n, m.latest_drop, True, service=service)]
    e = task.earliest_pickup
    if task.dropoff is None:
        return [Stop(PICKUP, task, task.loc, 0, task.deadline, True, service=service,
                     earliest=e)]
    return [Stop(PICKUP, task, task.loc, n, task.deadline, False, earliest=e),
            Stop(DROPOFF, task, task.dropoff, -n, task.dropoff_deadline, True, service=service)]


class Plan:
    """The stops a vehicle still has to make, in order (:attr:`stops`), read as a sequence
    (``len``, iteration, ``plan[0]``, truth), and changed only through its methods."""

    __slots__ = ("vehicle", "stops", "_cache")

    def __init__(self, vehicle) -> None:  # (a dispatch.plan.vehicles.Vehicle: it owns us)
        self.vehicle = vehicle
        self.stops: list[Stop] = []
        self._cache = None  # (key, arrays) of arrays()

    def __len__(self) -> int:
        return len(self.stops)

    def __bool__(self) -> bool:
        return bool(self.stops)

    def __iter__(self):
        return iter(self.stops)

    def __getitem__(self, k):
        return self.stops[k]

    # ------------------------------------------------------------------ reading
    def times(self, now: float) -> list[float]:
        """Planned arrival times at its stops: from the leg the vehicle drives to the first,
        or from when it can leave where it stands (``now``, or the end of a service)."""
        stops, v = self.stops, self.vehicle
        if not stops:
            return []
        if v.heading is stops[0] and v.leg is not None:
            first = v.leg_start + v.leg.seconds
        else:
            first = max(now, v.free_at) + stops[0].leg
        return schedule(first, stops)

    def arrays(self, now: float) -> tuple[list, list, list, list, list, list]:
        """The plan as a decision at ``now`` reads it: planned arrival times, service seconds
        of each stop, latest times, occupancies after each stop, locations, earliest times
        (lists; kept until the plan, the drive along it or, where its times start at
        ``now`` (:func:`starts_now`), the time changes)."""
        v = self.vehicle
        key = (v.plan_version,
               now if starts_now(v.heading is None, v.waiting, v.free_at, now) else None)
        cached = self._cache
        if cached is not None and cached[0] == key:
            return cached[1]
        stops = self.stops
        arrays = (self.times(now), [s.service for s in stops], [s.latest for s in stops],
                  [s.occupancy for s in stops], [s.loc for s in stops],
                  [s.earliest for s in stops])
        self._cache = (key, arrays)
        return arrays

    def kept(self) -> list[Stop]:
        """The stops a decision keeps: all of them, but none of a plan whose first stop a
        request cuts (a repositioning move)."""
        stops = self.stops
        return [] if stops and not KINDS[stops[0].kind].kept else stops

    def tasks(self) -> list[Task]:
        """The tasks its stops serve, each once, in plan order."""
        out: list = []
        for s in self.stops:
            if s.task is not None and s.task not in out:
                out.append(s.task)
        return out

    # ------------------------------------------------------------------ changes
    def changed(self) -> None:
        """Its stops, their occupancies or the drive along them changed: what decisions keep
        of it is stale, and the fleet learns whether a seat is free somewhere in it."""
        v = self.vehicle
        v.plan_version += 1
        low = v.load
        for s in self.stops:
            if s.occupancy < low:
                low = s.occupancy
        v.room = low < v.capacity

    def replace(self, stops: list[Stop], times: list[float] | None, now: float) -> None:
        """The plan becomes ``stops``, planned to be reached at ``times`` (each stop's
        ``leg`` is set from them; None: the stops keep theirs), their occupancies counted
        from the load on board."""
        if times is not None:
            self._set_legs(stops, times, now)
        self.stops = stops
        occupancies(self.vehicle.load, stops, self.vehicle.capacity)
        self.changed()

    def insert(self, new: list[Stop], at: Insertion, now: float) -> None:
        """Insert a request's stops ``new`` where the decision's insertion ``at`` puts them
        (the pickup after stop ``at.i``, the drop-off after ``at.j``: :func:`insert`): the
        stops after them are reached later, by what the insertion computed."""
        old = self.stops
        i, j = at.i, at.j
        times = pushed(self.times(now), old, i, j, at.shift1, at.shift2)
        times = insert(times, [at.pickup_at, at.dropoff_at][:len(new)], i, j)
        self.replace(insert(old, new, i, j), times, now)

    def put(self, stop: Stop, k: int, times: list[float], now: float) -> None:
        """Put ``stop`` (serving no request) before the plan's ``k``-th stop, the new plan
        planned to be reached at ``times``."""
        self.replace(self.stops[:k] + [stop] + self.stops[k:], times, now)

    def clear(self) -> None:
        """No stops left (a breakdown, a re-assignment, the cut of a move)."""
        self.stops = []
        self.changed()

    def done(self) -> Stop:
        """The first stop is made: it leaves the plan (the caller says :meth:`changed` once
        the vehicle's load is what the stop left)."""
        return self.stops.pop(0)

    def _set_legs(self, stops: list[Stop], times: list[float], now: float) -> None:
        """Each stop's ``leg`` from planned arrival ``times`` (what is not driving, waiting or
        service between two arrivals is the drive)."""
        t = max(now, self.vehicle.free_at)
        for s, arrive in zip(stops, times):
            s.leg = arrive - t
            t = leave(arrive, s.earliest, s.service)
