"""The operator: it hands requests to vehicles and drives their plans, one SimPy process per
busy vehicle.

The :class:`Operator` inserts a decision's stops into a vehicle's plan (its stop list, see
:mod:`dispatch.plan.stops`) and one process per busy vehicle drives it stop by stop: to each stop,
pick up or drop off (with capacity above 1 several requests ride at once), the service time
where a request completes, idle when the list is empty. A breakdown or a re-assignment removes
stops; nothing else changes the plan. How it drives depends on the space, through the *driver*
its space makes (:mod:`dispatch.space.drivers`: cell by cell in a voxel world, one timeout per leg
on
roads).

How a vehicle sets out on a plan, is halted by a breakdown and is repaired is the operator's
*execution* (:mod:`dispatch.plan.execution`): its own plan process, or with reservations timed
drives.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import simpy

from dispatch.events import EventBus
from dispatch.plan.breakdowns import Breakdowns
from dispatch.plan.execution import Execution, PlanExecution
from dispatch.plan.stops import (CHARGE, DEPOT, DROPOFF, PICKUP, REPOSITION, TOL, PlannedStop, Stop,
                                 insert, leave, occupancies, pushed, schedule, timetable)
from dispatch.plan.tasks import COMPLETED, Task, TaskBook
from dispatch.plan.tasks import PICKED_UP as PICKED_UP_STATE
from dispatch.plan.vehicles import Fleet, Vehicle, stop_leg

if TYPE_CHECKING:
    from dispatch.plan.insertion import Insertion


def _task_id(s: Stop) -> int:
    """The id of the request a stop serves; -1 for a stop that serves none."""
    return -1 if s.task is None else s.task.id


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


class Operator(Breakdowns):
    """Hands requests to vehicles (inserting their stops into the vehicle's plan) and drives
    every plan with one SimPy process per vehicle on the move: the process is the loop, the
    stop list is the state. It drives every kind of stop: pickups and drop-offs, a charging
    visit (:data:`dispatch.plan.stops.CHARGE`: drive, queue for a plug, charge, leave; see
    :mod:`dispatch.fleet.chargers`) and a repositioning move
    (:data:`dispatch.plan.stops.REPOSITION`:
    drive, idle all the way; a decision that gives the vehicle a request cuts it). Breakdowns,
    strandings (``towing``), repairs and tows are its own
    (:class:`~dispatch.plan.breakdowns.Breakdowns`). How a vehicle sets out and is
    halted is its ``execution`` (:class:`~dispatch.plan.execution.Execution`, made by
    ``execution(operator)``): :class:`~dispatch.plan.execution.PlanExecution`, or with reservations
    (voxel, capacity 1) one ``drive`` process per vehicle following a timed route (see
    :mod:`dispatch.plan.reservations`)."""

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
        m = task.meeting
        if m is not None and not task.transfers:  # meeting points (dispatch.decide.meeting)
            return [Stop(PICKUP, task, m.board, n, task.deadline, False, earliest=m.earliest),
                    Stop(DROPOFF, task, m.alight, -n, m.latest_drop, True, service=svc)]
        e = task.earliest_pickup  # (a booked request's requested departure: prebook)
        if task.dropoff is None:
            return [Stop(PICKUP, task, task.loc, 0, task.deadline, True, service=svc,
                         earliest=e)]
        return [Stop(PICKUP, task, task.loc, n, task.deadline, False, earliest=e),
                Stop(DROPOFF, task, task.dropoff, -n, task.dropoff_deadline, True, service=svc)]

    def assign(self, task: Task, v: Vehicle, cost: float, at: Insertion | None = None) -> None:
        """Give ``task`` to ``v`` at the decision's ``cost``: an idle vehicle (or one that has
        just given its task up, :meth:`give_up`) starts a plan of the task's stops; a busy one
        (pooling) gets them inserted where ``at`` says (:func:`dispatch.plan.stops.insert`), and
        re-routes if its next stop changed."""
        env = self.env
        self._cut(v)  # a repositioning move ends here: the vehicle sets out from where it is
        if at is not None and at.meeting is not None:  # where the rider boards and alights
            task.meeting = at.meeting
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

    def route_times(self, v: Vehicle, rows: list[PlannedStop], until: float = math.inf
                    ) -> tuple[list[float] | None, str]:
        """Planned arrival times if ``v`` drove the stops ``rows`` (of
        :func:`dispatch.decide.answers.route_stops`) from where it is now, on the planner's travel
        times, by the schedule rule (:func:`dispatch.plan.stops.timetable`; a new stop waits for
        its row's ``earliest``), or ``(None, why)`` where a stop would be late, the vehicle
        over its capacity or the route would end (leave its last stop) after ``until`` (a
        driver's shift end plus the grace). A stop of its plan that is already planned late
        (traffic ran slower than planned) may stay as late as it is."""
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
                earliest.append(r.earliest)
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
            end = leave(times[-1], earliest[-1], service[-1])
            if end > until + TOL:
                return None, f"the route ends at {end:.6g} s, after the vehicle's shift end " \
                             f"and grace {until:.6g} s"
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
                         bool(r.completes), service=svc if r.completes else 0.0,
                         earliest=r.earliest)
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
        # (a standing vehicle's times start at ``now``; dispatch.decide.plan_costs.PlanTable.gather
        # asks
        # again by this same key, read from the fleet's arrays: change both together)
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
        """Send the idle vehicle ``v`` on a charging ``visit`` (:class:`dispatch.fleet.chargers.
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

    def to_depot(self, v: Vehicle, node) -> None:
        """Send ``v`` (its plan empty, or a repositioning move, which ends where it is) to its
        depot ``node`` (dispatch.fleet.shifts): its plan becomes one depot stop; on arrival an
        ``idle``."""
        self._cut(v)
        v.stops = [Stop(DEPOT, None, node, 0, math.inf, False)]
        self.changed(v)
        v.proc = self.env.process(self._run(v, None, v.stops[0]))

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
        charge stop it makes the visit (:meth:`dispatch.fleet.chargers.Visit.serve`); at a
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
                    if stop.earliest > env.now:  # (the rule) a rider still walking to it, a
                        stop.leg = 0.0  # booked ride's departure: it waits where the stop is
                        v.plan_version += 1  # (a new first stop interrupts the wait: reroute)
                        yield env.timeout(stop.earliest - env.now)
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
            if stop.kind is REPOSITION or stop.kind is DEPOT:
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
