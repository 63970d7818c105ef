"""How an operator takes a vehicle out of its plan: breakdowns (a battery run empty strands
it: a breakdown ended by a tow), the repair and the tow that end them, and giving a task up
(``[dispatch] reassign``).

:class:`Breakdowns` is a base of :class:`~dispatch.plan.operator.Operator`: its methods use the
operator's clock, bus, task book, fleet, driver, hooks, ``towing`` and ``execution``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import simpy

from dispatch.plan.tasks import TaskState
from dispatch.plan.vehicles import stop_leg

if TYPE_CHECKING:
    from dispatch.plan.tasks import Task
    from dispatch.plan.vehicles import Vehicle


class Breakdowns:
    """How an operator takes a vehicle out of its plan: breakdowns, strandings, repair and
    tow, giving a task up (``[dispatch] reassign``) and standing idle after it."""

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
        v.load, v.serving, v.heading = 0, None, None
        v.plan.clear()
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
        task = v.plan[0].task if v.plan else None
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
        v.heading = None
        v.plan.clear()
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
