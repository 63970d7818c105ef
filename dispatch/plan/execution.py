"""How the operator's vehicles execute their plans: the :class:`Execution` protocol (set out,
halt for a breakdown, repair, the run's end, the counts the ``vehicles`` table reports) and the
operator's own :class:`PlanExecution`. The other execution is
:class:`dispatch.plan.timed_drives.TimedExecution`: with a reservation-aware planner (voxel only,
capacity 1) timed drives follow routes that the run's :class:`dispatch.plan.traffic.Traffic`
keeps conflict-free and owns. The operator (:class:`dispatch.plan.operator.Operator`) makes its
execution at its construction, from itself.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from dispatch.plan.stops import PICKUP
from dispatch.plan.tasks import Task
from dispatch.plan.vehicle_plan import request_stops
from dispatch.plan.vehicles import Vehicle

if TYPE_CHECKING:
    from dispatch.plan.insertion import Insertion


class Execution(Protocol):
    """How the operator's vehicles execute their plans (a driver the operator uses, made at
    its construction from the operator): :class:`PlanExecution` (the operator's plan process)
    or :class:`dispatch.plan.timed_drives.TimedExecution` (timed routes on reservations)."""

    def set_out(self, v: Vehicle, task: Task, cost: float, at: Insertion | None) -> None:
        """``v``, with an empty plan, is given ``task`` at ``cost`` (``at``: the decision's
        insertion, with its planned times, see :meth:`dispatch.plan.operator.Operator.assign`)
        and sets out now."""

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


class PlanExecution:
    """The operator's own execution (every run without reservations): a vehicle that sets out
    gets its task's stops as its plan and one process drives them
    (:meth:`dispatch.plan.operator.Operator.drive`); a breakdown interrupts that process at
    once."""

    def __init__(self, op) -> None:
        self.op = op  # the operator (which imports this module)

    def set_out(self, v: Vehicle, task: Task, cost: float, at: Insertion | None) -> None:
        op, now = self.op, self.op.env.now
        new = request_stops(task, op.service_time)
        path = op.driver.plan(v, new[0].loc, now)
        op.book.assign(task, v.id, cost)
        times = None
        if at is not None:  # the planned times of the decision
            times = [at.pickup_at, at.dropoff_at][:len(new)]
        else:  # (legs only matter to later insertions: pooled runs always pass ``at``)
            new[0].leg = op.driver.leg_seconds(path)
            if len(new) > 1:  # the drive at this hour, as insertions time it (congestion)
                planner = op.driver.planner
                new[1].leg = task.direct_time if planner.free_flow is planner else float(
                    np.asarray(planner.between([task.loc], [task.dropoff], pairwise=True))[0])
        v.plan.replace(new, times, now)
        op.fleet.refresh(v)
        v.proc = op.env.process(op.drive(v, path, new[0]))

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
        s = v.plan[0] if v.plan else None
        return s.task if s is not None and s.kind is PICKUP else None

    def repaired(self, v: Vehicle) -> None:
        """Nothing to do: its next plan starts a process."""

    def end(self, now: float) -> None:
        """Nothing open: the run's end cut the legs being driven."""

    def counts(self, v: Vehicle) -> dict:
        return {"waits": 0, "replans": 0, "wait_seconds": 0.0}
