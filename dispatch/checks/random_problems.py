"""The random problems the allocator checks run on (:mod:`dispatch.checks.allocators`), and the
reference schedule of a multi-request answer's routes on a problem's own travel times.

:func:`allocation_problems`: no agents, no tasks, square and rectangular, rows and columns all
``inf``, ids that are not indices, several communication components, message loss.
:func:`pooled_problems`: shared rides (vehicles with plans, seats, ``problem.travel`` on
:func:`dispatch.checks.common.small_network`). :func:`route_schedule`: a route's planned times
by the schedule rule, or why it is infeasible.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from dispatch.api import registry
from dispatch.api.problem import AgentView, AllocationProblem, StopView, TaskView
from dispatch.checks.common import small_network
from dispatch.decide.answers import route_stops
from dispatch.plan.stops import DROPOFF, TOL, PlannedStop, leave, timetable


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
    """``(label, factory)`` of the problems :func:`~dispatch.checks.allocators.check_allocator`
    runs (a factory builds the same problem, with a fresh ``rng`` of the same seed, at every
    call)."""
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
    """The shared-ride problems :func:`~dispatch.checks.allocators.check_allocator` adds for
    multi-request allocators."""
    s = seed * 1000
    return [pooled_problem(s + 1, 1, 1, 2), pooled_problem(s + 2, 3, 6, 3),
            pooled_problem(s + 3, 2, 8, 4, busy=0.0), pooled_problem(s + 4, 6, 10, 4, busy=1.0),
            pooled_problem(s + 5, 4, 5, 2, service=10.0, max_pax=2),
            pooled_problem(s + 6, 5, 0, 2), pooled_problem(s + 7, 0, 4, 2)]


def route_schedule(problem: AllocationProblem, aid: int, rows: list[PlannedStop]
                   ) -> tuple[list[float] | None, str]:
    """Planned arrival times of agent ``aid`` driving the stop rows ``rows`` (of
    :func:`dispatch.decide.answers.route_stops`) from where it is, on ``problem.travel``, by the
    schedule rule (:func:`dispatch.plan.stops.timetable`; a stop waits for its row's
    ``earliest``), or ``(None, why)``: what :meth:`dispatch.plan.operator.Operator.route_times`
    checks, from the problem alone (the vehicle leaves now, when ``problem.ready`` says, or
    when its first planned stop's time says; its route ends by ``problem.until``)."""
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
    service, latest, earliest = [], [], []
    for r in rows:
        old = mine.get((r.kind, r.task_id))
        completes = r.completes
        if completes is None:
            completes = r.kind == DROPOFF or r.task_id not in drops
        service.append(problem.service_time if completes else 0.0)
        latest.append(r.latest if old is None else max(r.latest, old.eta))
        earliest.append(r.earliest)
    pax = [r.passengers for r in rows]
    times = [0.0] * len(rows)
    bad, over = timetable(t, legs, earliest, service, latest, pax, load, cap, TOL, times)
    if bad < 0:
        end = leave(times[-1], earliest[-1], service[-1])
        until = math.inf if problem.until is None else float(problem.until[k])
        if end > until + TOL:
            return None, f"the route ends at {end:.6g} s, after its shift end {until:.6g} s"
        return times, ""
    r = rows[bad]
    if over:
        return None, (f"{load + sum(pax[:bad + 1])} on board after {r.kind} of request "
                      f"{r.task_id} (capacity {cap})")
    return None, (f"{r.kind} of request {r.task_id} at {times[bad]:.6g} s, after its latest "
                  f"{r.latest:.6g} s")
