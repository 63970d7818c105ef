"""The dispatcher: a SimPy process that turns idle vehicles and open tasks into assignments.

It wakes when a task is released or a vehicle becomes idle, waits the optional batching window
(a zero window still lets every event of the same instant land first), builds an
:class:`AllocationProblem` with the planner's cost matrix, asks the allocator, checks the answer
and hands the tasks to the vehicles.
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING

import numpy as np

from dispatch.contracts import Allocation, AllocationProblem
from dispatch.errors import AllocationError
from dispatch.tasks import TaskState

if TYPE_CHECKING:
    from dispatch.sim import Simulation

log = logging.getLogger(__name__)


def validate(problem: AllocationProblem, allocation: Allocation) -> None:
    """Raise AllocationError unless every pair names a known agent and task, no agent or task
    appears twice, and no pair has infinite cost."""
    if not isinstance(allocation, Allocation):
        raise AllocationError(f"allocator returned {type(allocation).__name__}, not an Allocation")
    agent_index = {a.id: i for i, a in enumerate(problem.agents)}
    task_index = {t.id: j for j, t in enumerate(problem.tasks)}
    seen_agents: set[int] = set()
    seen_tasks: set[int] = set()
    for pair in allocation.pairs:
        try:
            aid, tid = pair
        except (TypeError, ValueError):
            raise AllocationError(f"pair {pair!r} is not an (agent_id, task_id) pair") from None
        if aid not in agent_index:
            raise AllocationError(f"unknown agent id {aid!r} (idle agents: {sorted(agent_index)})")
        if tid not in task_index:
            raise AllocationError(f"unknown task id {tid!r} (open tasks: {sorted(task_index)})")
        if tid in seen_tasks:
            raise AllocationError(f"task {tid} is given to more than one agent")
        if aid in seen_agents:
            raise AllocationError(f"agent {aid} is given more than one task")
        if not math.isfinite(problem.cost[agent_index[aid], task_index[tid]]):
            raise AllocationError(f"agent {aid} cannot serve task {tid} (infinite cost)")
        seen_agents.add(aid)
        seen_tasks.add(tid)


class Dispatcher:
    """Owns the wake-up event and the decision step of one simulation."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self.wake = sim.env.event()
        self.decisions = 0
        self.cost_seconds = 0.0
        self.decide_seconds = 0.0
        self.rounds = 0
        self.messages = 0
        self.process = sim.env.process(self._loop())

    def notify(self) -> None:
        """Ask for a decision (idempotent until the dispatcher wakes)."""
        if not self.wake.triggered:
            self.wake.succeed()

    def _loop(self):
        env, window = self.sim.env, self.sim.spec.scenario.dispatch.batch_window
        while True:
            yield self.wake
            yield env.timeout(window)
            self.wake = env.event()
            self.decide()

    def decide(self) -> None:
        """One decision over the idle vehicles and the open tasks (nothing if either is empty)."""
        sim = self.sim
        idle = [v for v in sim.vehicles if not v.busy]
        open_tasks = [t for t in sim.tasks if t.state is TaskState.OPEN]
        if not idle or not open_tasks:
            return
        agents = tuple(v.view() for v in idle)
        t0 = time.perf_counter()
        cost = sim.planner.costs(agents, tuple(t.view() for t in open_tasks))
        servable = np.isfinite(cost).any(axis=0)
        if not servable.all():
            self._close_unreachable([t for t, ok in zip(open_tasks, servable) if not ok])
        cost_s = time.perf_counter() - t0
        self.cost_seconds += cost_s
        if not servable.any():
            return
        open_tasks = [t for t, ok in zip(open_tasks, servable) if ok]
        problem = AllocationProblem(
            time=sim.env.now, agents=agents, tasks=tuple(t.view() for t in open_tasks),
            cost=np.ascontiguousarray(cost[:, servable]), comm=np.ones((len(idle),) * 2, bool),
            rng=sim.alloc_rng, max_rounds=sim.spec.scenario.dispatch.max_rounds,
        )
        t1 = time.perf_counter()
        allocation = sim.allocator.allocate(problem)
        decide_s = time.perf_counter() - t1
        validate(problem, allocation)
        self.decide_seconds += decide_s
        self.rounds += allocation.rounds
        self.messages += allocation.messages
        sim.record_decision(self.decisions, problem, allocation, cost_s, decide_s)
        self.decisions += 1
        conflicted = allocation.conflicted_tasks()
        by_task = {t.id: t for t in open_tasks}
        by_agent = {v.id: v for v in idle}
        for t in open_tasks:
            t.offered = True
            t.conflicted = t.conflicted or t.id in conflicted
        col = {t.id: j for j, t in enumerate(open_tasks)}
        row = {a.id: i for i, a in enumerate(agents)}
        for aid, tid in allocation.pairs:
            sim.assign(by_task[tid], by_agent[aid], float(problem.cost[row[aid], col[tid]]))

    def _close_unreachable(self, tasks) -> None:
        """Close tasks no vehicle of the fleet can reach; vehicles never leave their connected
        component of free space, so a task unreachable from every vehicle's cell stays so."""
        sim = self.sim
        busy = tuple(v.view() for v in sim.vehicles if v.busy)
        if busy:
            c = sim.planner.costs(busy, tuple(t.view() for t in tasks))
            tasks = [t for t, ok in zip(tasks, np.isfinite(c).any(axis=0)) if not ok]
        for t in tasks:
            sim.close_task(t, TaskState.UNREACHABLE)
