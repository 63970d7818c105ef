"""How the operator's vehicles execute their plans: the :class:`Execution` protocol (set out,
halt for a breakdown, repair, the run's end, the counts the ``vehicles`` table reports) and the
operator's own :class:`PlanExecution`. The other execution is
:class:`dispatch.plan.reservations.TimedExecution`: with a reservation-aware planner (voxel only,
capacity 1) timed drives follow routes that the run's :class:`dispatch.plan.reservations.Traffic`
keeps conflict-free and owns. The operator (:class:`dispatch.plan.operator.Operator`) makes its
execution at its construction, from itself.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from dispatch.plan.insertion import Insertion
from dispatch.plan.stops import PICKUP, occupancies
from dispatch.plan.tasks import Task
from dispatch.plan.vehicles import Vehicle


class Execution(Protocol):
    """How the operator's vehicles execute their plans (a driver the operator uses, made at
    its construction from the operator): :class:`PlanExecution` (the operator's plan process)
    or :class:`dispatch.plan.reservations.TimedExecution` (timed routes on reservations)."""

    def set_out(self, v: Vehicle, task: Task, cost: float, at: Insertion | None) -> None:
        """``v``, with an empty plan, is given ``task`` at ``cost`` (``at``: the decision's
        planned times, see :meth:`dispatch.plan.operator.Operator.assign`) and sets out now."""

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
    (:meth:`dispatch.plan.operator.Operator._run`); a
    breakdown interrupts that process at once."""

    def __init__(self, op) -> None:
        self.op = op  # the operator (which imports this module)

    def set_out(self, v: Vehicle, task: Task, cost: float, at: Insertion | None) -> None:
        op = self.op
        new = op._stops(task)
        path = op.driver.plan(v, new[0].loc, op.env.now)
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
