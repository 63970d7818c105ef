"""The dispatcher: a SimPy process that turns idle vehicles and open tasks into assignments.

It wakes when a task is released or a vehicle becomes idle (deciding at once, only while a
task is open: see :meth:`Dispatcher.notify`), waits the optional batching window
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

Re-assignment before pickup (``[dispatch] reassign = true``, road networks). A decision also
considers the vehicles still driving to a pickup (as FleetPy and MATSim DRT allow): they join
the problem's agents (where they are at the decision, part-way along an edge included) and
their tasks join its tasks. A vehicle whose answer is its own task drives on. One given another
task, or none while its task goes to another vehicle, gives its task up (a ``reassign`` event
naming the vehicle and the task; :meth:`Operator.give_up`): it stops where it is, the task is
open again (release time and deadline kept) and the hand-out's ``assign`` events follow; a
vehicle left without a task is idle where it stopped. A vehicle that gets nothing while its
task gets no one keeps its task. The summary counts ``reassignments``.

Lazy exact costs (``[dispatch] lazy_costs = true``, with a planner that computes lower bounds
and an allocator that minimizes the total cost): the decision starts from the planner's lower
bounds and computes exact costs only for the pairs an optimal answer needs, in the certificate
loop of :mod:`dispatch.lazy`; tasks become unreachable, rejected or left out exactly as with
exact costs. The recorded problem's cost matrix then holds bounds beside the exact costs of
the pairs handed out.

Cost per decision. The idle vehicles come from the fleet's arrays as an
:class:`~dispatch.contracts.AgentViews` (views built only when read), the answer is checked
pair by pair (no dict over all agents), and with an unlimited communication range the
problem's ``comm`` is a broadcast all-True array: a decision's Python work grows with its
tasks, not with the fleet.

The dispatcher is handed what it needs (the task book, the fleet, the operator that hands tasks
to vehicles, the planner, the allocator, the space, its configuration) and reaches into nothing
else; each decision goes to ``on_decision`` (the recorder). It decides and hands out; the plan
machinery (insertion costs, the problem's plans) is :mod:`dispatch.plans`'s and the checking of
an answer :mod:`dispatch.answers`'s (``validate`` and ``route_stops`` are importable from here).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

# answer checking; validate and route_stops stay importable from here (plugins' tests use them)
from dispatch.answers import finders, route_stops, validate  # noqa: F401
from dispatch.comms import comm_graph, components
from dispatch.contracts import Allocation, AllocationProblem, Allocator, Planner
from dispatch.errors import AllocationError, DispatchError, PluginError
from dispatch.heap import keep_large_blocks
from dispatch.lazy import certify, resolve_open
from dispatch.plans import Inserts, Plans, insertion_costs_of, roomy
from dispatch.space import Space
from dispatch.stops import OBJECTIVES
from dispatch.tasks import OPEN, TaskBook, TaskState

if TYPE_CHECKING:
    import simpy

    from dispatch.scenario import CommsConfig, DispatchConfig
    from dispatch.vehicles import Fleet, Operator

log = logging.getLogger(__name__)


def _line(e: BaseException, limit: int = 400) -> str:
    """An exception's message on one line, at most ``limit`` characters."""
    text = " ".join(str(e).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _positions(space: Space, agents) -> np.ndarray:
    """``(N, 3)`` positions of a decision's agents: from their node array where the sequence
    carries one (road points part-way along an edge one by one), else view by view."""
    nodes = getattr(agents, "nodes", None)
    if nodes is None:
        return space.positions([a.loc for a in agents])
    out = space.positions(nodes)
    for k in agents.points.tolist():
        out[k] = space.positions([agents[k].loc])[0]
    return out


class DecisionDeferred(BaseException):
    """Raised by an allocator's ``allocate`` to answer the decision later, from outside the
    simulation (:mod:`dispatch.rl`): the dispatcher's loop waits for ``resume`` (an event
    the deferring code triggers at the same simulated instant, once it holds the answer) and
    then decides again (see :meth:`Dispatcher._decide_or_defer`). A ``BaseException`` so
    that the dispatcher's wrapping of plugin errors lets it through; raise it only before
    the problem's state is touched (``allocate`` is the last step before the hand-out)."""

    def __init__(self, resume: simpy.Event) -> None:
        super().__init__("decision deferred")
        self.resume = resume


@dataclass
class _Pending:
    """A decision taken and validated, waiting for its hand-out (after the comms delay)."""

    problem: AllocationProblem
    allocation: Allocation
    tasks: list
    cost_s: float
    decide_s: float
    delay: float
    components: int
    holder: dict = field(default_factory=dict)  # reassign: task id -> vehicle id at decision
    index: list = field(default_factory=list)  # each pair's (row, column) in the problem
    #: shared rides: (row, column) of a pair whose vehicle has a plan -> where its stops go
    #: (see :class:`dispatch.stops.Insertions`)
    inserts: Inserts | dict = field(default_factory=dict)


class Dispatcher:
    """Owns the wake-up event and the decision step of one simulation."""

    def __init__(self, env: simpy.Environment, book: TaskBook, fleet: Fleet, operator: Operator,
                 planner: Planner, allocator: Allocator, space: Space, cfg: DispatchConfig,
                 comms: CommsConfig, rng: np.random.Generator,
                 on_decision: Callable[..., None], links=None, *, pooled: bool = False,
                 max_delay: bool = False) -> None:
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
        self.reassignments = 0  # [dispatch] reassign: tasks a vehicle gave up for another
        self.agent_seconds = 0.0  # sum over decisions of the per-agent critical path
        self.first_cost = math.nan  # the first decision's total cost and wall seconds
        self.first_seconds = math.nan
        self._pending: _Pending | None = None
        #: [dispatch] lazy_costs, with a planner and an allocator that support it
        self.lazy = bool(getattr(cfg, "lazy_costs", False))
        if self.lazy and not (getattr(planner, "lower_bounds", False)
                              and getattr(allocator, "minimizes_total_cost", False)):
            log.warning("lazy_costs is on but planner %r computes no lower bounds or allocator "
                        "%r does not minimize the total cost: exact costs are used",
                        planner.name, allocator.name)
            self.lazy = False
        #: the vehicles have plans to insert into (a capacity above 1), requests have drop-off
        #: limits or the objective is the added time: costs are insertion costs (dispatch.stops)
        self.pooled = bool(pooled)
        self.plans = self.pooled or cfg.objective != "pickup_time" or bool(max_delay)
        self.objective = OBJECTIVES[cfg.objective]
        #: the planner routes between any two locations (direct times, insertions)
        self.routes = bool(getattr(planner, "travel_times", False))
        #: [fleet.energy]: ``(cost, drive, slots, tasks) -> cost`` with ``inf`` where a vehicle
        #: would end below its reserve (dispatch.battery.Energy.filter); None without energy
        self.energy_filter = None
        if self.plans and not self.routes:
            raise PluginError(f"planner {planner.name!r} computes no travel times between "
                              "locations (Planner.between): shared rides, max_delay and the "
                              "added_time objective need them")
        if self.lazy and self.plans:
            log.warning("lazy_costs is off: shared rides, max_delay and the added_time "
                        "objective cost insertions exactly")
            self.lazy = False
        self.lazy_rounds = 0  # lazy costs: allocator calls (one per certificate round)
        self.lazy_pairs = 0  # lazy costs: pairs whose exact cost was computed
        self._everyone: dict[int, np.ndarray] = {}  # n -> read-only all-True (n, n), no memory
        #: the run's id, for error messages (set by the simulation)
        self.run_id = ""
        keep_large_blocks()  # a batch's big arrays reuse heap memory (see dispatch.heap)
        self.process = env.process(self._loop())

    def _where(self, kind: str) -> str:
        """Where an error happened: the plugin, the run, the decision and the simulated time."""
        plugin = self.allocator if kind == "allocator" else self.planner
        name = getattr(plugin, "name", "") or type(plugin).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return f"{kind} {name!r}{run}, decision {self.decisions}, t = {self.env.now:.6g} s"

    def _bad_costs(self, cost, want: tuple[int, int]) -> PluginError:
        got = (f"{type(cost).__name__} {getattr(cost, 'shape', '')} "
               f"{getattr(cost, 'dtype', '')}").strip()
        return PluginError(f"{self._where('planner')}: costs() must return a float array of "
                           f"shape {want} without nan, got {got}")

    def _plugin_failed(self, kind: str, e: Exception) -> PluginError:
        reason = _line(e) or "(no message)"
        return PluginError(f"{self._where(kind)}: {kind} raised {type(e).__name__}: {reason}")

    def notify(self) -> None:
        """Ask for a decision (idempotent until the dispatcher wakes).

        Deciding at once (no batching window, no re-assignment), a call while no task is
        open is dropped: the decision would find nothing to do (a vehicle that becomes idle
        then costs no wake-up; the next release asks again). Only the order of decisions
        among events of one same simulated instant could differ, and only when a task is
        released at exactly the instant an idle vehicle's call would have been answered."""
        if not self.wake.triggered and (self.book.open or self.cfg.batch_window > 0
                                        or self.cfg.reassign):
            self.wake.succeed()

    def _loop(self):
        env, window = self.env, self.cfg.batch_window
        while True:
            yield self.wake
            yield env.timeout(window)
            self.wake = env.event()
            yield from self._decide_or_defer()
            if self._pending is not None:
                yield env.timeout(self._pending.delay)
                self._hand_out()

    def _decide_or_defer(self):
        """:meth:`decide`, or, when the allocator defers it (:class:`DecisionDeferred`: the
        answer comes from outside the simulation, see :mod:`dispatch.rl`), wait for the
        deferring allocator's ``resume`` event and decide again: nothing moved meanwhile (the
        event is triggered at the same instant, ahead of the events already queued), so the
        same problem is built again and the allocator now answers it. The hook that lets
        :mod:`dispatch.rl` drive decisions step by step without threads; a run with an
        ordinary allocator goes through :meth:`decide` exactly as before."""
        try:
            self.decide()
        except DecisionDeferred as d:
            yield d.resume
            self.decide()

    def decide(self) -> None:
        """One decision over the idle vehicles and the open tasks (nothing if either is empty).

        Without latency the tasks are handed out at once; with it the hand-out waits in
        ``self._pending`` for the loop to let the simulated deliberation time pass.

        Its Python work grows with the open tasks, not the fleet: the idle vehicles come as
        an :class:`AgentViews` (arrays, views built on access), and a planner that reads the
        arrays (the road planner does) costs them with numpy."""
        held = self.book.assigned if self.cfg.reassign else {}
        if not self.book.open and not held:
            return
        if self.routes:
            self._direct_times()
        idle = self.fleet.idle_index()
        if self.pooled:  # busy vehicles with a free seat somewhere in their plan take part
            idle = np.union1d(idle, roomy(self.fleet))
        holder: dict[int, int] = {}  # task id -> the vehicle driving to its pickup
        if held:  # [dispatch] reassign: vehicles driving to a pickup take part, with their tasks
            holder = {t.id: t.agent_id for t in held.values()}
            slots = np.array([self.fleet.by_id[a]._slot for a in holder.values()], np.int64)
            idle = np.union1d(idle, slots)
            open_tasks = sorted([*self.book.open.values(), *held.values()], key=lambda t: t.id)
        else:
            open_tasks = list(self.book.open.values())
        if not idle.size:
            return
        now = self.env.now
        agents = self.fleet.views(idle, now, ascending=True)  # flatnonzero, union1d: sorted
        t0 = time.perf_counter()
        tasks = tuple([t.view() for t in open_tasks])
        lazy = self.lazy
        cost, exact = self._planner_costs(agents, tasks)
        want = cost.shape
        # the usual case: a finite sum, so no inf and no nan (either would make the sum one):
        # every pair servable (a sum that overflows takes the element-wise checks below)
        if math.isfinite(np.add.reduce(cost, axis=None)):
            servable = None
        else:
            finite = np.isfinite(cost)
            if np.isnan(cost).any():
                raise self._bad_costs(cost, want)
            servable = finite.any(axis=0)
            if not servable.all():
                self._close_unreachable([t for t, ok in zip(open_tasks, servable) if not ok])
        deadlines = [t.deadline for t in open_tasks]
        drive = cost if self.energy_filter is not None else None
        inserts: dict = {}
        if self.plans:
            if servable is None:
                servable = np.ones(len(open_tasks), dtype=bool)
            cost, inserts = insertion_costs_of(cost, idle, open_tasks, now, set(holder.values()),
                                               fleet=self.fleet, operator=self.operator,
                                               planner=self.planner, objective=self.objective)
            servable = self._reject_late(open_tasks, cost, servable)
        elif any(d < math.inf for d in deadlines):
            if servable is None:
                servable = np.ones(len(open_tasks), dtype=bool)
            deadlines = np.array(deadlines)
            cost = np.where(now + cost <= deadlines + 1e-9, cost, np.inf)
            if lazy:  # late by its bound is late exactly; feasibility of each task made exact
                exact = exact | ~np.isfinite(cost)
                self.lazy_pairs += resolve_open(cost, exact, self._exact(agents, tasks), now,
                                                deadlines)
            servable = self._reject_late(open_tasks, cost, servable)
        if drive is not None:  # [fleet.energy]: below the reserve after the trip: inf
            cost = self.energy_filter(cost, drive, idle, open_tasks)
        cost_s = time.perf_counter() - t0
        self.cost_seconds += cost_s
        if servable is not None:
            if not servable.any():
                return
            if not servable.all():
                if inserts:  # their columns move left
                    inserts = inserts.kept(servable)
                open_tasks = [t for t, ok in zip(open_tasks, servable) if ok]
                tasks = tuple([t.view() for t in open_tasks])
                cost = cost[:, servable]
                if lazy:
                    exact = exact[:, servable]
        comms, space = self.comms, self.space
        comm, apos = self._hearing(agents, now)

        def tpos():
            return space.positions([t.loc for t in tasks])

        plans = Plans(self.fleet, self.operator, idle) if self.pooled else None
        seats = self.fleet.capacity[idle] if self.pooled else None
        ready = np.maximum(self.fleet.free_at[idle], now) if self.pooled else None
        travel = self.planner.between if self.routes else None

        def ask(cost: np.ndarray):
            problem = AllocationProblem.made(now, agents, tasks, np.array(cost, order="C"),
                                             comm, self.rng, self.cfg.max_rounds, comms.loss,
                                             comms.latency, self.cell_size, apos, tpos, plans,
                                             seats, self.operator.service_time, travel,
                                             ready)
            allocation, decide_s, index = self._ask(problem)
            return problem, allocation, decide_s, index

        if lazy:
            problem, allocation, decide_s, index, extra = self._certified(
                ask, cost, exact, agents, tasks, np.array([t.deadline for t in open_tasks]), now)
            cost_s += extra  # computing exact pairs is cost time
        else:
            problem, allocation, decide_s, index = ask(cost)
        self.decide_seconds += decide_s
        delay = allocation.hops * comms.latency
        conflicted = allocation.conflicted_tasks() if allocation.requests else set()
        for t in open_tasks:
            t.offered = True
            t.conflicted = t.conflicted or t.id in conflicted
        n_comp = 1 if comm.strides == (0, 0) else components(comm)[0]
        self._pending = _Pending(problem, allocation, open_tasks, cost_s, decide_s, delay,
                                 n_comp, holder, index, inserts)
        if delay <= 0:
            self._hand_out()

    def _planner_costs(self, agents, tasks):
        """The planner's ``(cost, exact)`` of a decision: its exact costs (``exact`` None), or
        with lazy costs its lower bounds and which of them are exact; a PluginError naming the
        planner and the decision for an exception or an answer of the wrong type or shape."""
        exact = None  # lazy costs: which entries of ``cost`` are exact (the others are bounds)
        try:
            if self.lazy:
                cost, exact = self.planner.bounds(agents, tasks)
                exact = np.array(exact, dtype=bool) if isinstance(exact, np.ndarray) else exact
            else:
                cost = self.planner.costs(agents, tasks)
        except DispatchError:
            raise
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self._plugin_failed("planner", e) from e
        want = (len(agents), len(tasks))
        if not isinstance(cost, np.ndarray) or cost.shape != want or cost.dtype.kind != "f":
            raise self._bad_costs(cost, want)
        if self.lazy and not (isinstance(exact, np.ndarray) and exact.shape == want
                              and exact.dtype == bool):
            raise PluginError(f"{self._where('planner')}: bounds() must return a bool array "
                              f"of shape {want} as its second item")
        return cost, exact

    def _reject_late(self, open_tasks: list, cost: np.ndarray,
                     servable: np.ndarray) -> np.ndarray:
        """``servable`` less the tasks no vehicle can reach in time (no finite cost); of those,
        a task offered for the first time is closed ``rejected`` at once (see the module
        doc), one offered before waits for its deadline."""
        late = servable & ~np.isfinite(cost).any(axis=0)
        for t, bad in zip(open_tasks, late):
            if bad and not t.offered:
                self.book.close(t, TaskState.REJECTED)
        return servable & ~late

    def _hearing(self, agents, now: float):
        """``(comm, positions)`` of a decision's agents: who hears whom (the ``[comms]`` range,
        a blackout's links) and their ``(N, 3)`` positions; with an unlimited range and no
        faults a broadcast all-True ``comm`` (no N x N matrix) and the positions as a function
        computed only if someone reads them (nothing moves within the decision)."""
        comms, space = self.comms, self.space
        unlimited = comms.range is None or math.isinf(comms.range)
        if unlimited and self.links is None:  # everyone hears everyone: no N x N matrix
            comm = self._everyone.get(len(agents))
            if comm is None:
                comm = self._everyone[len(agents)] = np.broadcast_to(np.True_, (len(agents),) * 2)
            nodes = getattr(agents, "nodes", None)
            if nodes is not None and not agents.points.size:
                def apos():  # node positions (fixed now), computed if someone reads them
                    return space.positions(nodes)
            else:  # read if someone asks, within the decision (nothing moves meanwhile)
                def apos():
                    return _positions(space, agents)
            return comm, apos
        apos = _positions(space, agents)
        comm = comm_graph(apos, comms.range)
        if self.links is not None:
            comm = self.links(comm, apos, now)
        return comm, apos

    def _certified(self, ask, cost, exact, agents, tasks, deadlines, now: float):
        """The certificate loop of lazy costs (:func:`dispatch.lazy.certify`) around ``ask``:
        ``(problem, allocation, allocator seconds, pair indices, seconds spent computing exact
        pairs)``; the latter are added to :attr:`cost_seconds`."""
        spent = [0.0]

        def timed(c):
            t = time.perf_counter()
            answer = ask(c)
            spent[0] += time.perf_counter() - t
            return answer

        t0 = time.perf_counter()
        (problem, allocation, _, index), rounds, pairs = certify(
            timed, cost, exact, self._exact(agents, tasks), now, deadlines)
        extra = time.perf_counter() - t0 - spent[0]
        self.cost_seconds += extra
        self.lazy_rounds += rounds
        self.lazy_pairs += pairs
        return problem, allocation, spent[0], index, extra

    def _exact(self, agents, tasks):
        """``compute(rows, cols)``: the planner's exact costs of those pairs (lazy costs)."""
        def compute(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            try:
                values = self.planner.exact(agents, tasks, rows, cols)
            except DispatchError:
                raise
            except Exception as e:  # a plugin's bug: one line naming it and where
                raise self._plugin_failed("planner", e) from e
            values = np.asarray(values, dtype=float).reshape(-1)
            if values.shape != rows.shape or np.isnan(values).any():
                raise PluginError(f"{self._where('planner')}: exact() must return "
                                  f"{rows.size} costs without nan, got {values.shape}")
            return values
        return compute

    def _ask(self, problem: AllocationProblem):
        """The allocator's answer to ``problem``, checked: ``(allocation, seconds it took,
        each pair's (row, column))``."""
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
        multi = bool(getattr(self.allocator, "multi_request", False))
        try:
            index = validate(problem, allocation, multi)
            routes = self._routes(problem, allocation) if multi and allocation.routes else {}
        except AllocationError as e:
            raise AllocationError(f"{self._where('allocator')}: {e}") from None
        if routes:
            object.__setattr__(allocation, "_checked_routes", routes)  # (a cache, frozen)
        return allocation, decide_s, index

    def _routes(self, problem: AllocationProblem, allocation: Allocation) -> dict:
        """The routes of a multi-request answer, checked: agent id -> (stop rows of
        :func:`route_stops`, planned arrival times); AllocationError where a route breaks the
        capacity or a limit."""
        by_task = {t.id: t for t in problem.tasks}
        new: dict[int, dict] = {}
        for aid, tid in allocation.pairs:
            new.setdefault(aid, {})[tid] = by_task[tid]
        out = {}
        for aid, route in allocation.routes.items():
            rows = route_stops(problem, aid, route, new.get(aid, {}))
            v = self.fleet.by_id[int(aid)]
            times, why = self.operator.route_times(v, rows)
            if why:
                raise AllocationError(f"route of agent {aid} is infeasible: {why}")
            out[int(aid)] = (rows, times)
        return out

    def _hand_out(self) -> None:
        """Record the pending decision and give each vehicle its task (see the module doc)."""
        p, self._pending = self._pending, None
        if p is None:
            return
        by_task = {t.id: t for t in p.tasks}
        by_id = self.fleet.by_id
        holding = {a: t for t, a in p.holder.items()}  # vehicle -> its task at the decision
        allocation = p.allocation
        cost = p.problem.cost
        if not holding and (p.delay <= 0 or all(by_task[t].state is OPEN and not by_id[a].busy
                                                for a, t in allocation.pairs)):
            # (without latency nothing changed since the decision; with it, a pooled pair
            # whose vehicle moved on is stale: the slow path below drops it)
            handed = tuple(allocation.pairs)
            pair_cost = [float(cost[i, j]) for i, j in p.index]
            routes = allocation.__dict__.get("_checked_routes")
            if routes:
                self._follow(p, allocation, routes, pair_cost)
                return
            if p.inserts:
                at = [p.inserts.get(ij) for ij in p.index]
                for (aid, tid), c, a in zip(handed, pair_cost, at):
                    self.operator.assign(by_task[tid], by_id[aid], c, a)
                self._recorded(p, allocation, pair_cost)
                return
        else:
            def still(a: int) -> bool:  # a vehicle of the decision, as it was then
                v = by_id[a]
                if a not in holding:
                    return not v.busy
                task = self.operator.holds(v)
                return task is not None and task.id == holding[a] \
                    and task.state is TaskState.ASSIGNED

            def available(t: int) -> bool:  # a task of the decision, as it was then
                task = by_task[t]
                return task.state is TaskState.OPEN if t not in p.holder else (
                    task.state is TaskState.ASSIGNED and task.agent_id == p.holder[t])

            handed = tuple((a, t) for a, t in allocation.pairs if available(t) and still(a))
            routes = allocation.__dict__.get("_checked_routes") or {}
            if routes:  # a route planned before the deliberation is stale: dropped
                handed = tuple((a, t) for a, t in handed if a not in routes)
            if p.inserts:  # a pooled pair is stale once its vehicle has moved on: dropped
                row, col = finders(p.problem)
                handed = tuple((a, t) for a, t in handed
                               if (row(a), col(t)) not in p.inserts)
            if len(handed) != len(allocation.pairs):
                log.debug("decision %d: %d pair(s) not handed out (task closed while deciding)",
                          self.decisions, len(allocation.pairs) - len(handed))
                allocation = replace(allocation, pairs=handed)
                self.notify()
            row, col = finders(p.problem)
            pair_cost = [float(cost[row(a), col(t)]) for a, t in allocation.pairs]
        self._recorded(p, allocation, pair_cost)
        if not holding:
            for (aid, tid), c in zip(handed, pair_cost):  # allocation.pairs is handed
                self.operator.assign(by_task[tid], by_id[aid], c)
            return
        self._reassign(p, holding, handed, pair_cost, still)

    def _follow(self, p: _Pending, allocation: Allocation, routes: dict,
                pair_cost: list[float]) -> None:
        """Hand out a multi-request answer: routed agents drive their routes (a routed pair's
        cost is the seconds from the decision to its planned pickup), the others get their
        one request as usual."""
        by_task = {t.id: t for t in p.tasks}
        by_id = self.fleet.by_id
        now = self.env.now
        mine: dict[int, dict] = {}
        for k, (aid, tid) in enumerate(allocation.pairs):
            if aid in routes:
                rows, times = routes[aid]
                at = next(t for (kind, task, *_), t in zip(rows, times)
                          if kind == "pickup" and task == tid)
                pair_cost[k] = at - now
                mine.setdefault(aid, {})[tid] = pair_cost[k]
        self._recorded(p, allocation, pair_cost)
        for (aid, tid), c, ij in zip(allocation.pairs, pair_cost, p.index):
            if aid not in routes:
                self.operator.assign(by_task[tid], by_id[aid], c, p.inserts.get(ij))
        for aid, costs in mine.items():
            rows, times = routes[aid]
            self.operator.follow(by_id[aid], rows, times, {t: by_task[t] for t in costs},
                                 costs)

    def _recorded(self, p: _Pending, allocation: Allocation, pair_cost: list[float]) -> None:
        """Count and record a decision's hand-out (``allocation`` as handed out)."""
        critical = max(allocation.agent_seconds, default=p.decide_s)
        self.rounds += allocation.rounds
        self.messages += allocation.messages
        self.comm_delay += p.delay
        self.agent_seconds += critical
        total = float(sum(pair_cost))
        if self.decisions == 0:
            self.first_cost, self.first_seconds = total, p.cost_s + p.decide_s
        self.on_decision(self.decisions, p.problem, allocation, total, p.cost_s, p.decide_s,
                         hops=allocation.hops, comm_delay=p.delay, agent_seconds=critical,
                         components=p.components)
        self.decisions += 1

    def _reassign(self, p: _Pending, holding: dict, handed: tuple, pair_cost: list[float],
                  still) -> None:
        """The hand-out of a decision with re-assignment before pickup."""
        by_task = {t.id: t for t in p.tasks}
        by_id = self.fleet.by_id
        # reassign: a vehicle driving to a pickup gives its task up when it gets another task,
        # or none while its task goes to another vehicle; otherwise it keeps it
        new_task = dict(handed)
        taken = set(new_task.values())
        give = sorted(a for a, t in holding.items() if still(a) and (
            new_task.get(a, t) != t or (a not in new_task and t in taken)))
        for a in give:
            self.operator.give_up(by_id[a])
        self.reassignments += len(give)
        for (aid, tid), c in zip(handed, pair_cost):
            if holding.get(aid) != tid:
                self.operator.assign(by_task[tid], by_id[aid], c)
        for a in give:
            if a not in new_task:
                self.operator.stand_idle(by_id[a])

    def _direct_times(self) -> None:
        """Set the free-flow direct drive time of open requests that have none yet (the first
        decision that considers a request; a congested planner's inner, free-flow one)."""
        need = [t for t in self.book.open.values()
                if t.dropoff is not None and t.direct_time != t.direct_time]
        if not need:
            return
        free = getattr(self.planner, "inner", self.planner)
        times = free.between([t.loc for t in need], [t.dropoff for t in need], pairwise=True)
        for t, x in zip(need, np.asarray(times, dtype=float).tolist()):
            t.direct_time = x

    def _close_unreachable(self, tasks) -> None:
        """Close tasks no vehicle of the fleet can reach; vehicles never leave their connected
        component of free space, so a task unreachable from every vehicle's cell stays so."""
        now = self.env.now
        busy = self.fleet.views(np.flatnonzero([v.busy for v in self.fleet.vehicles]), now)
        if busy:
            views = tuple(t.view() for t in tasks)  # lazy: an inf bound is an inf cost
            c = self.planner.bounds(busy, views)[0] if self.lazy else \
                self.planner.costs(busy, views)
            tasks = [t for t, ok in zip(tasks, np.isfinite(c).any(axis=0)) if not ok]
        for t in tasks:
            self.book.close(t, TaskState.UNREACHABLE)
