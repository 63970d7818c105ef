"""The dispatcher: a SimPy process that turns idle vehicles and open tasks into assignments.

It wakes when a task is released or a vehicle becomes idle, waits the optional batching window
(a zero window still lets every event of the same instant land first), builds an
:class:`AllocationProblem` with the planner's cost matrix and the communication graph of the idle
vehicles (from their positions and the scenario's ``[comms] range``; see :mod:`dispatch.comms`),
asks the allocator, checks the answer and hands the tasks to the vehicles.

Latency. With ``[comms] latency > 0`` a decision takes simulated time: the allocator reports the
sequential message hops of its decision (:attr:`Allocation.hops`; 0 for centralized methods)
and the dispatcher hands the tasks out ``hops * latency`` seconds after the decision started.
Meanwhile the deciding vehicles stay idle where they are and the dispatcher takes no other
decision (events that arrive meanwhile trigger the next one, right after the hand-out). A pair
whose task closed meanwhile (it expired) is not handed out: that vehicle stays idle and the next
decision considers it again. The ``decisions`` row is written at the hand-out and counts only
the pairs handed out; the summary's rounds, messages and comm delay are added up at the
hand-out too, so they always match the ``decisions`` table (a decision cut short by the end of
the run is in neither). Tasks are stamped ``assigned_at`` at the hand-out, so the deliberation
shows in wait times.

Requests with a ``max_wait``. A pair whose vehicle would reach the pickup after the request's
deadline (``released_at + max_wait``) is infeasible (``inf`` in the problem's cost). A request
that, the first time it is offered, no idle vehicle can reach in time is closed ``rejected`` at
once (as ride-hailing studies reject a request nobody can serve); one that had a chance but is
still open at its deadline expires.

The dispatcher is handed what it needs (the task book, the fleet, the operator that hands tasks
to vehicles, the planner, the allocator, the space, its configuration) and reaches into nothing
else; each decision goes to ``on_decision`` (the recorder).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from dispatch.comms import comm_graph, components
from dispatch.contracts import Allocation, AllocationProblem, Allocator, Planner
from dispatch.errors import AllocationError, DispatchError, PluginError
from dispatch.space import Space
from dispatch.tasks import TaskBook, TaskState

if TYPE_CHECKING:
    import simpy

    from dispatch.scenario import CommsConfig, DispatchConfig
    from dispatch.vehicles import Fleet, Operator

log = logging.getLogger(__name__)


def _line(e: BaseException, limit: int = 400) -> str:
    """An exception's message on one line, at most ``limit`` characters."""
    text = " ".join(str(e).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _ids(ids) -> str:
    ids = sorted(ids)
    return str(ids) if len(ids) <= 10 else f"[{', '.join(map(str, ids[:10]))}, ...] ({len(ids)})"


def validate(problem: AllocationProblem, allocation: Allocation) -> None:
    """Raise AllocationError unless every pair names a known agent and task, no agent or task
    appears twice, and no pair has infinite cost (and the counters are whole numbers >= 0)."""
    if not isinstance(allocation, Allocation):
        raise AllocationError(f"allocator returned {type(allocation).__name__}, not an Allocation")
    for k in ("rounds", "messages", "hops"):
        v = getattr(allocation, k)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise AllocationError(f"Allocation.{k} must be an integer >= 0, got {v!r}")
    try:
        pairs = tuple(allocation.pairs)
    except TypeError:
        raise AllocationError(f"Allocation.pairs must be a sequence of (agent_id, task_id) "
                              f"pairs, got {type(allocation.pairs).__name__}") from None
    agent_index = {a.id: i for i, a in enumerate(problem.agents)}
    task_index = {t.id: j for j, t in enumerate(problem.tasks)}
    seen_agents: set[int] = set()
    seen_tasks: set[int] = set()
    hint = ("; pairs name agents and tasks by id, not by index (Allocation.centralized "
            "turns index pairs into id pairs)")
    for pair in pairs:
        try:
            aid, tid = pair
            hash(aid), hash(tid)
        except (TypeError, ValueError):
            raise AllocationError(f"pair {pair!r} is not an (agent_id, task_id) pair") from None
        if aid not in agent_index:
            by_index = isinstance(aid, (int, np.integer)) and 0 <= aid < len(agent_index)
            raise AllocationError(f"unknown agent id {aid!r} (idle agents: "
                                  f"{_ids(agent_index)}){hint if by_index else ''}")
        if tid not in task_index:
            by_index = isinstance(tid, (int, np.integer)) and 0 <= tid < len(task_index)
            raise AllocationError(f"unknown task id {tid!r} (open tasks: "
                                  f"{_ids(task_index)}){hint if by_index else ''}")
        if tid in seen_tasks:
            raise AllocationError(f"task {tid} is given to more than one agent")
        if aid in seen_agents:
            raise AllocationError(f"agent {aid} is given more than one task")
        if not math.isfinite(problem.cost[agent_index[aid], task_index[tid]]):
            raise AllocationError(f"agent {aid} cannot serve task {tid} (infinite cost)")
        seen_agents.add(aid)
        seen_tasks.add(tid)


@dataclass
class _Pending:
    """A decision taken and validated, waiting for its hand-out (after the comms delay)."""

    problem: AllocationProblem
    allocation: Allocation
    tasks: list
    vehicles: list
    cost_s: float
    decide_s: float
    delay: float
    components: int


class Dispatcher:
    """Owns the wake-up event and the decision step of one simulation."""

    def __init__(self, env: simpy.Environment, book: TaskBook, fleet: Fleet, operator: Operator,
                 planner: Planner, allocator: Allocator, space: Space, cfg: DispatchConfig,
                 comms: CommsConfig, rng: np.random.Generator,
                 on_decision: Callable[..., None], links=None) -> None:
        self.env, self.book, self.fleet, self.operator = env, book, fleet, operator
        self.planner, self.allocator, self.space = planner, allocator, space
        self.cfg, self.comms, self.rng, self.on_decision = cfg, comms, rng, on_decision
        #: ``links(comm, positions, now) -> comm``: communication faults (a blackout), or None
        self.links = links
        self.cell_size = float(getattr(space, "cell", 1.0))
        self.wake = env.event()
        self.decisions = 0
        self.cost_seconds = 0.0
        self.decide_seconds = 0.0
        self.rounds = 0
        self.messages = 0
        self.comm_delay = 0.0  # simulated seconds spent deliberating (hops * latency)
        self.agent_seconds = 0.0  # sum over decisions of the per-agent critical path
        self.first_cost = math.nan  # the first decision's total cost and wall seconds
        self.first_seconds = math.nan
        self._pending: _Pending | None = None
        #: the run's id, for error messages (set by the simulation)
        self.run_id = ""
        self.process = env.process(self._loop())

    def _where(self, kind: str) -> str:
        """Where an error happened: the plugin, the run, the decision and the simulated time."""
        plugin = self.allocator if kind == "allocator" else self.planner
        name = getattr(plugin, "name", "") or type(plugin).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return f"{kind} {name!r}{run}, decision {self.decisions}, t = {self.env.now:.6g} s"

    def _plugin_failed(self, kind: str, e: Exception) -> PluginError:
        reason = _line(e) or "(no message)"
        return PluginError(f"{self._where(kind)}: {kind} raised {type(e).__name__}: {reason}")

    def notify(self) -> None:
        """Ask for a decision (idempotent until the dispatcher wakes)."""
        if not self.wake.triggered:
            self.wake.succeed()

    def _loop(self):
        env, window = self.env, self.cfg.batch_window
        while True:
            yield self.wake
            yield env.timeout(window)
            self.wake = env.event()
            self.decide()
            if self._pending is not None:
                yield env.timeout(self._pending.delay)
                self._hand_out()

    def decide(self) -> None:
        """One decision over the idle vehicles and the open tasks (nothing if either is empty).

        Without latency the tasks are handed out at once; with it the hand-out waits in
        ``self._pending`` for the loop to let the simulated deliberation time pass."""
        idle = self.fleet.idle()
        open_tasks = list(self.book.open.values())
        if not idle or not open_tasks:
            return
        now = self.env.now
        agents = tuple(v.view(now) for v in idle)
        t0 = time.perf_counter()
        try:
            cost = self.planner.costs(agents, tuple(t.view() for t in open_tasks))
        except DispatchError:
            raise
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self._plugin_failed("planner", e) from e
        want = (len(agents), len(open_tasks))
        if not isinstance(cost, np.ndarray) or cost.shape != want \
                or not np.issubdtype(cost.dtype, np.floating) or np.isnan(cost).any():
            got = (f"{type(cost).__name__} {getattr(cost, 'shape', '')} "
                   f"{getattr(cost, 'dtype', '')}").strip()
            raise PluginError(f"{self._where('planner')}: costs() must return a float array of "
                              f"shape {want} without nan, got {got}")
        servable = np.isfinite(cost).any(axis=0)
        if not servable.all():
            self._close_unreachable([t for t, ok in zip(open_tasks, servable) if not ok])
        deadlines = np.array([t.deadline for t in open_tasks])
        if np.isfinite(deadlines).any():
            cost = np.where(now + cost <= deadlines + 1e-9, cost, np.inf)
            late = servable & ~np.isfinite(cost).any(axis=0)
            for t, bad in zip(open_tasks, late):
                if bad and not t.offered:
                    self.book.close(t, TaskState.REJECTED)
            servable &= ~late
        cost_s = time.perf_counter() - t0
        self.cost_seconds += cost_s
        if not servable.any():
            return
        open_tasks = [t for t, ok in zip(open_tasks, servable) if ok]
        comms = self.comms
        apos = self.space.positions([a.loc for a in agents])
        comm = comm_graph(apos, comms.range)
        if self.links is not None:
            comm = self.links(comm, apos, now)
        tasks = tuple(t.view() for t in open_tasks)
        problem = AllocationProblem(
            time=now, agents=agents, tasks=tasks,
            cost=np.ascontiguousarray(cost[:, servable]), comm=comm,
            rng=self.rng, max_rounds=self.cfg.max_rounds,
            loss=comms.loss, latency=comms.latency, cell_size=self.cell_size,
            agent_pos=apos, task_pos=self.space.positions([t.loc for t in tasks]),
        )
        t1 = time.perf_counter()
        cost_given = problem.cost
        try:
            allocation = self.allocator.allocate(problem)
        except AllocationError as e:
            raise AllocationError(f"{self._where('allocator')}: {_line(e)}") from e
        except DispatchError as e:
            raise PluginError(f"{self._where('allocator')}: {_line(e)}") from e
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self._plugin_failed("allocator", e) from e
        decide_s = time.perf_counter() - t1
        if problem.cost is not cost_given or problem.cost.flags.writeable:
            raise AllocationError(f"{self._where('allocator')}: the allocator replaced or made "
                                  "writable problem.cost (the problem is read-only; work on a "
                                  "copy)")
        try:
            validate(problem, allocation)
        except AllocationError as e:
            raise AllocationError(f"{self._where('allocator')}: {e}") from None
        self.decide_seconds += decide_s
        delay = allocation.hops * comms.latency
        conflicted = allocation.conflicted_tasks()
        for t in open_tasks:
            t.offered = True
            t.conflicted = t.conflicted or t.id in conflicted
        self._pending = _Pending(problem, allocation, open_tasks, idle, cost_s, decide_s, delay,
                                 components(comm)[0])
        if delay <= 0:
            self._hand_out()

    def _hand_out(self) -> None:
        """Record the pending decision and give each vehicle its task (see the module doc)."""
        p, self._pending = self._pending, None
        if p is None:
            return
        by_task = {t.id: t for t in p.tasks}
        by_agent = {v.id: v for v in p.vehicles}
        handed = tuple((a, t) for a, t in p.allocation.pairs
                       if by_task[t].state is TaskState.OPEN and not by_agent[a].busy)
        allocation = p.allocation
        if len(handed) != len(allocation.pairs):
            log.debug("decision %d: %d pair(s) not handed out (task closed while deciding)",
                      self.decisions, len(allocation.pairs) - len(handed))
            allocation = replace(allocation, pairs=handed)
            self.notify()
        critical = max(allocation.agent_seconds, default=p.decide_s)
        self.rounds += allocation.rounds
        self.messages += allocation.messages
        self.comm_delay += p.delay
        self.agent_seconds += critical
        col = {t.id: j for j, t in enumerate(p.tasks)}
        row = {a.id: i for i, a in enumerate(p.problem.agents)}
        total = float(sum(p.problem.cost[row[a], col[t]] for a, t in allocation.pairs))
        if self.decisions == 0:
            self.first_cost, self.first_seconds = total, p.cost_s + p.decide_s
        self.on_decision(self.decisions, p.problem, allocation, total, p.cost_s, p.decide_s,
                         hops=allocation.hops, comm_delay=p.delay, agent_seconds=critical,
                         components=p.components)
        self.decisions += 1
        for aid, tid in handed:
            self.operator.assign(by_task[tid], by_agent[aid],
                                 float(p.problem.cost[row[aid], col[tid]]))

    def _close_unreachable(self, tasks) -> None:
        """Close tasks no vehicle of the fleet can reach; vehicles never leave their connected
        component of free space, so a task unreachable from every vehicle's cell stays so."""
        now = self.env.now
        busy = tuple(v.view(now) for v in self.fleet.vehicles if v.busy)
        if busy:
            c = self.planner.costs(busy, tuple(t.view() for t in tasks))
            tasks = [t for t, ok in zip(tasks, np.isfinite(c).any(axis=0)) if not ok]
        for t in tasks:
            self.book.close(t, TaskState.UNREACHABLE)
