"""Vehicles, the fleet, and the SimPy processes that drive them along their plans.

A vehicle's plan is data: its stop list (:mod:`dispatch.stops`), which it owns. The
:class:`Operator` inserts a decision's stops into it and one SimPy process per busy vehicle
drives it stop by stop: to each stop, pick up or drop off (with capacity above 1 several
requests ride at once), the service time where a request completes, idle when the list is
empty. A breakdown or a re-assignment removes stops; nothing else changes the plan. What a
vehicle drove, and with how many on board, is counted in one place (:meth:`Vehicle.drove`).
How it drives depends on the space, through the *driver* its space makes
(:mod:`dispatch.drivers`: cell by cell in a voxel world, one timeout per leg on roads, where
a vehicle part-way through a leg is interpolated from its route when someone asks:
:meth:`Vehicle.location`).

How a vehicle sets out on a plan, is halted by a breakdown and is repaired is the operator's
*execution* (:class:`Execution`): its own plan process (:class:`PlanExecution`), or, with a
reservation-aware planner (voxel only, capacity 1), the timed drives of
:class:`dispatch.reservations.TimedExecution`, which follow routes that the run's
:class:`dispatch.reservations.Traffic` keeps conflict-free and owns.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import simpy

from dispatch.contracts import AgentView, AgentViews
from dispatch.events import EventBus
from dispatch.locations import Location
from dispatch.space import Space
from dispatch.stops import (CHARGE, DROPOFF, PICKUP, REPOSITION, TOL, PlannedStop, Stop, insert,
                            leave, occupancies, pushed, schedule, timetable)
from dispatch.tasks import COMPLETED, PICKED_UP as PICKED_UP_STATE, Task, TaskBook, TaskState

if TYPE_CHECKING:
    from dispatch.insertion import Insertion
    from dispatch.legs import Leg


@dataclass(eq=False)
class Vehicle:
    """A UAV, a UGV or a car. ``loc`` is where it is (on roads: the node it last reached;
    while it drives a leg, :meth:`location` interpolates)."""

    id: int
    kind: str
    speed: float
    start: Location
    busy: bool = False
    #: seats (``[fleet] capacity``); a request of more passengers than this never rides in it
    capacity: int = 1
    #: the plan: stops still to make, in order (see :mod:`dispatch.stops`); the vehicle's
    #: process drives it, decisions insert into it, breakdowns and re-assignments remove from it
    stops: list = field(default_factory=list, repr=False)
    load: int = 0  # passengers on board
    distance: float = 0.0  # metres travelled
    empty_distance: float = 0.0  # ... without a passenger (to pickups, repositioning)
    occupied_distance: float = 0.0  # ... with one or more on board
    passenger_distance: float = 0.0  # passenger-metres: metres times passengers on board
    #: in service at a stop until then (the stop's task completes at that time)
    free_at: float = -math.inf
    serving: Task | None = field(default=None, repr=False)  # ... that task
    #: the stop its current drive goes to (None: standing, serving or idle)
    heading: Any = field(default=None, repr=False)
    plan_version: int = 0  # bumped at every change of the plan or of the drive along it
    plan_cache: Any = field(default=None, repr=False)  # (key, arrays) of Operator.plan_arrays
    busy_seconds: float = 0.0
    busy_since: float = 0.0
    completed: int = 0
    # ---- roads: when the leg being driven (:attr:`leg`) started
    leg_start: float = 0.0
    # ---- faults (see dispatch.faults)
    failed: bool = False
    failures: int = 0
    down_seconds: float = 0.0
    down_since: float = 0.0
    proc: Any = field(default=None, repr=False)  # the SimPy process serving its trip
    #: ``[fleet.energy]``: its battery (:class:`dispatch.battery.Battery`); None without energy
    battery: Any = field(default=None, repr=False)
    _view: AgentView | None = field(default=None, repr=False)
    # ``loc`` and ``leg`` live here; their setters tell the fleet (its arrays stay current)
    _loc: Location = field(default=None, init=False, repr=False)
    _leg: Leg | None = field(default=None, init=False, repr=False)
    _fleet: Fleet | None = field(default=None, init=False, repr=False)
    _slot: int = field(default=-1, init=False, repr=False)

    def __post_init__(self) -> None:
        self._loc = self.start

    @property
    def loc(self) -> Location:
        """Where it is (on roads: the node it last reached, or a road point where it stopped
        part-way along an edge)."""
        return self._loc

    @loc.setter
    def loc(self, value: Location) -> None:
        self._loc = value
        if self._fleet is not None:
            self._fleet._moved(self._slot, value)

    @property
    def leg(self) -> Leg | None:
        """Roads: the leg it is driving (None when it stands)."""
        return self._leg

    @leg.setter
    def leg(self, value: Leg | None) -> None:
        self._leg = value
        fleet = self._fleet
        if fleet is not None:
            i = self._slot
            fleet.driving[i] = value is not None
            fleet.special[i] = value is not None or fleet._odd[i]

    @property
    def cell(self):
        """The voxel name of :attr:`loc`."""
        return self.loc

    @cell.setter
    def cell(self, value) -> None:
        self.loc = value

    @property
    def flies(self) -> bool:
        return self.kind == "uav"

    def drove(self, metres: float, seconds: float = 0.0) -> None:
        """Count ``metres`` driven (in ``seconds``) with the passengers now on board: the one
        place where a vehicle's distances grow, and where its battery is drawn."""
        if self.battery is not None:
            self.battery.drive(metres, seconds)
        self.distance += metres
        if self.load:
            self.occupied_distance += metres
            self.passenger_distance += metres * self.load
        else:
            self.empty_distance += metres

    def tasks(self) -> list[Task]:
        """The tasks of its plan (the one in service first), each once, in plan order."""
        out = [] if self.serving is None else [self.serving]
        for s in self.stops:
            if s.task is not None and s.task not in out:
                out.append(s.task)
        return out

    def location(self, now: float) -> Location:
        """Where it is at ``now``: on a leg, the road point reached by then."""
        if self.leg is not None:
            return self.leg.point_at(now - self.leg_start)
        return self.loc

    def view(self, now: float | None = None) -> AgentView:
        """What a decision at ``now`` sees of it (kept while it stands still: a fleet of idle
        vehicles is viewed at every decision)."""
        if self.leg is not None and now is not None:
            return AgentView(self.id, self.kind, self.location(now), self.speed)  # type: ignore[arg-type]
        v = self._view
        if v is None or v.loc is not self.loc:
            v = self._view = AgentView(self.id, self.kind, self.loc, self.speed)  # type: ignore[arg-type]
        return v


class Fleet:
    """The run's vehicles by id, and the index of the idle ones.

    Besides the vehicles it keeps array state, aligned with :attr:`vehicles` (id order) and
    updated as vehicles change (their ``loc`` / ``leg`` setters and :meth:`refresh` call
    in), so that a decision over the idle vehicles costs numpy operations, not a
    Python loop over the fleet: ``ids``; ``idle_mask``; on roads ``node`` (the node a vehicle
    stands on, or the end of the edge it stopped on part-way), ``remaining`` (seconds left on
    that edge, 0 on a node), ``odd`` (its location is not a plain node: a road point, or a
    voxel cell) and ``driving`` (it has a leg: its location depends on the time). Where a
    location stands is the space's answer (:meth:`dispatch.space.Space.stands`)."""

    def __init__(self, vehicles: list[Vehicle], space: Space) -> None:
        self.vehicles = sorted(vehicles, key=lambda v: v.id)
        self.by_id = {v.id: v for v in self.vehicles}
        n = len(self.vehicles)
        self.ids = np.fromiter((v.id for v in self.vehicles), np.int64, n)
        #: the ids are the positions 0 .. n-1 (the usual fleet): a position is its id
        self._ids_are_slots = bool((self.ids == np.arange(n)).all())
        self.idle_mask = np.ones(n, dtype=bool)
        self.busy_mask = np.zeros(n, dtype=bool)
        #: a free seat somewhere in its plan (kept by Operator.changed)
        self.room = np.ones(n, dtype=bool)
        #: seats; the end of the service it is in (-inf: none), as the vehicles have them
        self.capacity = np.fromiter((v.capacity for v in self.vehicles), np.int64, n)
        self.free_at = np.full(n, -np.inf)
        self.node = np.full(n, -1, dtype=np.int64)
        self.remaining = np.zeros(n)
        self.odd = np.zeros(n, dtype=bool)
        self.driving = np.zeros(n, dtype=bool)
        #: driving or odd: where it is needs a look at the vehicle (kept with the two)
        self.special = np.zeros(n, dtype=bool)
        self._odd = [False] * n  # odd, as Python bools (read by the leg setter)
        self._stands = space.stands
        #: the node arrays hold (the space has nodes)
        self.road = n > 0 and all(space.stands(v.loc) is not None for v in self.vehicles)
        for i, v in enumerate(self.vehicles):
            v._fleet, v._slot = self, i
            self.driving[i] = v.leg is not None
            self._moved(i, v.loc)

    def __len__(self) -> int:
        return len(self.vehicles)

    def _moved(self, i: int, loc: Location) -> None:
        """Vehicle ``i``'s ``loc`` changed (called by its setter)."""
        at = self._stands(loc)
        if at is None:  # no node (a voxel cell): the arrays are unused
            odd = True
        else:
            self.node[i], self.remaining[i], odd = at
        self.odd[i] = odd
        self._odd[i] = odd
        self.special[i] = odd or self.vehicles[i]._leg is not None

    def idle_index(self) -> np.ndarray:
        """Positions (in :attr:`vehicles`, id order) of the idle vehicles."""
        return self.idle_mask.nonzero()[0]

    def idle(self) -> list[Vehicle]:
        """Idle vehicles in id order."""
        vs = self.vehicles
        return [vs[i] for i in np.flatnonzero(self.idle_mask).tolist()]

    def views(self, index: np.ndarray, now: float, ascending: bool | None = None
              ) -> AgentViews:
        """The vehicles at positions ``index`` as a decision at ``now`` sees them: a lazy
        sequence of :class:`AgentView` (built on access) that also carries their ids and, on
        roads, their nodes and remaining seconds as arrays (see :class:`AgentViews`).
        ``ascending``: whether ``index`` is strictly increasing, if the caller knows."""
        vs = self.vehicles
        idx = np.asarray(index, dtype=np.int64)

        def make(k: int) -> AgentView:
            return vs[int(idx[k])].view(now)

        if ascending is None:  # ids ascend with the positions (vehicles are in id order)
            ascending = bool(idx.size < 2 or (idx[1:] > idx[:-1]).all())
        # (take: a gather about twice as fast as fancy indexing, the same elements; a decision
        # of an immediate city day gathers thousands of idle vehicles, so each one counts)
        ids = idx.copy() if self._ids_are_slots else self.ids.take(idx)
        if not self.road:
            return AgentViews(ids, make, ascending=ascending)
        node = self.node.take(idx)
        special = self.special.take(idx)
        if not special.any():  # every one stands on a node: ``remaining`` is 0 for all
            return AgentViews(ids, make, node, np.zeros(idx.size), _NO_POINTS, ascending)
        rem = self.remaining.take(idx)
        special = special.nonzero()[0].tolist()
        points = []
        for k in special:  # driving (a leg: where is it now?) or stopped part-way along an edge
            v = vs[int(idx[k])]
            leg = v._leg
            if leg is not None:  # (Leg.point_at's numbers, without building the point)
                node[k], rem[k], on = leg.next_at(now - v.leg_start)
                if not on:
                    points.append(k)
                continue
            node[k], rem[k], off = self._stands(v.loc)
            if off:
                points.append(k)
        return AgentViews(ids, make, node, rem, np.array(points, dtype=np.int64), ascending)

    def refresh(self, v: Vehicle) -> None:
        """Set ``v``'s state from its plan and its failure: failed, or on a charging visit (a
        charge stop in its plan), it is neither idle nor busy (no decision considers it);
        serving a request or with one in its plan, busy; else idle (standing, or on a
        repositioning move, which a decision may cut)."""
        busy = idle = False
        if not v.failed:
            busy = v.serving is not None
            idle = not busy
            for s in v.stops:  # (a loop, not any(): it runs at every assignment and idle)
                if s.task is not None:
                    busy, idle = True, False
                    break
                if s.kind is CHARGE:
                    idle = False
        v.busy = busy
        self.idle_mask[v._slot] = idle
        self.busy_mask[v._slot] = busy


def _task_id(s: Stop) -> int:
    """The id of the request a stop serves; -1 for a stop that serves none."""
    return -1 if s.task is None else s.task.id


_NO_POINTS = np.zeros(0, dtype=np.int64)
_NO_POINTS.setflags(write=False)


# ----------------------------------------------------------------------------- drivers


def stop_leg(v: Vehicle, now: float) -> None:
    """Roads: ``v`` stops part-way along its leg at ``now``: the metres driven so far count
    (with the passengers on board) and it stands where it got (a node, or a road point
    part-way along an edge)."""
    leg, t = v.leg, now - v.leg_start
    v.drove(float(np.interp(t, np.r_[0.0, leg.times], np.r_[0.0, leg.metres])), t)
    point = leg.point_at(t)
    v.loc, v.leg = (point.node if point.on_node else point), None


# ----------------------------------------------------------------------------- operations


@dataclass(frozen=True)
class Hooks:
    """What the operator calls in the rest of the run (given at construction)."""

    #: asks the dispatcher for a decision (a vehicle became idle, tasks re-opened)
    notify: Callable[[], None]
    #: a task re-opened by a breakdown (the task source re-arms its expiry)
    reopen: Callable[[Task], None]


@dataclass(frozen=True)
class Towing:
    """``[fleet.energy]``: a vehicle whose battery runs empty is *stranded*: a breakdown (its
    riders transferred when ``transfer``, else their trips fail) that lasts ``seconds``, after
    which it stands at ``to(node)`` (the nearest station to the node where it stranded; None:
    where it is)."""

    seconds: float
    to: Callable[[Any], Any]
    transfer: bool


class Execution(Protocol):
    """How the operator's vehicles execute their plans (a driver the operator uses, made at
    its construction from the operator): :class:`PlanExecution` (the operator's plan process)
    or :class:`dispatch.reservations.TimedExecution` (timed routes on reservations)."""

    def set_out(self, v: Vehicle, task: Task, cost: float, at: tuple | None) -> None:
        """``v``, with an empty plan, is given ``task`` at ``cost`` (``at``: the decision's
        planned times, see :meth:`Operator.assign`) and sets out now."""

    def halt(self, v: Vehicle, again: Callable[[], Any]) -> list[Task] | None:
        """``v`` breaks down now: stop what drives it and return the tasks of its plan; or
        None where it can only stop later (``again`` then breaks it down)."""

    def breaking(self, v: Vehicle) -> bool:
        """``v`` breaks down as soon as it can (a breakdown waits for it)."""

    def holds(self, v: Vehicle) -> Task | None:
        """The task ``v`` drives to pick up (capacity 1, ``[dispatch] reassign``), or None."""

    def repaired(self, v: Vehicle) -> None:
        """``v`` is back in service."""

    def end(self, now: float) -> None:
        """The run is over at ``now``."""

    def counts(self, v: Vehicle) -> dict:
        """The ``vehicles`` table's ``waits``, ``replans`` and ``wait_seconds`` of ``v``."""


class Operator:
    """Hands requests to vehicles (inserting their stops into the vehicle's plan) and drives
    every plan with one SimPy process per vehicle on the move: the process is the loop, the
    stop list is the state. It drives every kind of stop: pickups and drop-offs, a charging
    visit (:data:`dispatch.stops.CHARGE`: drive, queue for a plug, charge, leave; see
    :mod:`dispatch.charging`) and a repositioning move (:data:`dispatch.stops.REPOSITION`:
    drive, idle all the way; a decision that gives the vehicle a request cuts it). Breakdowns,
    strandings (``towing``), repairs and tows are its own. How a vehicle sets out and is
    halted is its ``execution`` (:class:`Execution`, made by ``execution(operator)``):
    :class:`PlanExecution`, or with reservations (voxel, capacity 1) one ``drive`` process per
    vehicle following a timed route (see :mod:`dispatch.reservations`)."""

    def __init__(self, env: simpy.Environment, bus: EventBus, book: TaskBook, fleet: Fleet,
                 driver, service_time: float, hooks: Hooks,
                 execution: Callable[[Operator], Execution] | None = None,
                 towing: Towing | None = None) -> None:
        self.env, self.bus, self.book, self.fleet = env, bus, book, fleet
        self.driver, self.service_time, self.hooks = driver, service_time, hooks
        self.notify = hooks.notify
        #: what becomes of a stranded vehicle (``[fleet.energy]``; None without energy)
        self.towing = towing
        #: the driver's legs are RoadDriver.drive's one timeout each (no edge events): the
        #: plan's process drives them itself, without a generator per leg
        self._plain_legs = driver.plain_legs
        #: repositioning: moves under way (vehicle id -> (its reposition stop, its empty metres
        #: when the move began)), and the metres of the moves ended so far
        self._moves: dict[int, tuple[Stop, float]] = {}
        self.reposition_distance = 0.0
        #: how its vehicles set out, are halted and repaired
        self.execution: Execution = (execution or PlanExecution)(self)

    # ------------------------------------------------------------------ the plan
    def _stops(self, task: Task) -> list[Stop]:
        """The stops of ``task``: its pickup (which completes a point task) and drop-off."""
        n, svc = task.passengers, self.service_time
        if task.dropoff is None:
            return [Stop(PICKUP, task, task.loc, 0, task.deadline, True, service=svc)]
        return [Stop(PICKUP, task, task.loc, n, task.deadline, False),
                Stop(DROPOFF, task, task.dropoff, -n, task.dropoff_deadline, True, service=svc)]

    def assign(self, task: Task, v: Vehicle, cost: float, at: Insertion | None = None) -> None:
        """Give ``task`` to ``v`` at the decision's ``cost``: an idle vehicle (or one that has
        just given its task up, :meth:`give_up`) starts a plan of the task's stops; a busy one
        (pooling) gets them inserted where ``at`` says (:func:`dispatch.stops.insert`), and
        re-routes if its next stop changed."""
        env = self.env
        self._cut(v)  # a repositioning move ends here: the vehicle sets out from where it is
        if not v.stops and v.serving is None:  # an empty plan: the vehicle sets out now
            self.execution.set_out(v, task, cost, at)
            return
        new = self._stops(task)
        assert at is not None
        i, j = at.i, at.j
        self.book.assign(task, v.id, cost)
        old = v.stops
        # the stops after the new ones are reached later
        times = pushed(self._times(v), old, i, j, at.shift1, at.shift2)
        plan = insert(old, new, i, j)
        times = insert(times, [at.pickup_at, at.dropoff_at][:len(new)], i, j)
        self._set_legs(v, plan, times)
        v.stops = plan
        occupancies(v.load, v.stops)
        self.changed(v)
        self.bus.emit(env.now, "insert", v.id, task.id, v.loc)
        if i == 0 and v.heading is not None and v.proc is not None and v.proc.is_alive:
            v.proc.interrupt("reroute")  # its next stop is the new pickup

    def route_times(self, v: Vehicle, rows: list[PlannedStop]
                    ) -> tuple[list[float] | None, str]:
        """Planned arrival times if ``v`` drove the stops ``rows`` (of
        :func:`dispatch.answers.route_stops`) from where it is now, on the planner's travel
        times, by the schedule rule (:func:`dispatch.stops.timetable`), or ``(None, why)``
        where a stop would be late or the vehicle over its capacity. A stop of its plan that
        is already planned late (traffic ran slower than planned) may stay as late as it is."""
        env, planner = self.env, self.driver.planner
        now = env.now
        kept = self.kept(v)
        keys = [(s.kind, _task_id(s)) for s in kept]
        old = dict(zip(keys, kept))
        planned = dict(zip(keys, self._times(v)))
        first = old.get((rows[0].kind, rows[0].task_id))
        if first is not None and v.heading is first and v.leg is not None:
            t = v.leg_start + v.leg.seconds
        else:
            t = max(now, v.free_at) + float(planner.between([v.location(now)], [rows[0].loc])[0, 0])
        legs = (planner.between([r.loc for r in rows[:-1]], [r.loc for r in rows[1:]],
                                pairwise=True).tolist() if len(rows) > 1 else [])
        svc = self.service_time
        earliest, service, latest = [], [], []
        for r in rows:
            mine = old.get((r.kind, r.task_id))
            if mine is None:
                earliest.append(-math.inf)
                service.append(svc if r.completes else 0.0)
                latest.append(r.latest)
            else:
                earliest.append(mine.earliest)
                service.append(mine.service)
                latest.append(max(r.latest, planned[(r.kind, r.task_id)]))
        pax = [r.passengers for r in rows]
        times = [0.0] * len(rows)
        bad, over = timetable(t, legs, earliest, service, latest, pax, v.load, v.capacity, TOL,
                              times)
        if bad < 0:
            return times, ""
        r = rows[bad]
        if over:
            return None, f"{v.load + sum(pax[:bad + 1])} on board after {r.kind} of request " \
                         f"{r.task_id} (capacity {v.capacity})"
        return None, f"{r.kind} of request {r.task_id} at {times[bad]:.6g} s, after its latest " \
                     f"{r.latest:.6g} s"

    def follow(self, v: Vehicle, rows: list[PlannedStop], times: list[float], tasks: dict,
               costs: dict) -> None:
        """A multi-request decision (``Allocation.routes``): ``v`` gets the requests ``tasks``
        (task id -> Task, each handed at ``costs[task id]``) and drives the stops ``rows`` in
        that order (planned arrival ``times``, checked by :meth:`route_times`)."""
        env = self.env
        self._cut(v)  # a repositioning move ends here: the vehicle sets out from where it is
        old = {(s.kind, _task_id(s)): s for s in v.stops}
        empty = not v.stops and v.serving is None
        head = v.stops[0] if v.stops else None
        stops, svc = [], self.service_time
        for r in rows:
            s = old.get((r.kind, r.task_id))
            if s is None:
                s = Stop(r.kind, tasks[r.task_id], r.loc, r.passengers, r.latest,
                         bool(r.completes), service=svc if r.completes else 0.0)
            stops.append(s)
        if empty:
            path = self.driver.plan(v, stops[0].loc, env.now)
        for tid, task in tasks.items():
            self.book.assign(task, v.id, costs[tid])
        self._set_legs(v, stops, times)
        v.stops = stops
        occupancies(v.load, v.stops)
        self.changed(v)
        if empty:
            self.fleet.refresh(v)
            v.proc = env.process(self._run(v, path, stops[0]))
            return
        for tid in tasks:
            self.bus.emit(env.now, "insert", v.id, tid, v.loc)
        if stops[0] is not head and v.heading is not None and v.proc is not None \
                and v.proc.is_alive:
            v.proc.interrupt("reroute")

    def _times(self, v: Vehicle) -> list[float]:
        """Planned arrival times at ``v``'s stops (from the leg it drives, or from when it
        can leave where it stands)."""
        stops = v.stops
        if not stops:
            return []
        if v.heading is stops[0] and v.leg is not None:
            first = v.leg_start + v.leg.seconds
        else:
            first = max(self.env.now, v.free_at) + stops[0].leg
        return schedule(first, stops)

    def _set_legs(self, v: Vehicle, plan: list[Stop], times: list[float]) -> None:
        """Each stop's ``leg`` from planned arrival ``times`` (what is not driving, waiting or
        service between two arrivals is the drive)."""
        t = max(self.env.now, v.free_at)
        for s, arrive in zip(plan, times):
            s.leg = arrive - t
            t = leave(arrive, s.earliest, s.service)

    def plan_arrays(self, v: Vehicle) -> tuple[list, list, list, list, list, list]:
        """``v``'s plan as a decision reads it: planned arrival times, service seconds of
        each stop, latest times, occupancies after each stop, locations, earliest times
        (lists; kept until the plan or the vehicle's state changes: :meth:`changed`)."""
        now = self.env.now
        key = (v.plan_version, now if v.heading is None and v.free_at <= now else None)
        cached = v.plan_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        stops = v.stops
        arrays = (self._times(v), [s.service for s in stops],
                  [s.latest for s in stops], [s.occupancy for s in stops],
                  [s.loc for s in stops], [s.earliest for s in stops])
        v.plan_cache = (key, arrays)
        return arrays

    def changed(self, v: Vehicle) -> None:
        """``v``'s plan or its progress along it changed: what decisions cached of it goes,
        and the fleet learns whether it has a free seat somewhere in its plan."""
        v.plan_version += 1
        low = v.load
        for s in v.stops:
            if s.occupancy < low:
                low = s.occupancy
        self.fleet.room[v._slot] = low < v.capacity

    # ------------------------------------------------------------------ charging, repositioning
    def charge(self, v: Vehicle, visit) -> None:
        """Send the idle vehicle ``v`` on a charging ``visit`` (:class:`dispatch.charging.
        Visit`): its plan becomes the visit's charge stop (drive to the station, queue for a
        plug, charge, leave), during which it is neither idle nor busy; a repositioning move
        ends where it is."""
        self._cut(v)
        v.stops = [Stop(CHARGE, None, visit.station.node, 0, math.inf, False, visit=visit)]
        self.changed(v)
        self.fleet.refresh(v)
        v.proc = self.env.process(self._run(v, None, v.stops[0]))

    def reposition(self, v: Vehicle, node) -> None:
        """Send the idle vehicle ``v`` to ``node`` now (a move it is on ends where it is): its
        plan becomes one reposition stop, which it drives idle (a decision that gives it a
        request cuts the move: :meth:`_cut`). A ``reposition`` event (at the target), then a
        ``depart`` (where it starts); on arrival an ``idle``."""
        env = self.env
        self._cut(v)
        leg = self.driver.plan(v, node, env.now)
        stop = Stop(REPOSITION, None, node, 0, math.inf, False)
        v.stops = [stop]
        self.changed(v)
        self._moves[v.id] = (stop, v.empty_distance)
        self.bus.emit(env.now, "reposition", v.id, -1, node)
        self.bus.emit(env.now, "depart", v.id, -1, v.loc)
        v.proc = env.process(self._run(v, leg, stop, departed=True))

    def kept(self, v: Vehicle) -> list[Stop]:
        """The stops of ``v``'s plan that a decision keeps: all of them, but none of a
        repositioning move (which giving the vehicle a request cuts)."""
        return [] if v.stops and v.stops[0].kind is REPOSITION else v.stops

    def repositioning(self, v: Vehicle):
        """The node ``v`` is repositioning to, or None."""
        s = v.stops[0] if v.stops else None
        return s.loc if s is not None and s.kind is REPOSITION else None

    def _cut(self, v: Vehicle) -> None:
        """If ``v`` is on a repositioning move, the move ends now where it is (part-way along
        an edge possibly: the part driven counts) and its plan is empty."""
        if not v.stops or v.stops[0].kind is not REPOSITION:
            return
        env = self.env
        if v.leg is not None:
            stop_leg(v, env.now)
        self._moved(v, v.stops[0])
        proc = v.proc
        if proc is not None and proc.is_alive and proc is not env.active_process:
            proc.interrupt("cut")
        v.proc, v.stops, v.heading = None, [], None
        self.changed(v)

    def _moved(self, v: Vehicle, stop: Stop) -> None:
        """The repositioning move to ``stop`` ended (arrived, cut, broken down, or the run's
        end): its metres count once."""
        move = self._moves.get(v.id)
        if move is not None and move[0] is stop:
            del self._moves[v.id]
            self.reposition_distance += v.empty_distance - move[1]

    def finish(self) -> None:
        """The run ends: the moves still under way count what they drove (the simulation has
        already counted the part of each leg driven before the horizon)."""
        vs = self.fleet.by_id
        for vid, (stop, _) in sorted(self._moves.items()):
            self._moved(vs[vid], stop)

    def _dropped(self, v: Vehicle, stop: Stop) -> None:
        """The drive to ``stop`` ended without reaching it (a breakdown, an empty battery):
        a repositioning move's metres count, a charging visit is no longer coming."""
        if stop.kind is REPOSITION:
            self._moved(v, stop)
        elif stop.visit is not None:
            stop.visit.reached()

    # ------------------------------------------------------------------ the process
    def _run(self, v: Vehicle, path, first: Stop, departed: bool = False):
        """Process: drive ``v``'s plan stop by stop until it is empty, then idle. ``path``
        was planned to ``first`` when the plan was set (None: planned now); ``departed``: its
        ``depart`` event was already emitted. A decision that puts a new stop first
        interrupts a drive (``reroute``: it stops where it is and drives to the new first
        stop); a breakdown, a re-assignment or the cut of a repositioning move interrupts it
        for good (they have already put the vehicle and its tasks right). At a request's stop
        it picks up or drops off (and serves, where the stop completes the request); at a
        charge stop it makes the visit (:meth:`dispatch.charging.Visit.serve`); at a
        reposition stop it is idle where it arrived. Only a plan of requests counts as busy
        time."""
        env = self.env
        if v.proc is not env.active_process:  # given up before it started ([dispatch] reassign)
            return
        busy = first.task is not None
        if busy:
            v.busy_since = env.now
        emit, plain, book = self.bus.emit, self._plain_legs, self.book
        while v.stops:
            stop = v.stops[0]
            task = stop.task
            tid = -1 if task is None else task.id
            try:
                if stop.visit is not None and v.location(env.now) == stop.loc:
                    pass  # at the station already: no drive
                else:
                    if path is None or stop is not first:
                        path = self.driver.plan(v, stop.loc, env.now)
                    v.heading = stop
                    v.plan_version += 1  # (its first stop's time is now the leg's)
                    if not (departed and stop is first):
                        emit(env.now, "depart", v.id, tid, v.loc)
                    first = None
                    # (a repositioning move is not checked, as before it was a stop: it
                    # drives on with its battery held at 0 kWh; checking it strands such
                    # vehicles, which changes the results of runs that pair the two)
                    if v.battery is not None and self.towing is not None \
                            and stop.kind is not REPOSITION:
                        cut = v.battery.runs_out(path.length, path.seconds)
                        if cut is not None:  # it drives until the battery is empty
                            v.leg, v.leg_start = path, env.now
                            yield env.timeout(cut)
                            stop_leg(v, env.now)
                            self._dropped(v, stop)
                            self.strand(v)
                            return
                    if plain:  # RoadDriver.drive without edge events, inlined
                        v.leg, v.leg_start = path, env.now
                        yield env.timeout(path.seconds)
                        v.leg, v.loc = None, int(path.nodes[-1])
                        v.drove(path.length, path.seconds)
                    else:
                        yield from self.driver.drive(env, v, path, tid)
            except simpy.Interrupt as i:
                if i.cause != "reroute":
                    self._dropped(v, stop)
                    return
                if v.leg is not None:
                    stop_leg(v, env.now)
                v.heading, path = None, None
                v.plan_version += 1
                continue
            v.heading, path = None, None
            if stop.visit is not None:  # a charging visit: queue, charge, leave
                stop.visit.reached()
                try:
                    yield from stop.visit.serve(v)
                except simpy.Interrupt:  # a breakdown at the station: the visit is closed
                    return
                v.stops.pop(0)
                self.changed(v)
                continue
            v.stops.pop(0)
            if stop.kind is REPOSITION:
                self._moved(v, stop)
                self.changed(v)
                continue
            if stop.kind is PICKUP:
                if v.load and stop.passengers:  # a shared ride: it and those on board
                    task.shared = True
                    for s in v.stops:
                        if s.kind is DROPOFF and s.task.state is PICKED_UP_STATE:
                            s.task.shared = True
                v.load += stop.passengers
                book.picked_up(task)
            else:
                v.load += stop.passengers
                task.dropped_at = env.now
                emit(env.now, "dropoff", v.id, task.id, v.loc)
            self.changed(v)
            if not stop.completes:
                continue
            if self.service_time > 0:
                v.serving, v.free_at = task, env.now + self.service_time
                self.fleet.free_at[v._slot] = v.free_at
                try:
                    yield env.timeout(self.service_time)
                except simpy.Interrupt:  # a breakdown in service: breakdown() did the rest
                    return
                v.serving = None
            v.completed += 1
            if v.stops:
                book.close(task, COMPLETED)
            else:
                self._go_idle(v, task)
                return
        # done: the last stop was a visit or a move, or a re-routing removed every stop
        self._go_idle(v, busy=busy)

    def _go_idle(self, v: Vehicle, task: Task | None = None, busy: bool = True) -> None:
        """``v``'s plan is done: it is idle where it is; ``task``, its last stop's (served,
        after the service time), completes first. ``busy``: it was a plan of requests (its
        busy time counts)."""
        if busy:
            v.busy_seconds += self.env.now - v.busy_since
        v.proc, v.heading = None, None
        self.fleet.refresh(v)
        if task is not None:
            self.book.close(task, COMPLETED)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()

    # ------------------------------------------------------------------ faults, re-assignment
    def breakdown(self, v: Vehicle, duration: float, transfer: bool,
                  towed: bool = False) -> bool:
        """``v`` fails now, where it is (on roads possibly part-way along an edge: the part of
        the leg driven counts). Its plan is dropped (a charging visit ends: what was charged
        counts; a repositioning move ends): each request not yet picked up goes back to open;
        each one on board is re-opened for a transfer at the vehicle's position (on roads: the
        node it was driving to) when ``transfer``, else it ends ``failed``. It is out of
        service for ``duration`` seconds (``inf``: for good), then repaired where it stands
        or, ``towed``, at the place :attr:`towing` names. False if it had already failed (or,
        with reservations, never: faults are refused there at validate time)."""
        if v.failed or self.execution.breaking(v):
            return False
        env = self.env
        tasks = self.execution.halt(v, lambda: self.breakdown(v, duration, transfer, towed))
        if tasks is None:  # it breaks down when it can (the end of a step it is executing)
            return True
        if v.leg is not None:  # stop part-way: count what was driven, stand where it got
            stop_leg(v, env.now)
        if v.busy:
            v.busy_seconds += env.now - v.busy_since
        v.failed, v.failures, v.down_since = True, v.failures + 1, env.now
        v.stops, v.load, v.serving, v.heading = [], 0, None, None
        self.changed(v)
        self.fleet.refresh(v)
        self.bus.emit(env.now, "breakdown", v.id, tasks[0].id if tasks else -1, v.loc)
        for task in tasks:
            if task.state is TaskState.PICKED_UP and not transfer:
                self.book.close(task, TaskState.FAILED)
            else:  # a passenger waits at a node
                self.book.reopen(task, self.driver.node_of(v.loc))
                self.hooks.reopen(task)
        if tasks:
            self.notify()
        if duration < math.inf:
            env.process(self._repair(v, duration, towed))
        return True

    def strand(self, v: Vehicle) -> None:
        """``v``'s battery is empty where it stands: a ``stranded`` event, then a breakdown
        (its trips transferred or failed as :attr:`towing` says) that lasts the tow's seconds,
        after which it stands idle at the tow's place (a charging strategy charges it)."""
        tow = self.towing
        self.bus.emit(self.env.now, "stranded", v.id, -1, v.loc)
        self.breakdown(v, tow.seconds, tow.transfer, towed=True)

    def give_up(self, v: Vehicle) -> Task:
        """``[dispatch] reassign`` (capacity 1): ``v``, driving to its task's pickup, gives
        the task up now (a decision gave it another task or none): it stops where it is
        (part-way along an edge included; the metres driven count as empty), its busy time so
        far counts, its task goes back to open (release time and deadline kept) and a
        ``reassign`` event names both. It stays busy: the caller hands it its new task or
        :meth:`stand_idle`. Returns the task given up."""
        env = self.env
        task = v.stops[0].task if v.stops else None
        assert task is not None and task.state is TaskState.ASSIGNED
        proc = v.proc
        if proc is not None and proc.is_alive and proc is not env.active_process \
                and not isinstance(proc.target, simpy.events.Initialize):
            proc.interrupt("reassign")  # (one not started yet sees it is stale and returns)
        v.proc = None
        if v.leg is not None:
            stop_leg(v, env.now)
        v.busy_seconds += env.now - v.busy_since
        v.busy_since = env.now
        v.stops, v.heading = [], None
        self.changed(v)
        self.bus.emit(env.now, "reassign", v.id, task.id, v.loc)
        self.book.unassign(task)
        return task

    def holds(self, v: Vehicle) -> Task | None:
        """The task ``v`` drives to pick up (capacity 1, ``[dispatch] reassign``), or None."""
        return self.execution.holds(v)

    def stand_idle(self, v: Vehicle) -> None:
        """``v`` (after :meth:`give_up`, with no new task) is idle where it stopped."""
        self.fleet.refresh(v)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()

    def _repair(self, v: Vehicle, duration: float, towed: bool):
        """Process: ``v`` is out of service ``duration`` seconds, then idle where it stands
        or, ``towed``, where :attr:`towing` takes it (its battery settled there)."""
        yield self.env.timeout(duration)
        if towed:
            place = self.towing.to(self.driver.node_of(v.loc))
            if place is not None:
                v.loc = place
            v.battery.settle()
        v.failed = False
        self.execution.repaired(v)
        v.down_seconds += self.env.now - v.down_since
        self.fleet.refresh(v)
        self.bus.emit(self.env.now, "repair", v.id, -1, v.loc)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()


class PlanExecution:
    """The operator's own execution (every run without reservations): a vehicle that sets out
    gets its task's stops as its plan and one process drives them (:meth:`Operator._run`); a
    breakdown interrupts that process at once."""

    def __init__(self, op: Operator) -> None:
        self.op = op

    def set_out(self, v: Vehicle, task: Task, cost: float, at: tuple | None) -> None:
        op = self.op
        new = op._stops(task)
        path = op.driver.plan(v, task.loc, op.env.now)
        op.book.assign(task, v.id, cost)
        if at is not None:  # the planned times of the decision
            op._set_legs(v, new, [at[2], at[3]][:len(new)])
        else:  # (legs only matter to later insertions: pooled runs always pass ``at``)
            new[0].leg = op.driver.leg_seconds(path)
            if len(new) > 1:
                new[1].leg = task.direct_time
        v.stops = new
        occupancies(v.load, v.stops)
        op.changed(v)
        op.fleet.refresh(v)
        v.proc = op.env.process(op._run(v, path, new[0]))

    def halt(self, v: Vehicle, again: Callable[[], Any]) -> list[Task]:
        tasks = v.tasks()
        proc = v.proc
        if proc is not None and proc.is_alive and proc is not self.op.env.active_process:
            proc.interrupt("breakdown")
            v.proc = None
        return tasks

    def breaking(self, v: Vehicle) -> bool:
        return False

    def holds(self, v: Vehicle) -> Task | None:
        s = v.stops[0] if v.stops else None
        return s.task if s is not None and s.kind is PICKUP else None

    def repaired(self, v: Vehicle) -> None:
        """Nothing to do: its next plan starts a process."""

    def end(self, now: float) -> None:
        """Nothing open: the run's end cut the legs being driven."""

    def counts(self, v: Vehicle) -> dict:
        return {"waits": 0, "replans": 0, "wait_seconds": 0.0}
