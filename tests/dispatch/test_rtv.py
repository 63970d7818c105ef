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
from dispatch.dispatcher import route_stops, validate
from dispatch.testing import check_allocator, pooled_problem, route_schedule
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


def brute_force(problem, objective="delay"):
    """``(requests served, least total cost)`` over every assignment of groups of new requests
    (at most a vehicle's seats each) to vehicles, each group in its best stop order."""
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
        got = [_route_cost(problem, aid, r, new, objective) for r in _orders(plan_keys, new)]
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
    from dispatch.runner import make_recorder
    from dispatch.scenario import load_scenario
    from dispatch.sim import Simulation
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
    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"))
    sim.allocator = allocator
    sim.run()
    sim.recorder.finish()
    import pyarrow.parquet as pq
    return {n: pq.read_table(next((tmp_path / "out" / n).rglob("part-0.parquet"))).to_pandas()
            for n in ("tasks", "events")}


RUNS = [(cap, delay, faults, obj, seed)
        for seed, (cap, delay, faults, obj) in enumerate(
            (1 + i % 6, (None, 150.0)[i // 2 % 2], bool(i // 3 % 2),
             ("pickup_time", "added_time")[i // 5 % 2]) for i in range(24))]


def test_invariants_on_random_pooled_runs_with_rtv(tmp_path):
    """24 random runs (capacities 1-6, with and without max_delay, faults on and off, service
    times): the stop-list invariants hold and the runs share rides."""
    shared = 0
    for k, (cap, delay, faults, obj, seed) in enumerate(RUNS):
        d = tmp_path / f"run{k}"
        d.mkdir()
        summary, tables = _run(d, allocator="rtv", capacity=cap, max_delay=delay,
                               faults=faults, objective=obj, seed=seed + 500,
                               service=5.0 if k % 4 == 0 else 0.0)
        check_invariants(summary, tables)
        shared += int(tables["tasks"].shared.sum())
    assert shared > 0


def test_rtv_answers_single_requests_without_travel():
    """Without ``problem.travel`` (a voxel world) it is the linear assignment."""
    from allocators.hungarian import HungarianAllocator
    from dispatch.testing import allocation_problems

    for _, build in allocation_problems(0):
        p = build()
        assert RtvAllocator().allocate(p).pairs == HungarianAllocator().allocate(p).pairs \
            or not np.isfinite(p.cost).any()
