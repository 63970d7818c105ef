"""``rtv`` with stop earliest times (booked pickups, plan stops that wait) and vehicles whose
routes must end by a shift limit (``problem.until``): the kernel's route costs are those of the
one schedule rule (:func:`dispatch.plan.stops.timetable`, through
:func:`dispatch.checks.random_problems.route_schedule`) on its chosen order, its best order is the
best of every order, and its answers serve as many requests at the same cost as an exhaustive
search over every grouping and every order."""

from __future__ import annotations

import dataclasses
import math
from itertools import combinations

import numpy as np
import pytest

from allocators.rtv import RtvAllocator, _Batch
from dispatch.checks.random_problems import pooled_problem, route_schedule
from dispatch.decide.answers import route_stops, validate
from dispatch.plan.stops import leave
from tests.dispatch.test_rtv import _all_orders, _orders, _route_cost, _value, brute_force


def timed_problem(seed: int, n: int, m: int, cap: int, *, busy: float = 0.6,
                  service: float = 0.0, max_pax: int = 1, until: bool = True):
    """A :func:`pooled_problem` with earliest times: about half its requests booked (requested
    departure 0-400 s after the decision: release, limits and the pickup's ``earliest`` count
    from it), about half its plans' pickups waiting for an earliest time (the planned arrivals
    by the rule), with ``until`` about half its vehicles' routes ending by a limit; the costs
    recomputed as a pooled decision has them (the earliest pickup of the cheapest feasible
    insertion, by the rule)."""
    problem = pooled_problem(seed, n, m, cap, busy=busy, service=service, max_pax=max_pax)[1]()
    g = np.random.default_rng([seed, 31])
    now, travel, svc = problem.time, problem.travel, problem.service_time
    tasks = []
    for t in problem.tasks:
        if g.random() < 0.5:
            dep = now + float(g.uniform(0.0, 400.0))
            direct = float(travel([t.loc], [t.dropoff])[0, 0])
            t = dataclasses.replace(t, released_at=dep, deadline=dep + float(g.uniform(60, 200)),
                                    dropoff_deadline=dep + direct + float(g.uniform(30, 300)),
                                    earliest=dep)
        tasks.append(t)
    ids = problem.agent_ids.tolist()
    plans = {}
    for aid, stops in problem.plans.items():
        here, t, out = problem.agents[ids.index(aid)].loc, now, []
        for s in stops:
            t += float(travel([here], [s.loc])[0, 0])
            e = t + float(g.uniform(-30.0, 200.0)) if s.kind == "pickup" and g.random() < 0.5 \
                else -math.inf
            out.append(s._replace(eta=t, earliest=e, latest=t + (s.latest - s.eta)))
            t = leave(t, e, svc if s.kind == "dropoff" else 0.0)
            here = s.loc
        plans[aid] = tuple(out)
    lim = np.where(g.random(n) < 0.5, now + g.uniform(100.0, 1200.0, n), np.inf) if until \
        else None
    draft = dataclasses.replace(problem, tasks=tuple(tasks), plans=plans, until=lim)
    cost = np.full((n, m), np.inf)
    for i, aid in enumerate(ids):
        keys = [(s.kind, s.task_id) for s in plans.get(aid, ())]
        for k, t in enumerate(tasks):
            for p in range(len(keys) + 1):
                for q in range(p, len(keys) + 1):
                    route = keys[:p] + [("pickup", t.id)] + keys[p:q] + [("dropoff", t.id)] \
                        + keys[q:]
                    times, _ = route_schedule(draft, aid, route_stops(draft, aid, route,
                                                                      {t.id: t}))
                    if times is not None:
                        cost[i, k] = min(cost[i, k], times[p] - now)
    return dataclasses.replace(draft, cost=np.ascontiguousarray(cost))


def _route(batch: _Batch, problem, j: int, rs: list[int], codes) -> list:
    """The (kind, task id) route of the kernel's order ``codes`` for vehicle row ``j`` and the
    batch's requests ``rs``."""
    plan, tids, out = batch.plans[j], problem.task_ids, []
    for code in codes:
        if code == -99:
            break
        if code < 0:
            s = plan[-code - 1]
            out.append((s.kind, int(s.task_id)))
        else:
            out.append(("pickup" if code % 2 == 0 else "dropoff", int(tids[rs[code // 2]])))
    return out


ORDER_CASES = [(seed, 1 + seed % 3, 2 + seed % 3, 2 + seed % 2, (0.0, 20.0)[seed % 4 == 3],
                seed % 5 == 4) for seed in range(30)]


@pytest.mark.parametrize("seed, n, m, cap, service, reorder", ORDER_CASES)
def test_route_costs_are_the_rule_and_the_best_of_every_order(seed, n, m, cap, service,
                                                              reorder):
    """Every (vehicle, group of up to 3 requests) of a small decision: the kernel's cost is
    ``inf`` exactly when no order keeps every limit (waits included), else its order timed by
    the one rule costs what the kernel says, and no order costs less."""
    problem = timed_problem(seed + 40, n, m, cap, service=service)
    for objective in ("delay", "added_time"):
        alloc = RtvAllocator(objective=objective, reorder=reorder, max_nodes=10**7)
        batch = _Batch(problem, alloc)
        if batch.empty:
            continue
        groups, gveh = [], []
        for j in range(batch.nv):
            for k in (1, 2, 3):
                for g in combinations(range(batch.m), k):
                    groups.append(list(g) + [-1] * (3 - k))
                    gveh.append(j)
        cost, order, cut, end = batch.evaluate(np.array(groups, np.int64),
                                               np.array(gveh, np.int64))
        assert not cut.any()
        orders = _all_orders if reorder else _orders
        for g, j, c, codes, e in zip(groups, gveh, cost.tolist(), order, end.tolist()):
            rs = [r for r in g if r >= 0]
            aid = int(batch.aids[j])
            new = {problem.tasks[r].id: problem.tasks[r] for r in rs}
            keys = [(s.kind, s.task_id) for s in problem.plans.get(aid, ())]
            every = [_route_cost(problem, aid, r, new, objective) for r in orders(keys, new)]
            every = [x for x in every if x is not None]
            if not math.isfinite(c):
                assert not every, (aid, rs)
                continue
            got = _route_cost(problem, aid, _route(batch, problem, j, rs, codes), new,
                              objective)
            assert got is not None and got == pytest.approx(c, abs=1e-6)
            assert c == pytest.approx(min(every), abs=1e-6)
            if objective == "added_time":  # the route ends that much after the plan did
                assert e == pytest.approx(batch.old_end[j] + c, abs=1e-6)


CASES = [(seed, 1 + seed % 3, 2 + seed % 4, 1 + (seed // 3) % 3, (0.0, 0.5, 1.0)[seed % 3],
          1 + (seed // 2) % 2) for seed in range(30)]


@pytest.mark.parametrize("seed, n, m, cap, busy, max_pax", CASES)
def test_rtv_with_earliest_times_matches_brute_force(seed, n, m, cap, busy, max_pax):
    """Small decisions with booked requests, waiting plan stops and shift limits: as many
    requests served, at the same total cost, as the best of every grouping and order (with
    ``reorder`` on every third case); every route the dispatcher's check accepts."""
    problem = timed_problem(seed + 200, n, m, cap, busy=busy, max_pax=max_pax,
                            service=(0.0, 15.0)[seed % 2])
    objective = "delay" if seed % 4 else "added_time"
    reorder = seed % 3 == 0
    alloc = RtvAllocator(objective=objective, reorder=reorder)
    answer = alloc.allocate(problem)
    validate(problem, answer, multi=True)
    served, cost = _value(problem, answer, objective)
    want = brute_force(problem, objective, reorder=reorder)
    assert served == want[0]
    assert cost == pytest.approx(want[1], abs=1e-6)


def test_the_cases_wait_and_end_by_their_limits():
    """The decisions above do hold routes that wait for an earliest time, and routes that a
    vehicle's ``until`` alone rules out (else the checks would be vacuous)."""
    waits = limited = 0
    for seed, n, m, cap, busy, max_pax in CASES:
        problem = timed_problem(seed + 200, n, m, cap, busy=busy, max_pax=max_pax,
                                service=(0.0, 15.0)[seed % 2])
        answer = RtvAllocator().allocate(problem)
        new: dict = {}
        by_task = {t.id: t for t in problem.tasks}
        for aid, tid in answer.pairs:
            new.setdefault(aid, {})[tid] = by_task[tid]
        for aid, route in answer.routes.items():
            rows = route_stops(problem, aid, route, new[aid])
            times, _ = route_schedule(problem, aid, rows)
            waits += any(t < r.earliest for r, t in zip(rows, times))
        free = RtvAllocator().allocate(dataclasses.replace(problem, until=None))
        limited += len(free.pairs) > len(answer.pairs)
    assert waits >= 5 and limited >= 1


def test_without_earliest_times_nothing_changes():
    """Views and plans without earliest times and no ``until``: the answers of the problems
    as :func:`pooled_problem` makes them, unchanged by the fields' presence."""
    for seed in range(12):
        problem = pooled_problem(seed, 1 + seed % 3, 2 + seed % 4, 2, busy=0.5)[1]()
        assert problem.until is None
        assert all(t.earliest == -math.inf for t in problem.tasks)
        a = RtvAllocator().allocate(problem)
        b = RtvAllocator().allocate(dataclasses.replace(
            problem, until=np.full(problem.n_agents, np.inf)))
        assert a.routes == b.routes and a.pairs == b.pairs
