"""The ``rtv`` allocator (batch pooling): against an exhaustive search over every grouping on
small shared-ride decisions, every route feasible, the plugin checks, what its bounds cut, and
random pooled runs checked for the stop-list invariants."""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from allocators.rtv import RtvAllocator
from dispatch.checks.allocators import check_allocator
from dispatch.checks.random_problems import pooled_problem, route_schedule
from dispatch.decide.answers import route_stops, validate
from tests.dispatch.test_pooling import _run, check_invariants


def _orders(plan_keys, new_ids):
    """Every stop order: the plan's stops in their order, each new request's pickup before its
    drop-off, merged in every way."""
    out = []

    def rec(seq, k, state):
        if k == len(plan_keys) and all(s == 2 for s in state.values()):
            out.append(tuple(seq))
            return
        if k < len(plan_keys):
            rec(seq + [plan_keys[k]], k + 1, state)
        for tid, s in state.items():
            if s < 2:
                rec(seq + [("pickup" if s == 0 else "dropoff", tid)], k,
                    {**state, tid: s + 1})

    rec([], 0, {t: 0 for t in new_ids})
    return out


def _all_orders(plan_keys, new_ids):
    """Every stop order of the plan's stops and the new requests' together: each pickup before
    its drop-off (a plan's drop-off after its pickup where that is in the plan too), any stop
    first (the kernel re-routes a vehicle whose first stop changes: it finishes the edge it is
    on and drives to the new first stop; the drive it is on counts only when its stop stays
    first: :func:`dispatch.checks.random_problems.route_schedule`)."""
    stops = list(plan_keys) + [(k, t) for t in new_ids for k in ("pickup", "dropoff")]
    out = []

    def rec(seq, left):
        if not left:
            out.append(tuple(seq))
            return
        for s in left:
            if s[0] == "dropoff" and ("pickup", s[1]) in left:
                continue
            rec(seq + [s], [x for x in left if x != s])

    rec([], stops)
    return out


def _route_cost(problem, aid, route, new, objective):
    """``(cost, rows)`` of ``route`` for agent ``aid`` given the new requests ``new`` (id ->
    TaskView), or None where infeasible: every limit and the capacity checked by
    :func:`route_schedule` (what the dispatcher checks)."""
    rows = route_stops(problem, aid, route, new)
    times, why = route_schedule(problem, aid, rows)
    if why:
        return None
    plan = {(s.kind, s.task_id): s for s in problem.plans.get(aid, ())}
    if objective == "added_time":
        svc = problem.service_time
        end = times[-1] + (svc if rows[-1][5] or rows[-1][0] == "dropoff" else 0.0)
        p = problem.plans.get(aid, ())
        k = int(np.flatnonzero(problem.agent_ids == aid)[0])
        bare_end = problem.time if problem.ready is None else max(problem.time,
                                                                  float(problem.ready[k]))
        old = p[-1].eta + svc if p else bare_end
        return end - old
    cost = 0.0
    for (kind, tid, *_), t in zip(rows, times):
        if kind != "dropoff":
            continue
        if (kind, tid) in plan:
            cost += t - plan[(kind, tid)].eta
        else:
            task = new[tid]
            direct = float(problem.travel([task.loc], [task.dropoff])[0, 0])
            cost += t - task.released_at - direct
    return cost


def brute_force(problem, objective="delay", reorder=False):
    """``(requests served, least total cost)`` over every assignment of groups of new requests
    (at most a vehicle's seats each) to vehicles, each group in its best stop order (with
    ``reorder``: the plan's stops reordered too, :func:`_all_orders`)."""
    orders = _all_orders if reorder else _orders
    travel = problem.travel

    @cache
    def between(sources, targets, pairwise=False):
        return travel(list(sources), list(targets), pairwise=pairwise)

    problem = dataclasses.replace(problem, travel=lambda s, t, pairwise=False: between(
        tuple(s), tuple(t), pairwise))
    tasks = problem.tasks
    m = len(tasks)
    aids = problem.agent_ids.tolist()

    @cache
    def best(k, mask):
        aid = aids[k]
        if mask == 0:
            return 0.0
        new = {tasks[i].id: tasks[i] for i in range(m) if mask >> i & 1}
        if len(new) > int(problem.capacity[k]):
            return None
        plan_keys = [(s.kind, s.task_id) for s in problem.plans.get(aid, ())]
        got = [_route_cost(problem, aid, r, new, objective) for r in orders(plan_keys, new)]
        got = [c for c in got if c is not None]
        return min(got) if got else None

    @cache
    def solve(k, used):
        if k == len(aids):
            return (0, 0.0)
        top = solve(k + 1, used)
        free = ((1 << m) - 1) & ~used
        sub = free
        while sub:
            c = best(k, sub)
            if c is not None:
                rest = solve(k + 1, used | sub)
                cand = (rest[0] + sub.bit_count(), rest[1] + c)
                if cand[0] > top[0] or (cand[0] == top[0] and cand[1] < top[1] - 1e-9):
                    top = cand
            sub = (sub - 1) & free
        return top

    return solve(0, 0)


def _value(problem, allocation, objective="delay"):
    by_task = {t.id: t for t in problem.tasks}
    new: dict = {}
    for aid, tid in allocation.pairs:
        new.setdefault(aid, {})[tid] = by_task[tid]
    total = 0.0
    for aid, route in allocation.routes.items():
        c = _route_cost(problem, aid, route, new[aid], objective)
        assert c is not None, (aid, route)
        total += c
    return len(allocation.pairs), total


CASES = [(seed, 1 + seed % 3, 2 + seed % 5, 1 + (seed // 3) % 3, (0.0, 0.5, 1.0)[seed % 3],
          1 + (seed // 2) % 2) for seed in range(36)]


@pytest.mark.parametrize("seed, n, m, cap, busy, max_pax", CASES)
def test_rtv_matches_brute_force(seed, n, m, cap, busy, max_pax):
    """Small decisions (<= 3 vehicles, <= 6 requests, <= 3 seats, plans on board): as many
    requests served, at the same total cost, as the best of every grouping."""
    _, build = pooled_problem(seed, n, m, cap, busy=busy, max_pax=max_pax)
    problem = build()
    objective = "delay" if seed % 4 else "added_time"
    alloc = RtvAllocator(objective=objective)
    answer = alloc.allocate(problem)
    validate(problem, answer, multi=True)
    served, cost = _value(problem, answer, objective)
    want = brute_force(problem, objective)
    assert served == want[0]
    assert cost == pytest.approx(want[1], abs=1e-6)
    assert not any(alloc.stats[k] for k in ("pairs_cut", "groups_cut", "orders_cut",
                                            "levels_cut", "ilp_time_limit"))


@pytest.mark.parametrize("seed", range(12))
def test_rtv_matches_brute_force_with_vehicles_in_service(seed):
    """With a service time, plan-less vehicles still serving their last stop leave at
    ``problem.ready``: rtv schedules from it (as the brute force and the kernel do), so it
    serves as many at the same cost, and never plans a departure before it."""
    _, build = pooled_problem(seed + 500, 1 + seed % 3, 2 + seed % 4, 1 + seed % 3,
                              busy=0.3, service=30.0, max_pax=1 + seed % 2)
    problem = build()
    assert problem.ready is not None
    objective = "delay" if seed % 2 else "added_time"
    answer = RtvAllocator(objective=objective).allocate(problem)
    validate(problem, answer, multi=True)
    served, cost = _value(problem, answer, objective)
    want = brute_force(problem, objective)
    assert served == want[0]
    assert cost == pytest.approx(want[1], abs=1e-6)


def test_rtv_reads_ready_times():
    """A vehicle whose service ends just before a request's pickup deadline is too late for
    it: rtv leaves it out rather than planning a departure it cannot make."""
    for seed in range(40):
        _, build = pooled_problem(seed + 900, 2, 3, 2, busy=0.0, service=60.0)
        problem = build()
        late = dataclasses.replace(problem, ready=np.full(problem.n_agents, problem.time + 1e4))
        answer = RtvAllocator().allocate(late)
        assert not answer.pairs  # nobody is free before every pickup deadline has passed
        validate(late, answer, multi=True)


def test_the_brute_force_sees_groups():
    """The cases above do put several requests in one vehicle."""
    multi = 0
    for seed, n, m, cap, busy, max_pax in CASES:
        problem = pooled_problem(seed, n, m, cap, busy=busy, max_pax=max_pax)[1]()
        answer = RtvAllocator().allocate(problem)
        per = {}
        for aid, _ in answer.pairs:
            per[aid] = per.get(aid, 0) + 1
        multi += any(c > 1 for c in per.values())
    assert multi >= 5


@pytest.mark.parametrize("params", [{}, {"solver": "greedy"}, {"objective": "added_time"},
                                    {"max_requests": 2, "max_groups": 3}])
def test_check_allocator_covers_routes(params):
    report = check_allocator(RtvAllocator, **params)
    assert report.ok, str(report)


def test_check_allocator_catches_a_bad_route():
    """A multi-request allocator whose routes break a limit fails ``valid``."""
    class Late(RtvAllocator):
        def allocate(self, problem):
            a = super().allocate(problem)
            # every routed agent serves its requests last, after a detour through its plan
            routes = {aid: tuple(sorted(r, key=lambda s: s[0] == "pickup")) for aid, r in
                      a.routes.items()}
            return type(a)(pairs=a.pairs, routes=routes)

    report = check_allocator(Late)
    assert not report.ok and "valid" in str(report)


def test_bounds_are_counted():
    problem = pooled_problem(3, 3, 8, 3, busy=0.3)[1]()
    a = RtvAllocator(max_requests=2, max_groups=2)
    validate(problem, a.allocate(problem), multi=True)
    assert a.stats["pairs_cut"] > 0 and a.stats["groups_cut"] > 0
    assert "pairs_cut" in a.describe()
    b = RtvAllocator(max_nodes=1)
    validate(problem, b.allocate(problem), multi=True)
    assert b.stats["orders_cut"] > 0


def test_milp_is_no_worse_than_greedy():
    for seed in range(12):
        problem = pooled_problem(100 + seed, 4, 8, 3, busy=0.4)[1]()
        exact = _value(problem, RtvAllocator().allocate(problem))
        greedy = _value(problem, RtvAllocator(solver="greedy").allocate(problem))
        assert exact[0] >= greedy[0]
        if exact[0] == greedy[0]:
            assert exact[1] <= greedy[1] + 1e-6


@pytest.mark.parametrize("kwargs", [{"max_group": 0}, {"objective": "x"}, {"time_limit": 0},
                                    {"solver": "cplex"}, {"max_requests": 1.5}])
def test_bad_parameters(kwargs):
    with pytest.raises(TypeError):
        RtvAllocator(**kwargs)


def test_one_taxi_gets_two_requests_at_once(tmp_path):
    """Two requests released together and one two-seat taxi: rtv gives it both in one
    decision (one route), and both ride shared."""
    seen = []

    class Spy(RtvAllocator):
        def allocate(self, problem):
            a = super().allocate(problem)
            seen.append(a)
            return a

    got = _drive(tmp_path, Spy())
    tasks = got["tasks"].set_index("task_id").sort_index()
    assert list(tasks.state) == ["completed", "completed"] and tasks.shared.all()
    assert any(len(a.pairs) == 2 and len(a.routes) == 1 for a in seen)


def _drive(tmp_path: Path, allocator):
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario
    from tests.dispatch.test_trips import road_scenario, write_csv

    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 1, 4), (0.0, 2, 3)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                                         'max_wait = 100.0\nmax_delay = 100.0',
                         fleet='start = "fleet.csv"\ncapacity = 2',
                         network='network = "manhattan"\nblocks = [5, 2]\nblock = 100.0\n'
                                 'speed = 10.0', allocator="rtv", extra="batch_window = 5.0")
    [spec] = load_scenario(path).runs()
    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"), allocator=allocator)
    sim.run()
    sim.recorder.finish()
    import pyarrow.parquet as pq
    return {n: pq.read_table(next((tmp_path / "out" / n).rglob("part-0.parquet"))).to_pandas()
            for n in ("tasks", "events")}


RUNS = [(cap, delay, faults, obj, seed)
        for seed, (cap, delay, faults, obj) in enumerate(
            (1 + i % 6, (None, 150.0)[i // 2 % 2], bool(i // 3 % 2),
             ("pickup_time", "added_time")[i // 5 % 2]) for i in range(24))]


def _pooled_runs(tmp_path) -> int:
    """The runs of :data:`RUNS` with ``rtv`` (a folder each under ``tmp_path``), the stop-list
    invariants checked on each: how many tasks shared a ride in all."""
    shared = 0
    for k, (cap, delay, faults, obj, seed) in enumerate(RUNS):
        d = tmp_path / f"run{k}"
        d.mkdir()
        summary, tables = _run(d, allocator="rtv", capacity=cap, max_delay=delay,
                               faults=faults, objective=obj, seed=seed + 500,
                               service=5.0 if k % 4 == 0 else 0.0)
        check_invariants(summary, tables)
        shared += int(tables["tasks"].shared.sum())
    return shared


def test_invariants_on_random_pooled_runs_with_rtv(tmp_path):
    """24 random runs (capacities 1-6, with and without max_delay, faults on and off, service
    times): the stop-list invariants hold and the runs share rides."""
    assert _pooled_runs(tmp_path) > 0


def test_rtv_answers_single_requests_without_travel():
    """Without ``problem.travel`` (a voxel world) it is the linear assignment."""
    from allocators.hungarian import HungarianAllocator
    from dispatch.checks.random_problems import allocation_problems

    for _, build in allocation_problems(0):
        p = build()
        assert RtvAllocator().allocate(p).pairs == HungarianAllocator().allocate(p).pairs \
            or not np.isfinite(p.cost).any()


# ----------------------------------------------------------------------------- reorder
REORDER_CASES = [(seed, 1 + seed % 3, 2 + seed % 4, 1 + (seed // 3) % 3,
                  (0.5, 1.0)[seed % 2], 1 + (seed // 2) % 2) for seed in range(30)]


@pytest.mark.parametrize("seed, n, m, cap, busy, max_pax", REORDER_CASES)
def test_rtv_reorder_matches_brute_force(seed, n, m, cap, busy, max_pax):
    """With ``reorder`` (<= 3 vehicles, <= 5 requests, plans of <= 3 stops, mostly busy
    vehicles): as many requests served, at the same total cost, as the best of every grouping
    with every order of the plan's stops and the new ones; and never fewer served or a higher
    cost than without ``reorder``."""
    _, build = pooled_problem(seed + 700, n, m, cap, busy=busy, max_pax=max_pax,
                              service=(0.0, 20.0)[seed % 3 == 2])
    problem = build()
    assert all(len(p) <= 3 for p in problem.plans.values())
    objective = "delay" if seed % 4 else "added_time"
    alloc = RtvAllocator(objective=objective, reorder=True)
    answer = alloc.allocate(problem)
    validate(problem, answer, multi=True)
    served, cost = _value(problem, answer, objective)
    want = brute_force(problem, objective, reorder=True)
    assert served == want[0]
    assert cost == pytest.approx(want[1], abs=1e-6)
    assert not any(alloc.stats[k] for k in ("pairs_cut", "groups_cut", "orders_cut",
                                            "levels_cut", "ilp_time_limit"))
    plain = _value(problem, RtvAllocator(objective=objective).allocate(problem), objective)
    assert served >= plain[0]
    assert served > plain[0] or cost <= plain[1] + 1e-6


def test_reorder_changes_plans_and_gains():
    """The cases above do reorder plans, and somewhere reordering serves more or costs less
    (else the search would be a no-op)."""
    reordered = better = 0
    for seed, n, m, cap, busy, max_pax in REORDER_CASES:
        problem = pooled_problem(seed + 700, n, m, cap, busy=busy, max_pax=max_pax,
                                 service=(0.0, 20.0)[seed % 3 == 2])[1]()
        alloc = RtvAllocator(reorder=True)
        got = _value(problem, alloc.allocate(problem))
        plain = _value(problem, RtvAllocator().allocate(problem))
        reordered += alloc.stats["reordered"]
        better += got[0] > plain[0] or got[1] < plain[1] - 1e-6
    assert reordered >= 3 and better >= 3


@pytest.mark.parametrize("seed", range(16))
def test_reorder_never_worse_on_larger_decisions(seed):
    """Larger decisions (4-6 vehicles, 8-12 requests, up to 4 seats), no bound cutting: the
    search with ``reorder`` holds every order the one without holds, so it serves as many at
    no more cost (or more)."""
    problem = pooled_problem(seed + 1300, 4 + seed % 3, 8 + seed % 5, 2 + seed % 3,
                             busy=0.8)[1]()
    objective = "delay" if seed % 2 else "added_time"
    big = {"objective": objective, "max_groups": 100_000, "max_nodes": 10**7}
    a, b = RtvAllocator(reorder=True, **big), RtvAllocator(**big)
    got = _value(problem, a.allocate(problem), objective)
    plain = _value(problem, b.allocate(problem), objective)
    for alloc in (a, b):
        assert not any(alloc.stats[k] for k in ("groups_cut", "orders_cut", "levels_cut",
                                                "ilp_time_limit"))
    assert got[0] >= plain[0]
    assert got[0] > plain[0] or got[1] <= plain[1] + 1e-6


def test_reorder_false_is_the_default_and_unchanged():
    """``reorder = false`` (the default) gives the same answers as before the option: the plan's
    order kept in every route, and ``describe`` without the key."""
    for seed, n, m, cap, busy, max_pax in CASES[:12]:
        problem = pooled_problem(seed, n, m, cap, busy=busy, max_pax=max_pax)[1]()
        a = RtvAllocator()
        answer = a.allocate(problem)
        for aid, route in answer.routes.items():
            plan = [(s.kind, s.task_id) for s in problem.plans.get(aid, ())]
            assert [s for s in route if s in plan] == plan
        assert "reorder" not in a.describe() and "reordered" not in a.stats
    assert RtvAllocator(reorder=True).describe()["reorder"] == "True"
    with pytest.raises(TypeError):
        RtvAllocator(reorder="yes")


def test_check_allocator_covers_reorder():
    report = check_allocator(RtvAllocator, reorder=True)
    assert report.ok, str(report)


def test_invariants_on_random_pooled_runs_with_rtv_reorder(tmp_path, monkeypatch):
    """The 24 random runs of :func:`test_invariants_on_random_pooled_runs_with_rtv` with
    ``reorder``: the dispatcher accepts and drives the reordered routes (vehicles on their
    way to a stop re-routed, part-way along an edge), the stop-list invariants hold, rides are
    shared and plans are reordered."""
    made = []
    original = RtvAllocator.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **{**kwargs, "reorder": True})
        made.append(self)

    monkeypatch.setattr(RtvAllocator, "__init__", init)
    from dispatch.plan.operator import Operator

    swapped = moved = 0
    follow = Operator.follow

    def spy(self, v, rows, times, tasks, costs, meetings=None):  # what the kernel drives
        nonlocal swapped, moved
        old = [(s.kind, s.task.id) for s in v.plan]
        mine = [(r[0], r[1]) for r in rows if (r[0], r[1]) in old]
        if mine != old:
            swapped += 1
            moved += v.leg is not None and mine[0] != old[0]  # its head moved, mid-drive
        return follow(self, v, rows, times, tasks, costs, meetings)

    monkeypatch.setattr(Operator, "follow", spy)
    shared = _pooled_runs(tmp_path)
    assert made and all(a.reorder for a in made)
    assert shared > 0
    assert sum(a.stats["reordered"] for a in made) >= swapped > 0  # (a stale route is dropped)
    assert moved > 0
