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
from dispatch.plan.breaks import plan_break
from dispatch.plan.execution import Execution, PlanExecution
from dispatch.plan.kinds import TABLE as KINDS
from dispatch.plan.stops import (CHARGE, DEPOT, REPOSITION, TOL, PlannedStop, Stop, leave,
                                 timetable)
from dispatch.plan.tasks import COMPLETED, Task, TaskBook
from dispatch.plan.vehicle_plan import request_stops
from dispatch.plan.vehicles import Fleet, Vehicle, stop_leg

if TYPE_CHECKING:
    from dispatch.plan.insertion import Insertion


#: a hand-out that plans no meeting points keeps the task's (:meth:`Operator.assign`)
KEEP = object()


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
    :mod:`dispatch.plan.timed_drives`)."""

    def __init__(self, env: simpy.Environment, bus: EventBus, book: TaskBook, fleet: Fleet,
                 driver, service_time: float, *, hooks: Hooks,
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
    def assign(self, task: Task, v: Vehicle, cost: float, at: Insertion | None = None,
               meeting=KEEP) -> None:
        """Give ``task`` to ``v`` at the decision's ``cost``: an idle vehicle (or one that has
        just given its task up, :meth:`give_up`) starts a plan of the task's stops; a busy one
        (pooling) gets them inserted where ``at`` says (:meth:`dispatch.plan.vehicle_plan.Plan.
        insert`), and re-routes if its next stop changed. The rider boards and alights at the
        meeting points the decision planned: ``at.meeting``, or ``meeting`` where the decision
        planned each request at one pair (:mod:`dispatch.decide.meeting`; None: door to door;
        :data:`KEEP`: as the task has them)."""
        env = self.env
        self._cut(v)  # a repositioning move ends here: the vehicle sets out from where it is
        self._meet(task, at.meeting if at is not None and at.meeting is not None else meeting)
        if not v.plan and v.serving is None:  # an empty plan: the vehicle sets out now
            self.execution.set_out(v, task, cost, at)
            return
        assert at is not None
        self.book.assign(task, v.id, cost)
        v.plan.insert(request_stops(task, self.service_time), at, env.now)
        self.bus.emit(env.now, "insert", v.id, task.id, v.loc)
        if at.i == 0:
            self._reroute(v)  # its next stop is the new pickup

    @staticmethod
    def _meet(task: Task, meeting) -> None:
        """``task`` is handed out to ride from and to ``meeting`` (None: door to door;
        :data:`KEEP`: as it has them): the one place a task's meeting points are written."""
        if meeting is not KEEP:
            task.meeting = meeting

    def _reroute(self, v: Vehicle) -> None:
        """``v``'s first stop changed: a drive under way stops where it is and heads there."""
        if v.heading is not None and v.proc is not None and v.proc.is_alive:
            v.proc.interrupt("reroute")

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
        kept = v.plan.kept()
        keys = [(s.kind, _task_id(s)) for s in kept]
        old = dict(zip(keys, kept))
        planned = dict(zip(keys, v.plan.times(now)))
        first = old.get((rows[0].kind, rows[0].task_id))
        if first is not None and v.heading is first and v.leg is not None:
            t = v.leg_start + v.leg.seconds
        else:
            t = max(now, v.free_at) + float(planner.between([v.location(now)],
                                                            [rows[0].loc])[0, 0])
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
               costs: dict, meetings: dict | None = None) -> None:
        """A multi-request decision (``Allocation.routes``): ``v`` gets the requests ``tasks``
        (task id -> Task, each handed at ``costs[task id]``) and drives the stops ``rows`` in
        that order (planned arrival ``times``, checked by :meth:`route_times`); ``meetings``:
        the meeting points each request was planned at (task id -> them; see :meth:`assign`)."""
        env = self.env
        self._cut(v)  # a repositioning move ends here: the vehicle sets out from where it is
        old = {(s.kind, _task_id(s)): s for s in v.plan}
        empty = not v.plan and v.serving is None
        head = v.plan[0] if v.plan else None
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
            self._meet(task, (meetings or {}).get(tid, KEEP))
            self.book.assign(task, v.id, costs[tid])
        v.plan.replace(stops, times, env.now)
        if empty:
            self.fleet.refresh(v)
            v.proc = env.process(self.drive(v, path, stops[0]))
            return
        for tid in tasks:
            self.bus.emit(env.now, "insert", v.id, tid, v.loc)
        if stops[0] is not head:
            self._reroute(v)

    # ------------------------------------------------------------------ stops of no request
    def charge(self, v: Vehicle, visit) -> None:
        """Send the idle vehicle ``v`` on a charging ``visit`` (:class:`dispatch.fleet.chargers.
        Visit`): its plan becomes the visit's charge stop (drive to the station, queue for a
        plug, charge, leave), during which it is neither idle nor busy; a repositioning move
        ends where it is."""
        self._cut(v)
        stop = Stop(CHARGE, None, visit.station.node, 0, math.inf, False, visit=visit)
        v.plan.replace([stop], None, self.env.now)
        self.fleet.refresh(v)
        v.proc = self.env.process(self.drive(v, None, stop))

    def reposition(self, v: Vehicle, node) -> None:
        """Send the idle vehicle ``v`` to ``node`` now (a move it is on ends where it is): its
        plan becomes one reposition stop, which it drives idle (a decision that gives it a
        request cuts the move: :meth:`_cut`). A ``reposition`` event (at the target), then a
        ``depart`` (where it starts); on arrival an ``idle``."""
        env = self.env
        self._cut(v)
        leg = self.driver.plan(v, node, env.now)
        stop = Stop(REPOSITION, None, node, 0, math.inf, False)
        v.plan.replace([stop], None, env.now)
        self._moves[v.id] = (stop, v.empty_distance)
        self.bus.emit(env.now, "reposition", v.id, -1, node)
        self.bus.emit(env.now, "depart", v.id, -1, v.loc)
        v.proc = env.process(self.drive(v, leg, stop, departed=True))

    def to_depot(self, v: Vehicle, node) -> None:
        """Send ``v`` (its plan empty, or a repositioning move, which ends where it is) to its
        depot ``node`` (dispatch.fleet.shifts): its plan becomes one depot stop; on arrival an
        ``idle``."""
        self._cut(v)
        stop = Stop(DEPOT, None, node, 0, math.inf, False)
        v.plan.replace([stop], None, self.env.now)
        v.proc = self.env.process(self.drive(v, None, stop))

    def take_break(self, v: Vehicle, due: float, duration: float) -> Stop | None:
        """Plan ``v``'s break of ``duration`` seconds, due since ``due``, where
        :func:`dispatch.plan.breaks.plan_break` puts it (a repositioning move it is on ends
        where it is); the stop, or None where none can be planned now."""
        now = self.env.now
        self._cut(v)
        got = plan_break(v, due, duration, now, self.driver)
        if got is None:
            return None
        k, stop, times = got
        was_empty = not v.plan
        v.plan.put(stop, k, times, now)
        self.fleet.refresh(v)
        if was_empty and v.proc is None:  # idle: its break starts now, where it stands
            v.proc = self.env.process(self.drive(v, None, stop))
        elif k == 0:
            self._reroute(v)
        return stop

    def repositioning(self, v: Vehicle):
        """The node ``v`` is repositioning to, or None."""
        s = v.plan[0] if v.plan else None
        return s.loc if s is not None and s.kind is REPOSITION else None

    def _cut(self, v: Vehicle) -> None:
        """If ``v``'s first stop is one a request cuts (a repositioning move), the move ends
        now where it is (part-way along an edge possibly: the part driven counts) and its
        plan is empty."""
        first = v.plan[0] if v.plan else None
        if first is None or KINDS[first.kind].kept:
            return
        env = self.env
        if v.leg is not None:
            stop_leg(v, env.now)
        KINDS[first.kind].dropped(self, v, first)
        proc = v.proc
        if proc is not None and proc.is_alive and proc is not env.active_process:
            proc.interrupt("cut")
        v.proc, v.heading = None, None
        v.plan.clear()

    def move_ended(self, v: Vehicle, stop: Stop) -> None:
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
            self.move_ended(vs[vid], stop)

    # ------------------------------------------------------------------ the process
    def drive(self, v: Vehicle, path, first: Stop, departed: bool = False):
        """Process: drive ``v``'s plan stop by stop until it is empty, then idle. ``path``
        was planned to ``first`` when the plan was set (None: planned now); ``departed``: its
        ``depart`` event was already emitted. A decision that puts a new stop first
        interrupts a drive (``reroute``: it stops where it is and drives to the new first
        stop); a breakdown, a re-assignment or the cut of a repositioning move interrupts it
        for good (they have already put the vehicle and its tasks right). On arrival the
        stop's kind makes the stop (:data:`dispatch.plan.kinds.TABLE`: pick up, drop off and
        serve, charge, take a break, stand idle where a move ended). Only a plan of requests
        counts as busy time."""
        env = self.env
        if v.proc is not env.active_process:  # given up before it started ([dispatch] reassign)
            return
        busy = first.task is not None
        if busy:
            v.busy_since = env.now
        emit, plain, plan = self.bus.emit, self._plain_legs, v.plan
        while plan:
            stop = plan[0]
            kind = KINDS[stop.kind]
            task = stop.task
            tid = -1 if task is None else task.id
            try:
                if not kind.there(v, stop, env.now):
                    if path is None or stop is not first:
                        path = self.driver.plan(v, stop.loc, env.now)
                    v.heading = stop
                    v.plan_version += 1  # (its first stop's time is now the leg's)
                    if not (departed and stop is first):
                        emit(env.now, "depart", v.id, tid, v.loc)
                    first = None
                    if v.battery is not None and self.towing is not None \
                            and kind.checks_battery:
                        cut = v.battery.runs_out(path.length, path.seconds)
                        if cut is not None:  # it drives until the battery is empty
                            v.leg, v.leg_start = path, env.now
                            yield env.timeout(cut)
                            stop_leg(v, env.now)
                            kind.dropped(self, v, stop)
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
                    kind.dropped(self, v, stop)
                    return
                if v.leg is not None:
                    stop_leg(v, env.now)
                v.heading, path = None, None
                v.plan_version += 1
                continue
            v.heading, path = None, None
            if not (yield from kind.arrive(self, v, stop)):
                return
        # done: the last stop was a visit, a move or a break, or a re-routing removed them all
        v.proc = None
        self.go_idle(v, busy=busy)

    def go_idle(self, v: Vehicle, task: Task | None = None, busy: bool = True) -> None:
        """``v``'s plan is done: it is idle where it is; ``task``, its last stop's (served,
        after the service time), completes first. ``busy``: it was a plan of requests (its
        busy time counts)."""
        if busy:
            v.busy_seconds += self.env.now - v.busy_since
        v.heading = None
        self.fleet.refresh(v)
        if task is not None:
            self.book.close(task, COMPLETED)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()
