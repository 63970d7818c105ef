"""Checks for plugin authors: run an allocator or a planner on random problems and report what
it gets wrong, before a simulation does.

    from dispatch.testing import check_allocator, check_planner

    report = check_allocator(MyAllocator, some_param=3)   # keyword arguments: the constructor's
    assert report.ok, report                              # str(report): one line per check

    report = check_planner(MyPlanner)                     # on a small voxel world / road grid
    report = check_planner(MyPlanner, space)              # or on a space of your own

    report = check_repositioner(MyRepositioner, zone=500)  # on random views of a road grid

From the command line: ``dispatch check NAME`` (an installed allocator, planner or
repositioner).

Allocator checks, each on every problem of :func:`allocation_problems` (no agents, no tasks,
square and rectangular, rows and columns all ``inf``, ids that are not indices, several
communication components, message loss):

``construct``   the class builds with the given parameters;
``valid``       every answer is an :class:`~dispatch.contracts.Allocation` the dispatcher accepts
                (known ids, no agent or task twice, no ``inf`` pair, whole counters);
``progress``    when some pair is finite, the answer assigns at least one;
``no-mutation`` the problem (its arrays, views and scalars) is the same after the call, even
                for a plugin that makes an array writable again or swaps an attribute;
``deterministic`` the same problem with the same seed, to a fresh instance, gives the same answer;
``rng``         the answer does not change when the global ``random`` / ``numpy.random`` state
                does (randomness only from ``problem.rng``).

An allocator that sets ``multi_request`` (batch pooling) is also run on the shared-ride
problems of :func:`pooled_problems` (vehicles with plans, seats, ``problem.travel`` on
:func:`small_network`); ``valid`` then also checks each route of ``Allocation.routes`` as the
dispatcher does (the agent's plan and new requests once each, every pickup before its drop-off,
the capacity and every limit on the problem's travel times: :func:`route_schedule`).

Planner checks on random agents and tasks of the space: ``construct``, ``costs`` (shape
``(len(agents), len(tasks))``, floats, ``>= 0`` or ``inf``, no ``nan``, also for 0 agents / 0
tasks), ``plan`` (a path from the agent's location to the goal where the cost is finite),
``no-mutation`` (of the space's grid), ``deterministic`` and ``rng`` as above; for a planner
that sets ``lower_bounds``, ``bounds`` (each bound ``<=`` the cost, ``inf`` exactly where the
cost is, entries marked exact equal to it, and ``exact`` equal to the costs, all to 1e-9
relative, each on a fresh instance).

Repositioner checks on random views (:func:`reposition_view`) of :func:`small_network`
(no idle vehicles, no recent requests, vehicles already repositioning, part-way along edges):
``construct``, ``valid`` (a mapping from idle vehicle ids of the view to node indices),
``no-mutation`` (of the view), ``deterministic`` and ``rng`` as above. A passive repositioner
(never called by the kernel) must answer with no moves.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dispatch.problem import AgentView, Allocation, AllocationProblem, TaskView
from dispatch import registry
from dispatch.errors import AllocationError, PluginError
from dispatch.legs import as_point
from dispatch.space import KINDS, space_class
from dispatch.stops import DROPOFF, TOL, PlannedStop, timetable

__all__ = ["CheckResult", "Report", "allocation_problems", "check_allocator", "check_planner",
           "check_repositioner", "pooled_problem", "pooled_problems", "reposition_view",
           "route_schedule", "small_network", "small_world"]


@dataclass(frozen=True)
class CheckResult:
    name: str
    ok: bool
    detail: str


@dataclass
class Report:
    """The verdicts of one plugin: ``ok`` when every check passed; ``str``: one line each."""

    plugin: str
    results: list[CheckResult] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    def failed(self) -> list[CheckResult]:
        return [r for r in self.results if not r.ok]

    def add(self, name: str, failures: list[str], passed: str) -> None:
        if failures:
            more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
            self.results.append(CheckResult(name, False, failures[0] + more))
        else:
            self.results.append(CheckResult(name, True, passed))

    def __str__(self) -> str:
        return "\n".join(f"{'pass' if r.ok else 'FAIL'} {r.name}: {r.detail}"
                         for r in self.results)


def _err(e: BaseException) -> str:
    msg = " ".join(str(e).split())
    return f"{type(e).__name__}: {msg[:300]}" if msg else type(e).__name__


# ----------------------------------------------------------------------------- problems


def _problem(label: str, seed: int, n: int, m: int, *, p_inf: float = 0.0, inf_rows=(),
             inf_cols=(), components: int = 1, loss: float = 0.0, ids_offset=True,
             air: float = 0.0) -> tuple[str, Callable[[], AllocationProblem]]:
    """A problem factory: each call builds the same problem with a fresh ``rng`` (the answer
    to the same seed must be the same)."""
    g = np.random.default_rng([seed, n, m, components])
    cells = g.integers(0, 12, (n + m, 3)) * np.array([1, 1, 0]) + np.array([0, 0, 0])
    a_cells, t_cells = cells[:n].copy(), cells[n:].copy()
    kinds = ["uav" if i % 2 else "ugv" for i in range(n)]
    t_air = g.random(m) < air
    t_cells[t_air, 2] = g.integers(1, 4, int(t_air.sum()))
    a_ids = (g.permutation(1000)[:n] + 1000).tolist() if ids_offset else list(range(n))
    t_ids = (g.permutation(1000)[:m] + 5000).tolist() if ids_offset else list(range(m))
    speed = np.where(np.array(kinds) == "uav", 5.0, 3.0) if n else np.zeros(0)
    dist = np.linalg.norm(a_cells[:, None, :] - t_cells[None, :, :], axis=-1) + 0.5
    cost = dist / speed[:, None] if n else np.zeros((0, m))
    ugv = np.array([k == "ugv" for k in kinds], bool)
    cost[np.ix_(ugv, t_air)] = np.inf
    cost[g.random((n, m)) < p_inf] = np.inf
    cost[list(inf_rows), :] = np.inf
    cost[:, list(inf_cols)] = np.inf
    comm = np.zeros((n, n), bool)
    for c in range(components):
        members = np.arange(n)[np.arange(n) % components == c]
        comm[np.ix_(members, members)] = True
    agents = tuple(AgentView(a_ids[i], kinds[i], tuple(int(v) for v in a_cells[i]),
                             float(speed[i])) for i in range(n))
    tasks = tuple(TaskView(t_ids[j], "air" if t_air[j] else "ground",
                           tuple(int(v) for v in t_cells[j]), 0.0) for j in range(m))

    def build() -> AllocationProblem:
        return AllocationProblem(time=10.0, agents=agents, tasks=tasks,
                                 cost=np.ascontiguousarray(cost, float), comm=comm.copy(),
                                 rng=np.random.default_rng(seed), max_rounds=200, loss=loss,
                                 latency=0.0, cell_size=1.0)

    return label, build


def allocation_problems(seed: int = 0) -> list[tuple[str, Callable[[], AllocationProblem]]]:
    """``(label, factory)`` of the problems :func:`check_allocator` runs (a factory builds the
    same problem, with a fresh ``rng`` of the same seed, at every call)."""
    s = seed * 1000
    return [
        _problem("0 agents", s + 1, 0, 3),
        _problem("0 tasks", s + 2, 3, 0),
        _problem("0 agents 0 tasks", s + 3, 0, 0),
        _problem("1 x 1", s + 4, 1, 1),
        _problem("square 4 x 4", s + 5, 4, 4),
        _problem("square 8 x 8, ids = indices", s + 6, 8, 8, ids_offset=False),
        _problem("wide 3 x 7", s + 7, 3, 7),
        _problem("tall 7 x 3", s + 8, 7, 3),
        _problem("all-inf rows", s + 9, 5, 5, inf_rows=(1, 3)),
        _problem("all-inf columns", s + 10, 5, 5, inf_cols=(0, 4)),
        _problem("everything inf", s + 11, 3, 3, p_inf=1.0),
        _problem("sparse (60% inf), air tasks", s + 12, 6, 6, p_inf=0.6, air=0.5),
        _problem("3 comm components", s + 13, 9, 6, components=3),
        _problem("no links (9 components)", s + 14, 9, 9, components=9),
        _problem("loss 0.3", s + 15, 6, 6, loss=0.3),
        _problem("loss 0.3, 2 components, rectangular", s + 16, 8, 5, components=2, loss=0.3),
    ]


def pooled_problem(seed: int, n: int, m: int, capacity: int = 3, *, busy: float = 0.5,
                   service: float = 0.0, max_pax: int = 1
                   ) -> tuple[str, Callable[[], AllocationProblem]]:
    """A pooled road decision (shared rides) on :func:`small_network`, as a factory like
    :func:`_problem`'s: ``n`` vehicles of ``capacity`` seats at random intersections, about
    ``busy`` of them with a plan (a request on board, one to pick up, or both; planned times
    from where the vehicle stands, limits some seconds later), ``m`` new requests (pickup,
    drop-off, up to ``max_pax`` riders, pickup within 60-200 s of the release, drop-off within
    30-300 s of the direct drive), ``problem.travel`` the road planner's, costs as a pooled
    decision has them: seconds to the pickup of the request's earliest feasible insertion into
    the vehicle's plan (``inf`` where none is feasible)."""
    from dispatch.problem import StopView

    net = small_network()
    travel = registry.load("planner", net.default_planner)(net).between
    g = np.random.default_rng([seed, n, m, capacity, 7])
    now = 100.0
    nodes = g.integers(0, 30, n).tolist()  # (the grid's 30 intersections)
    a_ids = (g.permutation(100)[:n] + 10).tolist()
    plans: dict[int, tuple] = {}
    for i in range(n):
        if g.random() >= busy:
            continue
        kinds = [("dropoff", 9000 + 10 * i)] if g.random() < 0.7 else []
        if g.random() < 0.7:
            kinds.insert(int(g.integers(0, len(kinds) + 1)), ("pickup", 9001 + 10 * i))
            at = kinds.index(("pickup", 9001 + 10 * i))
            kinds.insert(int(g.integers(at + 1, len(kinds) + 1)), ("dropoff", 9001 + 10 * i))
        if not kinds:
            continue
        locs = g.integers(0, 30, len(kinds)).tolist()
        load = 1 if ("dropoff", 9000 + 10 * i) in kinds else 0
        occ, t, here, stops = load, now, nodes[i], []
        for (kind, tid), loc in zip(kinds, locs):
            t += float(travel([here], [loc])[0, 0])
            occ += 1 if kind == "pickup" else -1
            stops.append(StopView(kind, tid, loc, 1 if kind == "pickup" else -1,
                                  t + float(g.uniform(0, 150)), occ, t))
            if kind == "dropoff":
                t += service
            here = loc
        if max(load, *(s.occupancy for s in stops)) <= capacity:
            plans[a_ids[i]] = tuple(stops)
    picks = g.integers(0, 30, m).tolist()
    drops = [int((p + g.integers(1, 30)) % 30) for p in picks]
    direct = travel(picks, drops, pairwise=True) if m else np.zeros(0)
    t_ids = (g.permutation(1000)[:m] + 5000).tolist()
    tasks = []
    for k in range(m):
        rel = now - float(g.uniform(0, 30))
        tasks.append(TaskView(t_ids[k], "trip", picks[k], rel, drops[k],
                              rel + float(g.uniform(60, 200)), int(g.integers(1, max_pax + 1)),
                              rel + float(direct[k]) + float(g.uniform(30, 300))))
    agents = tuple(AgentView(a_ids[i], "car", nodes[i], 10.0) for i in range(n))
    cost = travel(nodes, picks) if n and m else np.zeros((n, m))
    cost = np.where(now + cost <= np.array([t.deadline for t in tasks]), cost, np.inf) \
        if n and m else cost
    apos, tpos = net.positions(nodes) if n else np.zeros((0, 3)), \
        net.positions(picks) if m else np.zeros((0, 3))
    seats = np.full(n, capacity, np.int64)
    # with a service time, a vehicle without a plan may still be serving its last stop: it
    # leaves at problem.ready (the kernel's free_at), somewhere in the next service time
    ready = None
    if service > 0 and n:
        ready = np.full(n, now)
        for i in range(n):
            if a_ids[i] not in plans and g.random() < 0.5:
                ready[i] = now + float(g.uniform(0, service))

    def build(drives: bool = False) -> AllocationProblem:
        return AllocationProblem(time=now, agents=agents, tasks=tuple(tasks),
                                 cost=np.ascontiguousarray(drive if drives else cost, float),
                                 comm=np.ones((n, n), bool), rng=np.random.default_rng(seed),
                                 max_rounds=200, agent_pos=apos.copy(), task_pos=tpos.copy(),
                                 plans=dict(plans), capacity=seats.copy(),
                                 service_time=service, travel=travel,
                                 ready=None if ready is None else ready.copy())

    # the costs a pooled decision has: the earliest pickup (seconds from now) of the request's
    # cheapest feasible insertion into the vehicle's plan, inf where none is feasible
    from dispatch.answers import route_stops

    drive, cost = cost, np.full((n, m), np.inf)
    draft = build(drives=True)
    for i, a in enumerate(agents):
        keys = [(st.kind, st.task_id) for st in plans.get(a.id, ())]
        for k, t in enumerate(tasks):
            for p in range(len(keys) + 1):
                for q in range(p, len(keys) + 1):
                    route = keys[:p] + [("pickup", t.id)] + keys[p:q] + [("dropoff", t.id)] \
                        + keys[q:]
                    times, _ = route_schedule(draft, a.id, route_stops(draft, a.id, route,
                                                                       {t.id: t}))
                    if times is not None:
                        cost[i, k] = min(cost[i, k], times[p] - now)

    return f"pooled {n} x {m}, capacity {capacity}", build


def pooled_problems(seed: int = 0) -> list[tuple[str, Callable[[], AllocationProblem]]]:
    """The shared-ride problems :func:`check_allocator` adds for multi-request allocators."""
    s = seed * 1000
    return [pooled_problem(s + 1, 1, 1, 2), pooled_problem(s + 2, 3, 6, 3),
            pooled_problem(s + 3, 2, 8, 4, busy=0.0), pooled_problem(s + 4, 6, 10, 4, busy=1.0),
            pooled_problem(s + 5, 4, 5, 2, service=10.0, max_pax=2),
            pooled_problem(s + 6, 5, 0, 2), pooled_problem(s + 7, 0, 4, 2)]


def route_schedule(problem: AllocationProblem, aid: int, rows: list[PlannedStop]
                   ) -> tuple[list[float] | None, str]:
    """Planned arrival times of agent ``aid`` driving the stop rows ``rows`` (of
    :func:`dispatch.answers.route_stops`) from where it is, on ``problem.travel``, by the
    schedule rule (:func:`dispatch.stops.timetable`), or ``(None, why)``: what
    :meth:`dispatch.vehicles.Operator.route_times` checks, from the problem alone (the vehicle
    leaves now, when ``problem.ready`` says, or when its first planned stop's time says)."""
    travel = problem.travel
    k = int(np.flatnonzero(problem.agent_ids == aid)[0])
    loc = problem.agents[k].loc
    cap = 1 if problem.capacity is None else int(problem.capacity[k])
    plan = problem.plans.get(aid, ())
    now = problem.time
    ready = now if problem.ready is None else max(now, float(problem.ready[k]))
    load = 0
    if plan:
        ready = max(now, plan[0].eta - float(travel([loc], [plan[0].loc])[0, 0]))
        load = plan[0].occupancy - plan[0].passengers
    mine = {(s.kind, s.task_id): s for s in plan}
    drops = {s.task_id for s in plan if s.kind == DROPOFF}
    if plan and (rows[0].kind, rows[0].task_id) == (plan[0].kind, plan[0].task_id):
        t = plan[0].eta
    else:
        t = ready + float(travel([loc], [rows[0].loc])[0, 0])
    legs = travel([r.loc for r in rows[:-1]], [r.loc for r in rows[1:]],
                  pairwise=True).tolist() if len(rows) > 1 else []
    service, latest = [], []
    for r in rows:
        old = mine.get((r.kind, r.task_id))
        completes = r.completes
        if completes is None:
            completes = r.kind == DROPOFF or r.task_id not in drops
        service.append(problem.service_time if completes else 0.0)
        latest.append(r.latest if old is None else max(r.latest, old.eta))
    pax = [r.passengers for r in rows]
    times = [0.0] * len(rows)
    # (a problem's plans carry no earliest times: a request's stops never wait)
    bad, over = timetable(t, legs, [-math.inf] * len(rows), service, latest, pax, load, cap,
                          TOL, times)
    if bad < 0:
        return times, ""
    r = rows[bad]
    if over:
        return None, (f"{load + sum(pax[:bad + 1])} on board after {r.kind} of request "
                      f"{r.task_id} (capacity {cap})")
    return None, (f"{r.kind} of request {r.task_id} at {times[bad]:.6g} s, after its latest "
                  f"{r.latest:.6g} s")


def _snapshot(p: AllocationProblem) -> tuple:
    return (p.time, p.agents, p.tasks, p.cost.copy(), p.comm.copy(), p.max_rounds, p.loss,
            p.latency, p.cell_size, p.agent_pos.copy(), p.task_pos.copy(),
            p.cost.flags.writeable, p.comm.flags.writeable)


def _same(a: tuple, b: tuple) -> bool:
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray):
            if not isinstance(y, np.ndarray) or x.shape != y.shape or \
                    not np.array_equal(x, y, equal_nan=True):
                return False
        elif x != y:
            return False
    return True


def _answer(a: Allocation) -> tuple:
    return (tuple(map(tuple, a.pairs)), a.rounds, a.requests, a.messages, a.hops,
            tuple(sorted((k, tuple(map(tuple, v))) for k, v in dict(a.routes).items())))


def _check_routes(problem: AllocationProblem, allocation: Allocation) -> None:
    """AllocationError unless each route of a multi-request answer holds its agent's plan and
    new requests once each, pickups first, within the capacity and every limit."""
    from dispatch.answers import route_stops

    routes = allocation.routes
    if not routes:
        return
    by_task = {t.id: t for t in problem.tasks}
    new: dict = {}
    for aid, tid in allocation.pairs:
        new.setdefault(aid, {})[tid] = by_task[tid]
    for aid, route in routes.items():
        rows = route_stops(problem, aid, route, new.get(aid, {}))
        if rows:
            _, why = route_schedule(problem, aid, rows)
            if why:
                raise AllocationError(f"route of agent {aid} is infeasible: {why}")


def _perturb_global_rng(k: int) -> None:
    import sys

    random.seed(k)
    np.random.seed(k)
    torch = sys.modules.get("torch")  # only if a plugin imported it
    if torch is not None:
        torch.manual_seed(k)


def _declared(kind: str, cls) -> tuple[Report, registry.Capabilities | None]:
    """A fresh report for plugin class ``cls`` of ``kind`` and what it declares (the
    registry's record); a class the registry would refuse (it does not subclass its kind's
    base class, or declares a capability without the method it needs) fails "construct"
    with the reason, and its declaration is None."""
    try:
        caps = registry.capabilities(kind, cls)
    except PluginError as e:
        report = Report(cls.__qualname__)
        report.add("construct", [str(e)], "")
        return report, None
    return Report(caps.name or cls.__name__), caps


def _constructed(kind: str, cls, params: dict) -> tuple[Report, registry.Capabilities | None]:
    """:func:`_declared`, with the "construct" check: ``cls(**params)`` must not raise
    (``report.ok`` says whether it did not)."""
    report, caps = _declared(kind, cls)
    if caps is None:
        return report, caps
    try:
        cls(**params)
    except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
        report.add("construct", [f"{cls.__name__}(**{params!r}) raised {_err(e)}"], "")
        return report, caps
    report.add("construct", [], f"{cls.__name__}(**{params!r})")
    return report, caps


def _replay(label: str, call: Callable[[], Any], first: Any, differs: list[str],
            global_rng: list[str], *, same: Callable[[Any, Any], bool] = lambda a, b: a == b,
            show: Callable[[Any], str] = str, given: str = "input") -> None:
    """Replay a check: ``call()`` (a fresh plugin on a fresh copy of the ``given`` input) must
    give ``first`` again, and again under another global random state. A call that raises or
    answers otherwise is appended to ``differs``; one whose answer follows the global random
    state, to ``global_rng``."""
    try:
        _perturb_global_rng(1)
        again = call()
        _perturb_global_rng(987654)
        other = call()
    except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
        differs.append(f"{label}: a second call raised {_err(e)}")
        return
    if not same(again, first):
        differs.append(f"{label}: the same {given} gave {show(again)}, then {show(first)}")
    elif not same(other, first):
        global_rng.append(f"{label}: the answer changed with the global random state "
                          f"({show(first)} vs {show(other)}); draw only from the seeded "
                          f"generator it is given")


# ----------------------------------------------------------------------------- allocators


def check_allocator(cls, *, seed: int = 0, **params: Any) -> Report:
    """Run every allocator check (see the module docstring) on ``cls(**params)``."""
    from dispatch.answers import validate

    report, caps = _constructed("allocator", cls, params)
    if not report.ok:
        return report
    problems = allocation_problems(seed)
    multi = caps.multi_request
    if multi:  # batch pooling: shared-ride problems, routes checked as the dispatcher does
        problems += pooled_problems(seed)
    invalid, stuck, mutated, differs, global_rng = [], [], [], [], []
    answers: dict[str, tuple] = {}
    for label, build in problems:
        problem = build()
        before = _snapshot(problem)
        try:
            _perturb_global_rng(1)
            allocation = cls(**params).allocate(problem)
        except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
            invalid.append(f"{label}: allocate raised {_err(e)}")
            continue
        if not _same(before, _snapshot(problem)):
            mutated.append(f"{label}: the problem changed during allocate")
        try:
            validate(problem, allocation, multi)
            _check_routes(problem, allocation)
        except AllocationError as e:
            invalid.append(f"{label}: {e}")
            continue
        if np.isfinite(before[3]).any() and not allocation.pairs:
            stuck.append(f"{label}: no pair assigned though some pair is finite")
        answers[label] = _answer(allocation)
    for label, build in problems:
        if label in answers:
            _replay(label, lambda b=build: _answer(cls(**params).allocate(b())), answers[label],
                    differs, global_rng, show=lambda a: str(a[0]), given="problem and seed")
    n = len(problems)
    report.add("valid", invalid, f"{n} problems, every answer accepted")
    report.add("progress", stuck, "assigns a pair whenever one is finite")
    report.add("no-mutation", mutated, "no problem changed")
    report.add("deterministic", differs, "same problem and seed, same answer")
    report.add("rng", global_rng, "answers do not depend on the global random state")
    return report


# ----------------------------------------------------------------------------- planners


def small_world(seed: int = 0):
    """A 12 x 12 x 6 m voxel world of 1 m cells with 4 obstacles (the voxel space's
    :meth:`~dispatch.space.Space.small`)."""
    return space_class("voxel").small(seed)


def small_network():
    """A 6 x 5 Manhattan grid, 100 m blocks, 10 m/s (the road space's
    :meth:`~dispatch.space.Space.small`)."""
    return space_class("road").small()


def check_planner(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every planner check (see the module docstring) on ``cls(space, **params)``; without
    a ``space``, on :func:`small_world` and/or :func:`small_network` (the spaces it serves)."""
    report, caps = _declared("planner", cls)
    if caps is None:
        return report
    if space is None:
        spaces = [space_class(kind).small(seed) for kind in KINDS if caps.serves(kind)]
    else:
        spaces = [space]
    for sp in spaces:
        tag = f" [{sp.kind}]" if len(spaces) > 1 else ""
        _check_planner_on(report, cls, caps, sp, seed, params, tag)
    return report


def _costs(planner, agents, tasks) -> np.ndarray:
    return np.asarray(planner.costs(agents, tasks))


def _check_planner_on(report: Report, cls, caps: registry.Capabilities, space, seed: int,
                      params: dict, tag: str) -> None:
    try:
        cls(space, **params)
    except Exception as e:  # noqa: BLE001
        report.add("construct" + tag, [f"{cls.__name__}(space, **{params!r}) raised {_err(e)}"],
                   "")
        return
    report.add("construct" + tag, [], f"{cls.__name__}(<{space.kind} space>, **{params!r})")
    grid = getattr(space, "grid", None)  # a voxel world's: its occupancy must not change
    occupied = None if grid is None else np.array(grid.occupied, copy=True)
    shapes = [(0, 3), (3, 0), (0, 0), (1, 1), (4, 6), (6, 2)]
    bad_costs, bad_plans, differs, global_rng, bad_bounds = [], [], [], [], []
    bounded = caps.lower_bounds
    for k, (n, m) in enumerate(shapes):
        agents, tasks = space.sample_views(np.random.default_rng(seed * 100 + k), n, m)
        label = f"{n} agents x {m} tasks"
        try:
            _perturb_global_rng(1)
            planner = cls(space, **params)
            c = _costs(planner, agents, tasks)
        except Exception as e:  # noqa: BLE001
            bad_costs.append(f"{label}: costs raised {_err(e)}")
            continue
        if c.shape != (n, m):
            bad_costs.append(f"{label}: costs has shape {c.shape}, expected {(n, m)}")
            continue
        if not np.issubdtype(c.dtype, np.floating) or np.isnan(c).any() or (c < 0).any():
            bad_costs.append(f"{label}: costs must be floats >= 0 or inf (no nan), got "
                             f"{c.dtype} {c.ravel()[:6]}")
            continue
        for i, a in enumerate(agents):
            for j, t in enumerate(tasks):
                if not math.isfinite(c[i, j]):
                    continue
                try:
                    path = planner.plan(a, t.loc)
                except Exception as e:  # noqa: BLE001
                    bad_plans.append(f"{label}: plan raised {_err(e)}")
                    continue
                if not path or not space.reaches(path, a.loc, t.loc):
                    bad_plans.append(f"{label}: agent {a.id} -> task {t.id}: cost {c[i, j]:.3g}"
                                     f" but plan gave {path if not path else (path[0], path[-1])}")
        if bounded:
            bad_bounds += _check_bounds(cls, space, params, agents, tasks, c, label)
        _replay(label, lambda a=agents, t=tasks: _costs(cls(space, **params), a, t), c, differs,
                global_rng, same=np.array_equal, show=lambda c: f"costs {c.ravel()[:4]}",
                given="queries")
    mutated = [] if occupied is None or np.array_equal(occupied, grid.occupied) else \
        ["the world's grid changed"]
    report.add("costs" + tag, bad_costs, f"{len(shapes)} query sets, shapes and values valid")
    report.add("plan" + tag, bad_plans, "a path to the goal wherever the cost is finite")
    report.add("no-mutation" + tag, mutated, "the space is unchanged")
    report.add("deterministic" + tag, differs, "same queries, same costs")
    report.add("rng" + tag, global_rng, "costs do not depend on the global random state")
    if bounded:
        report.add("bounds" + tag, bad_bounds, "lower bounds below the costs, exact ones equal")


def _check_bounds(cls, space, params: dict, agents, tasks, c: np.ndarray,
                  label: str) -> list[str]:
    """What is wrong with a ``lower_bounds`` planner's ``bounds`` and ``exact`` against the
    costs ``c`` of the same queries (each asked of a fresh instance)."""
    bad = []
    try:
        lower, known = cls(space, **params).bounds(agents, tasks)
        lower, known = np.asarray(lower, dtype=float), np.asarray(known)
        rows, cols = np.divmod(np.arange(c.size), max(1, c.shape[1]))
        ex = np.asarray(cls(space, **params).exact(agents, tasks, rows, cols), dtype=float)
    except Exception as e:  # noqa: BLE001
        return [f"{label}: bounds or exact raised {_err(e)}"]
    if lower.shape != c.shape or known.shape != c.shape or known.dtype != bool:
        return [(f"{label}: bounds gave shapes {lower.shape} / {known.shape} "
                 f"({known.dtype}), expected {c.shape} and bool")]
    finite = np.isfinite(c)
    slack = 1e-9 * np.where(finite, np.abs(c), 0.0)
    with np.errstate(invalid="ignore"):  # inf - inf where both are inf: not compared
        return bad + _bound_faults(lower, known, ex, c, finite, slack, label)


def _bound_faults(lower, known, ex, c, finite, slack, label: str) -> list[str]:
    bad = []
    if not np.array_equal(np.isinf(lower), ~finite):
        bad.append(f"{label}: a bound is inf where the cost is finite or the other way round")
    elif (lower[finite] > c[finite] + slack[finite]).any():
        bad.append(f"{label}: a bound is above its cost")
    elif (np.abs(lower - c)[known & finite] > slack[known & finite]).any():
        bad.append(f"{label}: an entry marked exact differs from its cost")
    if ex.shape != (c.size,) or not np.array_equal(np.isinf(ex), ~finite.ravel()) or \
            (np.abs(ex - c.ravel())[finite.ravel()] > slack.ravel()[finite.ravel()]).any():
        bad.append(f"{label}: exact() differs from costs()")
    return bad


# ----------------------------------------------------------------------------- repositioners


def reposition_view(space, vehicles, requests=(), *, time: float = 0.0, horizon: float = 1800.0,
                    targets=None, seed: int = 0):
    """A :class:`~dispatch.reposition.RepositionView` built by hand: ``vehicles`` maps idle
    vehicle ids to where they are (a node or a :class:`~dispatch.legs.RoadPoint`),
    ``requests`` lists ``(release time, pickup node)`` (all inside the horizon), ``targets``
    maps vehicles already repositioning to their target node."""
    from dispatch.reposition import RepositionView, _readonly

    ids = sorted(vehicles)
    locs = [vehicles[i] for i in ids]
    targets = targets or {}
    req = list(requests)
    points = [as_point(p) for p in locs]
    rnodes = _readonly([int(n) for _, n in req], np.int64)
    return RepositionView(
        time=float(time), horizon=float(horizon), vehicle_ids=_readonly(ids, np.int64),
        nodes=_readonly([p.node for p in points], np.int64),
        remaining=_readonly([max(p.remaining, 0.0) for p in points], np.float64),
        targets=_readonly([targets.get(i, -1) for i in ids], np.int64),
        vehicle_pos=_readonly(space.positions(locs) if locs else np.zeros((0, 3)), np.float64),
        request_times=_readonly([float(t) for t, _ in req], np.float64), request_nodes=rnodes,
        request_pos=_readonly(space.positions(rnodes), np.float64), space=space,
        rng=np.random.default_rng(seed))


def _reposition_views(space, seed: int):
    """Labelled view factories (each call builds the same view with a fresh rng)."""
    from dispatch.legs import RoadPoint

    g = np.random.default_rng(seed)
    n = space.n

    def views(label, n_vehicles, n_requests, moving=0, on_edge=0):
        nodes = g.integers(0, n, n_vehicles).tolist()
        ids = (g.permutation(1000)[:n_vehicles] + 1000).tolist()
        vehicles = dict(zip(ids, nodes))
        for vid in ids[:on_edge]:  # part-way along an edge into its node
            node = vehicles[vid]
            prev = int(space._time_t.indices[space._time_t.indptr[node]])
            secs, metres = space.edge(prev, node)
            vehicles[vid] = RoadPoint(node, prev, secs / 2, metres / 2)
        targets = {vid: int(g.integers(0, n)) for vid in ids[on_edge:on_edge + moving]}
        req = [(float(t), int(v)) for t, v in zip(np.sort(g.uniform(0, 1800, n_requests)),
                                                  g.integers(0, n, n_requests))]
        return label, lambda: reposition_view(space, vehicles, req, time=1800.0,
                                              targets=targets, seed=seed)

    return [views("no idle vehicles", 0, 10), views("no requests", 5, 0),
            views("one vehicle, one request", 1, 1), views("8 vehicles, 40 requests", 8, 40),
            views("some repositioning, some on edges", 10, 30, moving=3, on_edge=3),
            views("many vehicles, few requests", 25, 3)]


def _view_snapshot(v) -> tuple:
    arrays = (v.vehicle_ids, v.nodes, v.remaining, v.targets, v.vehicle_pos, v.request_times,
              v.request_nodes, v.request_pos)
    return (v.time, v.horizon, *(a.copy() for a in arrays),
            *(a.flags.writeable for a in arrays))


def check_repositioner(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every repositioner check (see the module docstring) on ``cls(**params)`` with views
    of ``space`` (default :func:`small_network`)."""
    from collections.abc import Mapping

    report, caps = _constructed("repositioner", cls, params)
    if not report.ok:
        return report
    space = space if space is not None else small_network()
    passive = caps.passive
    invalid, mutated, differs, global_rng = [], [], [], []
    answers: dict[str, dict] = {}
    cases = _reposition_views(space, seed)
    for label, build in cases:
        view = build()
        before = _view_snapshot(view)
        try:
            _perturb_global_rng(1)
            moves = cls(**params).reposition(view)
        except Exception as e:  # noqa: BLE001
            invalid.append(f"{label}: reposition raised {_err(e)}")
            continue
        if not _same(before, _view_snapshot(view)):
            mutated.append(f"{label}: the view changed during reposition")
        if not isinstance(moves, Mapping):
            invalid.append(f"{label}: returned {type(moves).__name__}, not a mapping")
            continue
        ids = set(view.vehicle_ids.tolist())
        bad = [(k, v) for k, v in moves.items()
               if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k not in ids
               or isinstance(v, bool) or not isinstance(v, (int, np.integer))
               or not 0 <= v < space.n]
        if bad:
            invalid.append(f"{label}: move {bad[0][0]!r} -> {bad[0][1]!r} names no idle vehicle "
                           f"of the view or no node of the network")
            continue
        if passive and moves:
            invalid.append(f"{label}: a passive repositioner returned {len(moves)} move(s)")
            continue
        answers[label] = dict(moves)
    for label, build in cases:
        if label in answers:
            _replay(label, lambda b=build: dict(cls(**params).reposition(b())), answers[label],
                    differs, global_rng, given="view and seed")
    report.add("valid", invalid, f"{len(cases)} views, every answer a mapping of idle vehicle "
                                 f"ids to nodes")
    report.add("no-mutation", mutated, "no view changed")
    report.add("deterministic", differs, "same view and seed, same moves")
    report.add("rng", global_rng, "moves do not depend on the global random state")
    return report


# ----------------------------------------------------------------------------- charging strategies


def charging_views(space=None, seed: int = 0) -> list[tuple[str, Callable[[], Any]]]:
    """:class:`dispatch.charging_strategy.ChargingView` factories on ``space`` (default
    :func:`small_network`): empty, low batteries, full batteries, busy stations."""
    from dispatch.charging import charge_seconds
    from dispatch.charging_strategy import ChargingView

    space = space if space is not None else small_network()

    def make(label: str, n: int, lo: float, hi: float, busy: bool):
        def build():
            g = np.random.default_rng(seed)
            nodes = g.integers(0, space.n, n)
            st = np.array([0, space.n - 1], dtype=np.int64)

            def ro(a, dtype):
                a = np.array(a, dtype=dtype)
                a.setflags(write=False)
                return a

            return ChargingView(
                time=3600.0 * 5, vehicle_ids=ro(np.arange(n) * 3 + 1, np.int64),
                nodes=ro(nodes, np.int64), remaining=ro(np.zeros(n), float),
                soc=ro(g.uniform(lo, hi, n), float), station_ids=("a", "b"),
                station_nodes=ro(st, np.int64), plugs=ro([1, 2], np.int64),
                in_use=ro([1, 2] if busy else [0, 0], np.int64),
                waiting=ro([2, 0] if busy else [0, 0], np.int64), kw=ro([50.0, 7.2], float),
                released_by_hour=ro([10, 20, 30, 40, 30, 5], np.int64), battery_kwh=50.0,
                reserve=0.1, space=space, rng=np.random.default_rng(seed),
                charge_seconds=lambda a, b, kw: charge_seconds(a, b, 50.0, kw, 0.8, 0.2))
        return label, build

    return [make("no idle vehicle", 0, 0.0, 1.0, False), make("low batteries", 12, 0.0, 0.3,
                                                                False),
            make("full batteries", 8, 0.95, 1.0, False), make("mixed, busy stations", 20, 0.0,
                                                               1.0, True)]


def check_charger(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every charging-strategy check on ``cls(**params)`` (a
    :class:`dispatch.charging_strategy.ChargingStrategy`): each answer a mapping of idle vehicle
    ids of the view to (station id of the view, target in (0, 1]); the view not mutated; same
    view and seed, same answer; no use of the global random state."""
    from collections.abc import Mapping

    report, _ = _constructed("charger", cls, params)
    if not report.ok:
        return report
    invalid, mutated, differs, global_rng = [], [], [], []
    answers: dict[str, dict] = {}
    cases = charging_views(space, seed)

    def snap(view):
        return tuple(np.array(a).tobytes() for a in
                     (view.vehicle_ids, view.nodes, view.remaining, view.soc,
                      view.station_nodes, view.plugs, view.in_use, view.waiting, view.kw,
                      view.released_by_hour))

    for label, build in cases:
        view = build()
        before = snap(view)
        try:
            _perturb_global_rng(1)
            moves = cls(**params).decide(view)
        except Exception as e:  # noqa: BLE001
            invalid.append(f"{label}: decide raised {_err(e)}")
            continue
        if before != snap(view):
            mutated.append(f"{label}: the view changed during decide")
        if not isinstance(moves, Mapping):
            invalid.append(f"{label}: returned {type(moves).__name__}, not a mapping")
            continue
        ids = set(view.vehicle_ids.tolist())
        bad = []
        for k, v in moves.items():
            ok = (not isinstance(k, bool) and isinstance(k, (int, np.integer)) and k in ids
                  and isinstance(v, tuple) and len(v) == 2 and v[0] in view.station_ids
                  and isinstance(v[1], (int, float)) and 0.0 < float(v[1]) <= 1.0)
            if not ok:
                bad.append((k, v))
        if bad:
            invalid.append(f"{label}: {bad[0][0]!r} -> {bad[0][1]!r} names no idle vehicle of "
                           f"the view, no station, or a target outside (0, 1]")
            continue
        answers[label] = {int(k): (v[0], float(v[1])) for k, v in moves.items()}
    for label, build in cases:
        if label in answers:
            _replay(label, lambda b=build: {int(k): (v[0], float(v[1])) for k, v in
                                            cls(**params).decide(b()).items()},
                    answers[label], differs, global_rng, given="view and seed")
    report.add("valid", invalid, f"{len(cases)} views, every answer a mapping of idle vehicle "
                                 f"ids to (station id, target)")
    report.add("no-mutation", mutated, "no view changed")
    report.add("deterministic", differs, "same view and seed, same visits")
    report.add("rng", global_rng, "visits do not depend on the global random state")
    return report
