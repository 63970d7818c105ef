"""The dispatcher: a SimPy process that turns idle vehicles and open tasks into assignments.

It wakes when a task is released or a vehicle becomes idle (deciding at once, only while a
task is open: see :meth:`Dispatcher.notify`), waits the optional batching window
(a zero window still lets every event of the same instant land first), builds an
:class:`AllocationProblem` with the planner's cost matrix and the communication graph of the idle
vehicles (from their positions and the scenario's ``[comms] range``; see :mod:`dispatch.api.comms`),
asks the allocator, checks the answer and hands the tasks to the vehicles.

Latency. With ``[comms] latency > 0`` a decision takes simulated time: the allocator reports the
sequential message hops of its decision (:attr:`Allocation.hops`; 0 for centralized methods)
and the dispatcher hands the tasks out ``hops * latency`` seconds after the decision started.
Meanwhile the fleet moves on (an idle vehicle stays where it is, a busy one drives its plan)
and the dispatcher takes no other decision (events that arrive meanwhile trigger the next one,
right after the hand-out). At the hand-out each pair is costed again from the fleet as it is
then (:mod:`dispatch.decide.deliberation`): one whose task closed meanwhile (it expired), whose
vehicle is no longer a candidate or that no longer keeps every limit is not handed out (the
next decision, at once, considers them again); the others get the insertion planned at the
hand-out. The ``decisions`` row is written at the hand-out and counts only
the pairs handed out; the summary's rounds, messages and comm delay are added up at the
hand-out too, so they always match the ``decisions`` table (a decision cut short by the end of
the run is in neither). Tasks are stamped ``assigned_at`` at the hand-out, so the deliberation
shows in wait times.

Requests with a ``max_wait``. A pair whose vehicle would reach the pickup after the request's
deadline (``released_at + max_wait``) is infeasible (``inf`` in the problem's cost). A request
that, the first time it is offered, no idle vehicle can reach in time is closed ``rejected`` at
once (as ride-hailing studies reject a request nobody can serve); one that had a chance but is
still open at its deadline expires. With ``[dispatch] out_of_reach = "wait"`` none is rejected:
a request out of reach stays open, a vehicle that frees up near it may take it at a later
decision, and it expires at its deadline if none does.

Re-assignment before pickup (``[dispatch] reassign = true``, road networks). A decision also
considers the vehicles still driving to a pickup (as FleetPy and MATSim DRT allow): they join
the problem's agents (where they are at the decision, part-way along an edge included) and
their tasks join its tasks. A vehicle whose answer is its own task drives on. One given another
task, or none while its task goes to another vehicle, gives its task up (a ``reassign`` event
naming the vehicle and the task; :meth:`dispatch.plan.breakdowns.Breakdowns.give_up`): it stops
where it is, the task is open again (release time and deadline kept) and the hand-out's
``assign`` events follow; a vehicle left without a task is idle where it stopped. A vehicle
that gets nothing while its task gets no one keeps its task. The summary counts ``reassignments``.

Lazy exact costs (``[dispatch] lazy_costs = true``, with a planner that computes lower bounds
and an allocator that minimizes the total cost): the decision starts from the planner's lower
bounds and computes exact costs only for the pairs an optimal answer needs, in the certificate
loop of :mod:`dispatch.decide.lazy`; tasks become unreachable, rejected or left out exactly as with
exact costs. The recorded problem's cost matrix then holds bounds beside the exact costs of
the pairs handed out.

Cost per decision. The idle vehicles come from the fleet's arrays as an
:class:`~dispatch.api.problem.AgentViews` (views built only when read), the answer is checked
pair by pair (no dict over all agents), and with an unlimited communication range the
problem's ``comm`` is a broadcast all-True array: a decision's Python work grows with its
tasks, not with the fleet.

The dispatcher is handed what it needs (the wake-up call, the pipeline that builds each
decision's problem, the fleet, the operator that hands tasks to vehicles, the allocator, the
run's tally, its configuration) and reaches into nothing else; each decision goes to
``on_decision`` (the recorder). It asks and hands out: the problem is built in the named steps
of :mod:`dispatch.decide.pipeline` (costs, deadlines, insertions, the energy filter, lazy
certification, the comm graph), the plan machinery is :mod:`dispatch.decide.plan_costs`'s and the
checking
of an answer :mod:`dispatch.decide.answers`'s.

Offers riders may decline (``[acceptor]``, ``[pricing]``; see :mod:`dispatch.api.acceptor`). With an
``offering`` (:class:`dispatch.decide.offer_step.Offering`), each pair about to be handed out is
first
offered to its rider with the estimates of the plan the decision chose; a declined pair is
left out of the hand-out as a pair closed while deciding is (its stops never enter the plan;
a routed vehicle drives its route without them, re-timed), and the ``decisions`` row counts
the pairs handed out. Without one (the default) the hand-out is what it always was.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from dispatch.api.comms import components
from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem
from dispatch.decide.answers import Checked, finders, route_stops, validate
from dispatch.decide.deliberation import candidate, recheck
from dispatch.decide.offer_step import (Estimates, Offering, insertion_estimates, plain_estimates,
                                        route_estimates)
from dispatch.decide.pipeline import Pipeline
from dispatch.decide.plan_costs import Inserts
from dispatch.decide.tally import Blame, Tally, one_line
from dispatch.errors import AllocationError, DispatchError, PluginError
from dispatch.heap import keep_large_blocks
from dispatch.plan.operator import KEEP
from dispatch.plan.stops import DROPOFF, PICKUP, PlannedStop
from dispatch.plan.tasks import TaskBook, TaskState

if TYPE_CHECKING:
    import simpy

    from dispatch.plan.operator import Operator
    from dispatch.plan.vehicles import Fleet

log = logging.getLogger(__name__)


class DecisionDeferred(BaseException):
    """Raised by an allocator's ``allocate`` to answer the decision later, from outside the
    simulation (:mod:`learning.rl`): the dispatcher's loop waits for ``resume`` (an event
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
    #: a multi-request answer's checked routes (:attr:`Checked.routes`; cut by the offers)
    routes: dict = field(default_factory=dict)
    #: shared rides: (row, column) of a pair whose vehicle has a plan -> where its stops go
    #: (see :class:`dispatch.plan.insertion.Insertion`)
    inserts: Inserts | dict = field(default_factory=dict)
    cut: int = 0  # open tasks the candidate cut left out (dispatch.decide.candidates)
    #: task id -> the meeting points it was planned at (one point per request; see
    #: :attr:`dispatch.decide.pipeline.Decision.meetings`)
    meetings: dict = field(default_factory=dict)


class Wakeup:
    """The dispatcher's wake-up call: made before the objects that call it (the operator, the
    task source, repositioning, charging) and the dispatcher that waits on it, so that none
    of them needs the others to exist first.

    Calling it asks for a decision (idempotent until the dispatcher wakes). Deciding at once
    (``always`` False: no batching window, no re-assignment), a call while no task is open is
    dropped: the decision would find nothing to do (a vehicle that becomes idle then costs no
    wake-up; the next release asks again). Only the order of decisions among events of one
    same simulated instant could differ, and only when a task is released at exactly the
    instant an idle vehicle's call would have been answered."""

    def __init__(self, env: simpy.Environment, book: TaskBook, always: bool) -> None:
        self.env, self.book, self.always = env, book, bool(always)
        #: triggered by a call; the dispatcher waits on it and then :meth:`rearm`\ s it
        self.event = env.event()

    def __call__(self) -> None:
        if not self.event.triggered and (self.book.open or self.always):
            self.event.succeed()

    def rearm(self) -> None:
        """A fresh event: calls from now on ask for the next decision."""
        self.event = self.env.event()


class Dispatcher:
    """The loop of one simulation's decisions: wait for the wake-up, ask the pipeline for the
    problem, ask the allocator, check the answer and hand it out (after the comms delay)."""

    def __init__(self, env: simpy.Environment, wakeup: Wakeup, pipeline: Pipeline,
                 fleet: Fleet, operator: Operator, allocator: Allocator, *, tally: Tally,
                 blame: Blame, on_decision: Callable[..., None], window: float = 0.0,
                 latency: float = 0.0, offering: Offering | None = None) -> None:
        self.env, self.wakeup, self.pipeline = env, wakeup, pipeline
        self.fleet, self.operator, self.allocator = fleet, operator, allocator
        self.tally, self.blame, self.on_decision = tally, blame, on_decision
        #: seconds waited after a wake-up (batching); simulated seconds per message hop
        self.window, self.latency = window, latency
        #: offers riders may decline (dispatch.api.acceptor); None: every pair is handed out
        self.offering = offering
        self._pending: _Pending | None = None
        keep_large_blocks()  # a batch's big arrays reuse heap memory (see dispatch.heap)
        env.process(self._loop())

    def _loop(self):
        env, window, wakeup = self.env, self.window, self.wakeup
        while True:
            yield wakeup.event
            yield env.timeout(window)
            wakeup.rearm()
            yield from self._decide_or_defer()
            if self._pending is not None:
                yield env.timeout(self._pending.delay)
                self._hand_out()

    def _decide_or_defer(self):
        """:meth:`decide`, or, when the allocator defers it (:class:`DecisionDeferred`: the
        answer comes from outside the simulation, see :mod:`learning.rl`), wait for the
        deferring allocator's ``resume`` event and decide again: nothing moved meanwhile (the
        event is triggered at the same instant, ahead of the events already queued), so the
        same problem is built again and the allocator now answers it. The hook that lets
        :mod:`learning.rl` drive decisions step by step without threads; a run with an
        ordinary allocator goes through :meth:`decide` exactly as before."""
        try:
            self.decide()
        except DecisionDeferred as d:
            yield d.resume
            self.decide()

    def decide(self) -> None:
        """One decision over the candidate vehicles and the open tasks (nothing if the pipeline
        finds nothing to decide).

        Without latency the tasks are handed out at once; with it the hand-out waits in
        ``self._pending`` for the loop to let the simulated deliberation time pass.

        Its Python work grows with the open tasks, not the fleet: the idle vehicles come as
        an :class:`AgentViews` (arrays, views built on access), and a planner that reads the
        arrays (the road planner does) costs them with numpy."""
        d = self.pipeline.build(self.env.now)
        if d is None:
            return
        answer = self.pipeline.answer(d, self._ask)
        problem, allocation, decide_s = answer.problem, answer.allocation, answer.seconds
        self.tally.decide_seconds += decide_s
        delay = allocation.hops * self.latency
        conflicted = allocation.conflicted_tasks() if allocation.requests else set()
        for t in d.requests:
            t.offered = True
            t.conflicted = t.conflicted or t.id in conflicted
        comm = d.comm
        n_comp = 1 if comm.strides == (0, 0) else components(comm)[0]
        self._pending = _Pending(problem, allocation, d.requests, d.cost_s, decide_s, delay,
                                 n_comp, d.holder, answer.index, answer.routes, d.inserts,
                                 d.cut, d.meetings)
        if delay <= 0:
            self._hand_out()

    def _where(self) -> str:
        """Where an allocator's error happened (see :class:`dispatch.decide.pipeline.Blame`)."""
        return self.blame.where("allocator", self.allocator)

    def _ask(self, problem: AllocationProblem) -> Checked:
        """The allocator's answer to ``problem``, checked."""
        t1 = time.perf_counter()
        cost_given = problem.cost
        try:
            allocation = self.allocator.allocate(problem)
        except AllocationError as e:
            raise AllocationError(f"{self._where()}: {one_line(e)}") from e
        except DispatchError as e:
            raise PluginError(f"{self._where()}: {one_line(e)}") from e
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self.blame.failed("allocator", self.allocator, e) from e
        decide_s = time.perf_counter() - t1
        if problem.cost is not cost_given or problem.cost.flags.writeable:
            raise AllocationError(f"{self._where()}: the allocator replaced or made "
                                  "writable problem.cost (the problem is read-only; work on a "
                                  "copy)")
        multi = self.allocator.multi_request
        try:
            index = validate(problem, allocation, multi)
            routes = self._routes(problem, allocation) if multi and allocation.routes else {}
        except AllocationError as e:
            raise AllocationError(f"{self._where()}: {e}") from None
        return Checked(problem, allocation, decide_s, routes, index)

    def _routes(self, problem: AllocationProblem, allocation: Allocation) -> dict:
        """The routes of a multi-request answer, checked: agent id -> (stop rows of
        :func:`route_stops`, planned arrival times); AllocationError where a route breaks the
        capacity, a limit or the vehicle's shift end (``problem.until``)."""
        by_task = {t.id: t for t in problem.tasks}
        row = finders(problem)[0] if problem.until is not None else None
        new: dict[int, dict] = {}
        for aid, tid in allocation.pairs:
            new.setdefault(aid, {})[tid] = by_task[tid]
        out = {}
        for aid, route in allocation.routes.items():
            rows = route_stops(problem, aid, route, new.get(aid, {}))
            v = self.fleet.by_id[int(aid)]
            until = math.inf if row is None else float(problem.until[row(aid)])
            times, why = self.operator.route_times(v, rows, until)
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
        ats: dict = {}  # the slow path's pairs with their insertions
        if not holding and p.delay <= 0:  # (nothing changed since the decision)
            if self.offering is not None:
                allocation = self._offered(p, allocation)
            handed = tuple(allocation.pairs)
            pair_cost = [float(cost[i, j]) for i, j in p.index]
            if p.routes:
                self._follow(p, allocation, p.routes, pair_cost)
                return
            if p.inserts:
                at = [p.inserts.get(ij) for ij in p.index]
                for (aid, tid), c, a in zip(handed, pair_cost, at):
                    self.operator.assign(by_task[tid], by_id[aid], c, a)
                self._recorded(p, allocation, pair_cost)
                return
        else:
            def vehicle_unchanged(a: int) -> bool:  # a vehicle of the decision, as it was then
                v = by_id[a]
                if a not in holding:  # (still one a decision considers)
                    return candidate(self.pipeline, v)
                task = self.operator.holds(v)
                return task is not None and task.id == holding[a] \
                    and task.state is TaskState.ASSIGNED

            def available(t: int) -> bool:  # a task of the decision, as it was then
                task = by_task[t]
                return task.state is TaskState.OPEN if t not in p.holder else (
                    task.state is TaskState.ASSIGNED and task.agent_id == p.holder[t])

            handed = tuple((a, t) for a, t in allocation.pairs
                           if available(t) and vehicle_unchanged(a))
            if p.routes:  # a route planned before the deliberation is stale: dropped
                handed = tuple((a, t) for a, t in handed if a not in p.routes)
            row, col = finders(p.problem)
            if p.delay > 0:  # each pair costed again now (its insertion too), or dropped
                new = [(a, t) for a, t in handed if holding.get(a) != t]
                fresh = recheck(self.pipeline, self.env.now, new, by_task,
                                {a for a, _ in new if a in holding})
                handed = tuple(pair for pair in handed if pair in fresh or pair not in new)
                p.inserts = {(row(a), col(t)): at for (a, t), at in fresh.items()}
            if p.inserts:
                ats = {(a, t): p.inserts.get((row(a), col(t))) for a, t in handed}
            if self.offering is not None:  # (routes dropped, insertions as planned now)
                index = [(row(a), col(t)) for a, t in handed]
                handed, _ = self._offer(p, handed, index, {})
            if len(handed) != len(allocation.pairs):
                log.debug("decision %d: %d pair(s) not handed out (stale after deliberating)",
                          self.tally.decisions, len(allocation.pairs) - len(handed))
                allocation = replace(allocation, pairs=handed)
                self.wakeup()
            pair_cost = [float(cost[row(a), col(t)]) for a, t in allocation.pairs]
        self._recorded(p, allocation, pair_cost)
        if not holding:
            for (aid, tid), c in zip(handed, pair_cost):  # allocation.pairs is handed
                self.operator.assign(by_task[tid], by_id[aid], c, ats.get((aid, tid)),
                                     meeting=p.meetings.get(tid, KEEP))
            return
        self._reassign(p, holding, handed, pair_cost, vehicle_unchanged)

    def _offered(self, p: _Pending, allocation: Allocation) -> Allocation:
        """``allocation`` less the pairs whose riders decline their offers (``p.index`` cut
        to match; a routed vehicle's route in ``p.routes`` re-timed without the declined
        requests' stops)."""
        kept, routes = self._offer(p, allocation.pairs, p.index, p.routes)
        if len(kept) == len(allocation.pairs):
            return allocation
        keep = set(kept)
        p.index = [ij for pair, ij in zip(allocation.pairs, p.index) if pair in keep]
        p.routes = routes
        return replace(allocation, pairs=tuple(kept))

    def _offer(self, p: _Pending, pairs, index, routes: dict) -> tuple[tuple, dict]:
        """``(pairs accepted, routes)``: each of ``pairs`` (at ``index``, its (row, column)
        in the problem) whose rider has not accepted before is offered with the estimates of
        the plan the decision chose (a route's planned times, an insertion's, or the vehicle
        setting out now); ``routes`` re-timed without the declined requests' stops. A
        declined request left open for a re-offer asks for the next decision."""
        off, by_id, op = self.offering, self.fleet.by_id, self.operator
        by_task = {t.id: t for t in p.tasks}
        now, cost = self.env.now, p.problem.cost  # (vehicles set out now, deliberated too)
        plans = self.pipeline.plans
        kept, gone = [], {}
        for (aid, tid), ij in zip(pairs, index):
            task = by_task[tid]
            if tid in p.holder or not off.asks(task):  # accepted before
                kept.append((aid, tid))
                continue
            v = by_id[aid]
            at = p.inserts.get(ij) if p.inserts else None
            if aid in routes:
                rows, times = routes[aid]
                est = route_estimates(task, rows, times, v.load)
            elif at is not None:
                est = insertion_estimates(task, v.plan.kept(), v.load, at)
            elif plans:  # a vehicle setting out on the request's stops, by the schedule rule
                est = self._set_out_estimates(v, task, now, float(cost[ij]))
            else:
                est = plain_estimates(task, now, float(cost[ij]))
            if off.offer(task, aid, now, est):
                kept.append((aid, tid))
            else:
                gone.setdefault(aid, set()).add(tid)
        if off.reoffer:
            off.reoffer = False
            self.wakeup()
        if routes and gone.keys() & routes.keys():
            routes = dict(routes)
            mine = {a for a, _ in kept}
            for aid in gone.keys() & routes.keys():
                if aid not in mine:  # no new request left: it keeps its plan as it is
                    del routes[aid]
                    continue
                rows = [r for r in routes[aid][0] if r.task_id not in gone[aid]]
                times, why = op.route_times(by_id[aid], rows)
                if times is None:  # (fewer stops of a feasible route stay feasible)
                    raise DispatchError(f"{self._where()}: the route of vehicle {aid} without "
                                        f"the declined requests is infeasible: {why}")
                routes[aid] = (rows, times)
        return tuple(kept), routes

    def _set_out_estimates(self, v, task, now: float, cost: float) -> Estimates:
        """Estimates of ``v`` driving ``task``'s stops from where it is ``now`` (the operator's
        route times, no limit; a booked pickup waits for its departure, as the plan will), or
        from the decision's cost where those cannot be had."""
        n = task.passengers
        rows = [PlannedStop(PICKUP, task.id, task.loc, n if task.dropoff is not None else 0,
                            math.inf, task.dropoff is None, task.earliest_pickup)]
        if task.dropoff is not None:
            rows.append(PlannedStop(DROPOFF, task.id, task.dropoff, -n, math.inf, True))
        times, _ = self.operator.route_times(v, rows)
        if times is None:
            return plain_estimates(task, now, cost)
        return route_estimates(task, rows, times, 0)

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
                at = next(t for r, t in zip(rows, times)
                          if r.kind == PICKUP and r.task_id == tid)
                pair_cost[k] = at - now
                mine.setdefault(aid, {})[tid] = pair_cost[k]
        self._recorded(p, allocation, pair_cost)
        for (aid, tid), c, ij in zip(allocation.pairs, pair_cost, p.index):
            if aid not in routes:
                self.operator.assign(by_task[tid], by_id[aid], c, p.inserts.get(ij),
                                     meeting=p.meetings.get(tid, KEEP))
        for aid, costs in mine.items():
            rows, times = routes[aid]
            self.operator.follow(by_id[aid], rows, times, {t: by_task[t] for t in costs},
                                 costs, p.meetings)

    def _recorded(self, p: _Pending, allocation: Allocation, pair_cost: list[float]) -> None:
        """Count and record a decision's hand-out (``allocation`` as handed out)."""
        critical = max(allocation.agent_seconds, default=p.decide_s)
        tally = self.tally
        tally.rounds += allocation.rounds
        tally.messages += allocation.messages
        tally.comm_delay += p.delay
        tally.agent_seconds += critical
        total = float(sum(pair_cost))
        if tally.decisions == 0:
            tally.first_cost, tally.first_seconds = total, p.cost_s + p.decide_s
        self.on_decision(tally.decisions, p.problem, allocation, total, p.cost_s, p.decide_s,
                         hops=allocation.hops, comm_delay=p.delay, agent_seconds=critical,
                         components=p.components, cut=p.cut)
        tally.decisions += 1

    def _reassign(self, p: _Pending, holding: dict, handed: tuple, pair_cost: list[float],
                  vehicle_unchanged) -> None:
        """The hand-out of a decision with re-assignment before pickup."""
        by_task = {t.id: t for t in p.tasks}
        by_id = self.fleet.by_id
        # reassign: a vehicle driving to a pickup gives its task up when it gets another task,
        # or none while its task goes to another vehicle; otherwise it keeps it
        new_task = dict(handed)
        taken = set(new_task.values())
        give = sorted(a for a, t in holding.items() if vehicle_unchanged(a) and (
            new_task.get(a, t) != t or (a not in new_task and t in taken)))
        for a in give:
            self.operator.give_up(by_id[a])
        self.tally.reassignments += len(give)
        for (aid, tid), c in zip(handed, pair_cost):
            if holding.get(aid) != tid:
                self.operator.assign(by_task[tid], by_id[aid], c,
                                     meeting=p.meetings.get(tid, KEEP))
        for a in give:
            if a not in new_task:
                self.operator.stand_idle(by_id[a])
