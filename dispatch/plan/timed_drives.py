"""Reservation-based execution's drives: one process per vehicle for the whole run follows the
timed route that the run's :class:`dispatch.plan.traffic.Traffic` keeps for it, and
:class:`TimedExecution` is the operator's execution on that traffic.

Every wait is a ``wait`` event (the vehicle stands in its cell from then until the step of its
next ``move`` starts, i.e. the move's time minus the step's duration); the ``vehicles`` table
counts ``waits``, ``replans`` and ``wait_seconds``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import simpy

from dispatch.api.motion import EPS, step_length, step_seconds
from dispatch.plan.tasks import TaskState
from dispatch.plan.traffic import TimedVehicle, Traffic
from dispatch.plan.vehicle_plan import request_stops


class DriveContext:
    """What the timed drives need of the run (the operator's): the task book, the fleet's
    index, the service time, the dispatcher's wake-up, a breakdown to finish later and the
    vehicle's return to idle (:meth:`dispatch.plan.operator.Operator.go_idle`)."""

    def __init__(self, book, fleet, service_time: float, notify: Callable[[], None],
                 breakdown: Callable[..., bool], go_idle: Callable[..., None]) -> None:
        self.book, self.fleet, self.service_time = book, fleet, service_time
        self.notify, self.breakdown, self.go_idle = notify, breakdown, go_idle


def _start(traffic: Traffic, ctx: DriveContext) -> None:
    for t in traffic.vehicles.values():
        t.vehicle.proc = traffic.env.process(_drive(traffic, ctx, t))


def begin_wait(traffic: Traffic, t: TimedVehicle) -> None:
    """It stands in its cell on the way to its task (until its next step starts)."""
    if t.waiting_since is None:
        now = traffic.env.now
        t.waiting_since = now
        t.waits += 1
        traffic.emit(now, "wait", t.id, t.task.id, t.cell)


def end_wait(t: TimedVehicle, now: float) -> None:
    """Its wait (if any) ends now."""
    if t.waiting_since is not None:
        t.wait_seconds += now - t.waiting_since
        t.waiting_since = None


def _finish(traffic: Traffic, ctx: DriveContext, t: TimedVehicle):
    """Serve the task at its cell (the service time), then idle."""
    env, v, task = traffic.env, t.vehicle, t.task
    if ctx.service_time > 0:
        yield env.timeout(ctx.service_time)
    t.task = None
    v.completed += 1
    v.plan.clear()
    ctx.go_idle(v, task)


def _drive(traffic: Traffic, ctx: DriveContext, t: TimedVehicle):
    """Process (one per vehicle for the whole run): follow the timed route that the traffic
    keeps for this vehicle, whatever it is for: its task (then serve it), parking out of
    someone's way while idle, or holding its cell (a one-cell route). Without a route to its
    task it waits and asks again."""
    env, cell_m, v = traffic.env, traffic.grid.cell, t.vehicle
    while True:
        if t.changed.triggered:
            t.changed = env.event()
        route, task = t.route, t.task
        if v.failed or t.breaking:  # broken down (Traffic.hold): stand until repaired
            try:
                yield t.changed
            except simpy.Interrupt:
                pass
            continue
        if len(route) == 1:
            if task is None:  # idle: stay until told to move
                yield t.changed
            elif v.loc == task.loc:
                t.arrived = True
                ctx.book.picked_up(task)
                try:
                    yield from _finish(traffic, ctx, t)
                except simpy.Interrupt:  # broke down while serving: breakdown() did the rest
                    continue
                t.arrived = False
                traffic.notify()  # idle now: it can be asked to make way
            else:  # no route to the task: hold the cell, retry on a release or a timer
                begin_wait(traffic, t)
                yield env.any_of([env.timeout(traffic.retry_after), t.changed,
                                  traffic.released])
                if t.route is route and t.last_try < env.now:  # once per instant
                    traffic.request(t)
            continue
        (_, here), (arr, nxt) = route[0], route[1]
        dep = arr - step_seconds(here, nxt, v.speed, cell_m)
        if dep > env.now + EPS:
            if task is not None:
                begin_wait(traffic, t)
            yield env.any_of([env.timeout(dep - env.now), t.changed])
            continue
        end_wait(t, env.now)
        nxt, arr = traffic.start_step(t)
        yield env.timeout(max(arr - env.now, 0.0))
        metres = step_length(v.loc, nxt) * cell_m
        v.loc = nxt
        v.drove(metres)  # to a task, or parking: never with a passenger here
        traffic.emit(env.now, "move", v.id, -1 if t.task is None else t.task.id, nxt)


def _after_step(traffic: Traffic, t: TimedVehicle, again: Callable[[], Any]):
    yield traffic.env.timeout(t.step[3] - traffic.env.now)
    t.breaking = False
    again()


class TimedExecution:
    """Reservation-based execution (voxel world, capacity 1), the operator's
    :class:`dispatch.plan.execution.Execution`: one drive process per vehicle for the whole run
    follows the timed route the traffic keeps for it; the operator hands it a task, breaks it
    down and repairs it through here."""

    def __init__(self, traffic: Traffic, op) -> None:
        self.traffic, self.op = traffic, op
        self.context = DriveContext(op.book, op.fleet, op.service_time, op.notify, op.breakdown,
                                    op.go_idle)
        _start(traffic, self.context)

    @property
    def env(self):
        return self.traffic.env

    def set_out(self, v, task, cost: float, at: tuple | None) -> None:
        """``v`` now drives to ``task`` (its plan: the task's one stop); the task's ``cost`` is
        its priority."""
        op = self.op
        op.book.assign(task, v.id, cost)
        v.plan.replace(request_stops(task, op.service_time), None, self.env.now)
        op.fleet.refresh(v)
        t = self.traffic.of(v)
        t.task, v.busy_since = task, self.env.now
        self.traffic.emit(self.env.now, "depart", v.id, task.id, v.loc)
        self.traffic.request(t)
        if task.deadline < math.inf:
            self.env.process(self._deadline(v, t, task))

    def _deadline(self, v, t: TimedVehicle, task):
        """Process: ``task``'s pickup limit. The decision timed the drive on the free grid,
        but reservations may hold the vehicle up on the way (a detour, a wait); a rider is
        never picked up late, so if the vehicle is not there by the deadline (nor stepping
        into the task's cell to arrive by it), it gives the task up where it is: the task
        goes back to open and expires at once (as an open task does at its deadline), and
        the vehicle stops at the end of its step, idle."""
        env, traffic = self.env, self.traffic
        yield env.timeout(max(task.deadline - env.now, 0.0))
        if t.task is not task or t.arrived or task.state is not TaskState.ASSIGNED:
            return
        s = t.step
        if s is not None and s[1] == task.loc and env.now <= s[3] <= task.deadline + EPS:
            return  # arriving on time
        op = self.op
        end_wait(t, env.now)
        t.task = None
        v.plan.clear()
        v.busy_seconds += env.now - v.busy_since
        op.book.unassign(task)
        op.book.close(task, TaskState.EXPIRED)
        op.fleet.refresh(v)
        traffic.stop(t)
        traffic.emit(env.now, "idle", v.id, -1, v.loc)
        op.notify()

    def holds(self, v):
        return self.traffic.of(v).task

    def breaking(self, v) -> bool:
        return self.traffic.of(v).breaking

    def halt(self, v, again: Callable[[], Any]) -> list | None:
        """``v`` breaks down: None if it is executing a step (a step is never interrupted:
        ``again`` runs on arrival in the step's cell, so it never moves while failed); else
        it stops serving, holds its cell hard, and the task it had is returned (in a list)."""
        env, t = self.env, self.traffic.of(v)
        if t.step is not None and t.step[3] > env.now + EPS:
            t.breaking = True
            env.process(_after_step(self.traffic, t, again))
            return None
        task = t.task
        if t.arrived and task is not None and v.proc is not env.active_process:
            v.proc.interrupt("breakdown")  # in service at the task's cell
        end_wait(t, env.now)
        self.traffic.hold(t)
        t.task = None
        return [] if task is None else [task]

    def repaired(self, v) -> None:
        t = self.traffic.of(v)
        t.arrived = False  # displaceable again, like any idle vehicle
        self.traffic.notify()
        if not t.changed.triggered:
            t.changed.succeed()

    def end(self, now: float) -> None:
        """The run is over: open waits end now."""
        for t in self.traffic.vehicles.values():
            end_wait(t, now)

    def counts(self, v) -> dict:
        """The ``vehicles`` table's waits, replans and wait_seconds of ``v``."""
        t = self.traffic.of(v)
        return {"waits": t.waits, "replans": t.replans, "wait_seconds": t.wait_seconds}

