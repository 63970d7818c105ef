"""A decision's problem, built in named steps: what the dispatcher asks the allocator about.

The dispatcher (:mod:`dispatch.decide.dispatcher`) wakes, asks :meth:`Pipeline.build` for the
decision's problem, asks the allocator (once, or in the certificate loop of lazy costs:
:meth:`Pipeline.answer`) and hands the answer out. What a problem is made of is here, each step
a function or a small class that says what it promises, composed in :meth:`Pipeline.build`
in the order they run:

1. :func:`direct_times`: each open request's free-flow direct drive time, set once.
2. :func:`candidates`: the vehicles and requests that take part (the idle vehicles; with
   shared rides the busy ones with a free seat; with re-assignment those driving to a pickup,
   with their requests).
3. :class:`PlannerCosts`: the planner's cost matrix (or, with lazy costs, its lower bounds and
   which of them are exact), checked: a :class:`PluginError` naming the planner otherwise.
4. :func:`reachable`: the requests some vehicle of the decision can reach; those no vehicle of
   the fleet can ever reach are closed ``unreachable`` (:func:`close_unreachable`).
5. :meth:`Pipeline.limits`: with plans, the insertion costs by the objective
   (:func:`dispatch.decide.plan_costs.insertion_costs_of`: each request's cheapest feasible
   insertion
   into each vehicle's plan; with meeting points :func:`dispatch.decide.meeting.meeting_costs`, the
   cheapest over its candidate boarding and alighting points too); without,
   :func:`~dispatch.decide.planner_costs.deadlines` (``inf`` where a vehicle would reach the
   pickup after the deadline; with lazy costs each request's feasibility made exact,
   :func:`dispatch.decide.lazy.resolve_open`).
   A request no vehicle reaches in time is rejected the first time it is offered
   (:func:`~dispatch.decide.planner_costs.reject_late`).
6. The energy filter (``[fleet.energy]``, :meth:`dispatch.fleet.battery.Energy.filter`): ``inf``
   where a vehicle would end below its reserve; the shift limit (:meth:`dispatch.fleet.shifts.
   Shifts.limit`): ``inf`` where a plan would end after the vehicle's shift and its grace.
7. :func:`keep_servable`: the columns of the requests left out are dropped.
8. :class:`dispatch.api.comms.Hearing`: who hears whom (the ``[comms]`` range, a blackout's
   links) and where the agents are.
9. :class:`Problems`: the :class:`AllocationProblem` of a cost matrix, everything else fixed.
10. :func:`certified`: with lazy costs the certificate loop (:mod:`dispatch.decide.lazy`) around the
    allocator; without them one question; a decision of one request for an allocator that
    decides it by its cost minimum none (:mod:`dispatch.decide.one_request`).

An allocator that also declares it may be cut decides a one-request decision over only the
vehicles a lower bound of their cost cannot rule out, nearest first (steps 2-7 on those:
:meth:`Pipeline.nearest`, :mod:`dispatch.decide.nearest`).

A step reads the run's objects it is given when the pipeline is built (the task book, the
fleet, the operator, the planner, the space, the configuration) and the decision's values it
is passed; the steps that close requests (4, 5) close them in the task book, as the dispatcher
always has. The seconds spent building problems are added to :attr:`Tally.cost_seconds`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dispatch.api.comms import Hearing
from dispatch.api.contracts import Allocator, Planner
from dispatch.api.problem import AgentViews, AllocationProblem
from dispatch.api.space import Space
from dispatch.decide import nearest, one_request
from dispatch.decide.answers import Checked
from dispatch.decide.candidates import cut as candidate_cut
from dispatch.decide.lazy import certify, resolve_open
from dispatch.decide.meeting import meeting_costs, view_at
from dispatch.decide.one_request import decided, fits
from dispatch.decide.plan_costs import (
    Inserts,
    PlanEnds,
    Plans,
    PlanTable,
    insertion_costs_of,
    ride_seconds,
)
from dispatch.decide.planner_costs import (
    PlannerCosts,
    close_unreachable,
    deadlines,
    lazy_costs,
    reject_late,
)
from dispatch.decide.prebook import earliest_views
from dispatch.decide.tally import Blame, Tally
from dispatch.errors import PluginError
from dispatch.plan.stops import OBJECTIVES
from dispatch.plan.tasks import TaskBook

if TYPE_CHECKING:
    from dispatch.config.comms import CommsConfig
    from dispatch.config.dispatching import DispatchConfig
    from dispatch.plan.operator import Operator
    from dispatch.plan.tasks import Task
    from dispatch.plan.vehicles import Fleet

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- the steps


def direct_times(book: TaskBook, free: Planner, seen: int) -> int:
    """Set the free-flow direct drive time of the open requests released since the decision
    that saw the ids up to ``seen`` (a request gets it at the first decision that considers
    it), from ``free`` (a congested planner's inner, free-flow one); return the last id seen.
    The book keeps open requests in id order, so only the new ones are read (thousands may
    wait in an overloaded run)."""
    need = []
    for t in reversed(book.open.values()):
        if t.id <= seen:
            break
        if t.dropoff is not None and t.direct_time != t.direct_time:
            need.append(t)
    if need:
        need.reverse()
        times = free.between([t.loc for t in need], [t.dropoff for t in need], pairwise=True)
        for t, x in zip(need, np.asarray(times, dtype=float).tolist()):
            t.direct_time = x
    return book.released - 1


def rides(planner, tasks) -> np.ndarray | None:
    """Each trip's drive from pickup to drop-off at this hour (0 for a point task), from
    where a transferred rider waits now (:func:`dispatch.decide.plan_costs.ride_seconds`);
    None where every one is the trip's free-flow ``direct_time``."""
    return ride_seconds(planner, tasks, congested_only=True)


def candidates(fleet: Fleet, book: TaskBook, held: dict, pooled: bool
               ) -> tuple[np.ndarray, list[Task], dict[int, int]]:
    """``(slots, requests, holder)`` of a decision: the fleet positions of its vehicles,
    ascending (the idle ones; ``pooled``: and the busy ones with a free seat in their plan;
    with re-assignment those driving to the pickup of a ``held`` task), its requests (the
    open ones in release order, or with ``held`` tasks all by id) and, for each held task,
    the vehicle driving to it (task id -> vehicle id)."""
    if pooled:  # busy vehicles with a free seat somewhere in their plan take part
        idle = np.flatnonzero(fleet.idle_mask | (fleet.busy_mask & fleet.room))
    else:
        idle = fleet.idle_index()
    holder: dict[int, int] = {}  # task id -> the vehicle driving to its pickup
    if held:  # [dispatch] reassign: vehicles driving to a pickup take part, with their tasks
        holder = {t.id: t.agent_id for t in held.values()}
        slots = np.array([fleet.by_id[a]._slot for a in holder.values()], np.int64)
        idle = np.union1d(idle, slots)
        open_tasks = sorted([*book.open.values(), *held.values()], key=lambda t: t.id)
    else:
        open_tasks = list(book.open.values())
    return idle, open_tasks, holder


def keep_servable(servable: np.ndarray, requests: list, cost: np.ndarray, exact, inserts):
    """``(requests, tasks, cost, exact, inserts)`` for the ``servable`` columns only: the
    requests and their fresh views, the columns of the costs (and of ``exact``, lazy costs)
    and the insertions (renumbered)."""
    if inserts:  # their columns move left
        inserts = inserts.kept(servable)
    requests = [t for t, ok in zip(requests, servable) if ok]
    tasks = tuple([t.view() for t in requests])
    cost = cost[:, servable]
    if exact is not None:
        exact = exact[:, servable]
    return requests, tasks, cost, exact, inserts


class Problems:
    """The :class:`AllocationProblem` of a decision's cost matrix: the run's fixed fields (the
    allocator's generator, rounds, the comms' loss and latency, the cell size, the service
    time, travel times between locations when the planner routes) and the decision's."""

    def __init__(self, fleet: Fleet, operator: Operator, planner: Planner, space: Space,
                 cfg: DispatchConfig, comms: CommsConfig, *, rng: np.random.Generator,
                 pooled: bool, routes: bool, until: np.ndarray | None = None) -> None:
        self.fleet, self.operator, self.planner, self.space = fleet, operator, planner, space
        #: driver shifts: each fleet position's latest plan end (dispatch.fleet.shifts.Shifts.until,
        #: kept up to date there); None without shift ends
        self.until = until
        self.rng, self.max_rounds = rng, cfg.max_rounds
        self.loss, self.latency = comms.loss, comms.latency
        self.pooled, self.routes = pooled, routes
        self.cell_size = float(space.cell)

    def of(self, now: float, agents, tasks, slots: np.ndarray, comm: np.ndarray, apos, *,
           post=None) -> Callable[[np.ndarray], AllocationProblem]:
        """``make(cost)``: the problem of these agents (at fleet positions ``slots``), tasks
        and comm graph with a C-ordered copy of ``cost`` (the certificate loop changes its
        matrix between questions); the task positions, the plans, seats and ready times
        (shared rides) as the problem reads them."""
        space = self.space

        def tpos():
            return space.positions([t.loc for t in tasks])

        plans = Plans(self.fleet, slots, now) if self.pooled else None
        seats = self.fleet.capacity[slots] if self.pooled else None
        ready = np.maximum(self.fleet.free_at[slots], now) if self.pooled else None
        travel = self.planner.between if self.routes else None
        until = None if self.until is None else self.until[slots]

        def make(cost: np.ndarray) -> AllocationProblem:
            return AllocationProblem.made(now, agents, tasks, np.array(cost, order="C"), comm,
                                          self.rng, max_rounds=self.max_rounds, loss=self.loss,
                                          latency=self.latency, cell_size=self.cell_size,
                                          agent_pos=apos, task_pos=tpos, plans=plans,
                                          capacity=seats,
                                          service_time=self.operator.service_time,
                                          travel=travel, ready=ready, until=until,
                                          post=post)
        return make


#: ``ask(problem) -> Checked``: the dispatcher's question to the allocator, its answer
#: checked.
Ask = Callable[[AllocationProblem], Checked]


def certified(ask, cost, exact, compute, now: float, deadline: np.ndarray,
              *, tally: Tally) -> tuple[Checked, float]:
    """The certificate loop of lazy costs (:func:`dispatch.decide.lazy.certify`) around ``ask``
    (``cost -> Checked``): ``(the last answer, its seconds the allocator's in every round;
    the seconds spent computing exact pairs)``; the latter, the rounds and the pairs computed
    are added to ``tally``."""
    spent = [0.0]

    def timed(c):
        t = time.perf_counter()
        answer = ask(c)
        spent[0] += time.perf_counter() - t
        return answer

    t0 = time.perf_counter()
    answer, rounds, pairs = certify(timed, cost, exact, compute, now, deadline)
    extra = time.perf_counter() - t0 - spent[0]
    tally.cost_seconds += extra
    tally.lazy_rounds += rounds
    tally.lazy_pairs += pairs
    return answer._replace(seconds=spent[0]), extra


# ----------------------------------------------------------------------------- composed


@dataclass
class Decision:
    """A decision's problem, built (what :meth:`Pipeline.answer` asks the allocator about):
    its time, agents (at fleet positions ``slots``), requests and their views, the cost
    matrix (with lazy costs bounds and ``exact``), where a busy vehicle's stops would go
    (``inserts``), re-assignment's holders (task id -> vehicle id), the comm graph, the
    seconds spent building it and ``make(cost)`` (:meth:`Problems.of`)."""

    now: float
    slots: np.ndarray
    agents: AgentViews
    requests: list
    tasks: tuple
    cost: np.ndarray
    exact: np.ndarray | None
    inserts: Inserts | dict
    holder: dict
    comm: np.ndarray
    cost_s: float
    make: Callable[[np.ndarray], AllocationProblem]
    cut: int = 0  # open tasks the candidate cut left out (dispatch.decide.candidates)
    #: (one point per request, dispatch.decide.meeting) task id -> the meeting points it was
    #: planned at; handed out, the operator makes them the task's (Task.meeting's one writer)
    meetings: dict = field(default_factory=dict)
    #: the candidate vehicles where the vehicle cut costed only some (dispatch.decide.nearest):
    #: the decision's agents are those it costed; None: they are all the candidates
    n_idle: int | None = None


class Pipeline:
    """The steps of a decision's problem (see the module), composed in :meth:`build`."""

    def __init__(self, book: TaskBook, fleet: Fleet, operator: Operator, planner: Planner,
                 allocator: Allocator, space: Space, *, cfg: DispatchConfig, comms: CommsConfig,
                 rng: np.random.Generator, tally: Tally, blame: Blame, links=None,
                 energy_filter=None, pooled: bool = False, max_delay: bool = False,
                 shifts=None, walks=None) -> None:
        self.book, self.fleet, self.operator, self.tally = book, fleet, operator, tally
        self.space = space
        #: the vehicles have plans to insert into (a capacity above 1), requests have drop-off
        #: limits or the objective is the added time: costs are insertion costs
        #: (dispatch.plan.stops)
        self.pooled = bool(pooled)
        #: meeting points (:class:`dispatch.decide.meeting.Walks`; None: door to door); an allocator
        #: that routes several requests (rtv) plans with one pair of points per request
        self.walks = walks
        self.one_point = walks is not None and allocator.multi_request
        #: an allocator routing several requests itself reads each pickup's earliest time
        #: from the views (dispatch.decide.prebook.earliest_views); the others insert by the costs
        self.routed = allocator.multi_request
        #: the allocator asks the value of its pairs' post-decision states
        #: (:attr:`dispatch.api.contracts.Allocator.value_function`): with plans, the problem
        #: says where each pair's plan ends (:class:`dispatch.decide.plan_costs.PlanEnds`)
        self.looks_ahead = allocator.value_function is not None
        self._points: dict = {}  # (one_point) task id -> its Meeting, of the last limits
        self.plans = self.pooled or cfg.objective != "pickup_time" or bool(max_delay) \
            or walks is not None
        self.objective = OBJECTIVES[cfg.objective]
        self.reassign = cfg.reassign
        #: [dispatch] out_of_reach: a request no vehicle reaches in time at its first offer is
        #: rejected at once (else it waits for its deadline)
        self.reject = cfg.out_of_reach == "reject"
        #: the planner routes between any two locations (direct times, insertions)
        self.routes = planner.travel_times
        if self.plans and not self.routes:
            raise PluginError(f"planner {planner.name!r} computes no travel times between "
                              "locations (Planner.between): shared rides, max_delay and the "
                              "added_time objective need them")
        #: [dispatch] lazy_costs, with a planner and an allocator that support it
        self.lazy = lazy_costs(cfg, planner, allocator, self.plans)
        self.planner = planner
        self.costs = PlannerCosts(planner, self.lazy, blame)
        #: a one-request decision is decided here, without the general problem
        #: (dispatch.decide.one_request): the allocator declares it decides one request by
        #: its cost minimum, and no certificate loop or re-assignment asks more of it
        self.one_request = allocator.one_by_minimum \
            and not allocator.multi_request and not self.lazy and not self.reassign
        #: [fleet.energy]: ``(cost, drive, slots, tasks[, holders]) -> cost`` with ``inf`` where
        #: a vehicle would end below its reserve (dispatch.fleet.battery.Energy.filter); None
        #: without energy
        self.energy_filter = energy_filter
        #: driver shifts (dispatch.fleet.shifts.Shifts.limit: ``inf`` where a plan would end after
        #: the vehicle's shift and grace); None without shift ends
        self.shifts = shifts
        self.hearing = Hearing(space, comms, links)
        self.problems = Problems(fleet, operator, planner, space, cfg, comms, rng=rng,
                                 pooled=self.pooled, routes=self.routes,
                                 until=None if shifts is None else shifts.until)
        #: with plans, the fleet's plans as the compiled insertion reads them, kept between
        #: decisions (a row rewritten when its vehicle's plan changed)
        self.table = PlanTable(len(fleet)) if self.plans else None
        #: the last request id whose direct drive time a decision has set (direct_times)
        self._seen = -1
        #: the exact vehicle cut (dispatch.decide.nearest): the ``(speed, slack)`` promises
        #: that bound a vehicle's cost from its straight line (the planner's floor taken in),
        #: where it may be taken (a one-request decision of an allocator that declares it, in
        #: a space and with a planner that promise the bound, everyone hearing everyone); None
        #: where not
        top, floor = space.top_speed, planner.drive_floor
        self.speeds = tuple((s / floor, slack) for s, slack in
                            ((top, 0.0), *space.speed_slacks)) if (
            self.one_request and allocator.nearest_cut and walks is None and links is None
            and top and floor and floor > 0 and len(fleet) >= nearest.MIN_CANDIDATES
            and (comms.range is None or math.isinf(comms.range))
            and fleet.index_places() is not None) else None

    def build(self, now: float) -> Decision | None:
        """The problem of a decision at ``now`` over the candidate vehicles and the open
        requests; None when there is nothing to decide (no open request, no vehicle, or no
        request any vehicle can serve). Closes the requests it finds unreachable or (offered
        the first time) too late."""
        held = self.book.assigned if self.reassign else {}
        if not self.book.open and not held:
            return None
        if self.routes:
            self._seen = direct_times(self.book, self.planner.free_flow, self._seen)
        if self.speeds is not None and len(self.book.open) == 1 and not nearest.FULL \
                and not one_request.GENERAL:
            d = self.nearest(now)
            if d is not nearest.WHOLE:
                return d
        idle, open_tasks, holder = candidates(self.fleet, self.book, held, self.pooled)
        if not idle.size:
            return None
        agents = self.fleet.views(idle, now, ascending=True)  # flatnonzero, union1d: sorted
        t0 = time.perf_counter()
        open_tasks, n_cut = candidate_cut(open_tasks, agents, self.space, holder)
        tasks = tuple([t.view() for t in open_tasks])
        cost, exact = self.costs(agents, tasks)
        servable = self.costs.reachable(cost)
        if servable is not None and not servable.all():
            close_unreachable(self.book, self.fleet, self.costs,
                              [t for t, ok in zip(open_tasks, servable) if not ok], now)
        drive = cost if self.energy_filter is not None or self.shifts is not None else None
        cost, exact, servable, inserts = self.limits(now, agents, tasks, idle, open_tasks, holder,
                                                     cost=cost, exact=exact, servable=servable)
        if self.energy_filter is not None:  # [fleet.energy]: below the reserve after the trip: inf
            cost = self.energy_filter(cost, drive, idle, open_tasks,
                                      frozenset(holder.values()))
        if self.shifts is not None:  # shifts: a plan ending after the shift and grace: inf
            cost = self.shifts.limit(cost, drive, now, idle, open_tasks, inserts,
                                     plans=self.plans, ride=rides(self.planner, open_tasks),
                                     holders=frozenset(holder.values()))
        cost_s = time.perf_counter() - t0
        self.tally.cost_seconds += cost_s
        if servable is not None:
            if not servable.any():
                return None
            if not servable.all():
                open_tasks, tasks, cost, exact, inserts = keep_servable(
                    servable, open_tasks, cost, exact, inserts)
        meetings = {}
        if self.one_point:  # the requests planned at their meeting points (dispatch.decide.meeting)
            meetings = {t.id: self._points.get(t.id) for t in open_tasks}
            tasks = tuple(view if meetings[t.id] is None else view_at(t, meetings[t.id])
                          for t, view in zip(open_tasks, tasks))
        if self.routed:  # booked pickups' earliest times, for the allocator's own routes
            tasks = earliest_views(open_tasks, tasks)
        comm, apos = self.hearing(agents, now)
        post = None
        if self.looks_ahead and self.plans and self.walks is None and self.table.on_nodes:
            post = PlanEnds(now, idle, open_tasks, inserts, self.table, fleet=self.fleet,
                            objective=self.objective, service=self.operator.service_time)
        return Decision(now, idle, agents, open_tasks, tasks, cost, exact, inserts, holder, comm,
                        cost_s, self.problems.of(now, agents, tasks, idle, comm, apos, post=post),
                        n_cut, meetings)

    def nearest(self, now: float):
        """The decision at ``now`` of the one open request over the vehicles the exact cut
        costs (:func:`dispatch.decide.nearest.search`): the same as :meth:`build`'s over all
        of them; None where :meth:`build` finds nothing to decide (the request closed as it
        would close it); :data:`dispatch.decide.nearest.WHOLE` where only the whole column
        can tell."""
        got = nearest.search(self, now)
        if got is None or got is nearest.WHOLE:
            return got
        n, open_tasks, tasks, slots, cost, inserts, t0 = got
        agents = self.fleet.views(slots, now, ascending=True)
        cost_s = time.perf_counter() - t0
        self.tally.cost_seconds += cost_s
        comm, apos = self.hearing(agents, now)
        return Decision(now, slots, agents, open_tasks, tasks, cost, None, inserts, {}, comm,
                        cost_s, self.problems.of(now, agents, tasks, slots, comm, apos),
                        n_idle=n)

    def limits(self, now: float, agents, tasks, idle: np.ndarray, open_tasks: list,
               holder: dict, *, cost: np.ndarray, exact, servable):
        """``(cost, exact, servable, inserts)`` within every limit: with plans the insertion
        costs by the objective (and where a busy vehicle's stops would go); without, ``inf``
        where a vehicle would reach the pickup after the deadline (with lazy costs each
        request's feasibility made exact). The requests no vehicle reaches in time are left
        out of ``servable`` (rejected at their first offer); ``servable`` stays None where no
        limit applies and every request is reachable."""
        limits = [t.deadline for t in open_tasks]
        inserts: dict = {}
        if self.plans:
            if servable is None:
                servable = np.ones(len(open_tasks), dtype=bool)
            if self.walks is not None:  # meeting points: the cheapest candidate pair's
                cost, inserts, points = meeting_costs(
                    self.walks, cost, idle, agents, open_tasks, now, holders=set(holder.values()),
                    fleet=self.fleet, operator=self.operator, planner=self.planner,
                    objective=self.objective, one_point=self.one_point)
                self._points = {open_tasks[c].id: p for c, p in points.items()}
            else:
                cost, inserts = insertion_costs_of(cost, idle, open_tasks, now,
                                                   set(holder.values()), fleet=self.fleet,
                                                   operator=self.operator, planner=self.planner,
                                                   objective=self.objective, table=self.table)
            servable = reject_late(self.book, open_tasks, cost, servable, self.reject)
        elif any(d < math.inf for d in limits):
            if servable is None:
                servable = np.ones(len(open_tasks), dtype=bool)
            limits = np.array(limits)
            cost = deadlines(cost, limits, now)
            if self.lazy:  # late by its bound is late exactly; feasibility of each task exact
                exact = exact | ~np.isfinite(cost)
                self.tally.lazy_pairs += resolve_open(cost, exact, self.costs.exact(agents, tasks),
                                                      now, limits)
            servable = reject_late(self.book, open_tasks, cost, servable, self.reject)
        return cost, exact, servable, inserts

    def answer(self, d: Decision, ask: Ask) -> Checked:
        """``ask``'s answer to decision ``d``'s problem, or with lazy costs the certified one
        (its seconds those of every round; the seconds spent computing exact pairs are added
        to ``d.cost_s``)."""
        def solve(cost: np.ndarray) -> Checked:
            return ask(d.make(cost))

        if self.one_request and fits(d):
            return decided(d)
        if not self.lazy:
            return solve(d.cost)
        answer, extra = certified(
            solve, d.cost, d.exact, self.costs.exact(d.agents, d.tasks), d.now,
            np.array([t.deadline for t in d.requests]), tally=self.tally)
        d.cost_s += extra  # computing exact pairs is cost time
        return answer
