"""The ``auction`` allocator (CBBA): conflict-free consensus on connected graphs, CBBA's own
fixed-point conditions checked by brute force, rounds on a line graph, message loss, and
disconnected graphs settled by the conflict rule."""

from __future__ import annotations

import dataclasses
import random

import numpy as np
import pytest

from allocators.auction import AuctionAllocator, better
from dispatch.api import registry
from dispatch.api.comms import comm_graph, components, diameter
from dispatch.api.problem import AgentView, AllocationProblem, TaskView
from dispatch.errors import PluginError
from dispatch.run.plugins import make_plugin

from .helpers import assert_valid, index_pairs, make_problem, random_problem, total_cost


def line(n: int) -> np.ndarray:
    c = np.eye(n, dtype=bool)
    i = np.arange(n - 1)
    c[i, i + 1] = c[i + 1, i] = True
    return c


def spatial_problem(seed: int, n: int, m: int, *, comm_range=None, loss=0.0, p_inf=0.0,
                    size=30.0) -> AllocationProblem:
    """Agents and tasks at random cells of a ``size`` m square (1 m cells), cost = straight-line
    distance / speed times a random detour factor in [1, 1.5), ``inf`` with ``p_inf``; the
    communication graph from the agents' positions and ``comm_range``."""
    rng = np.random.default_rng(seed)
    a_cells = rng.integers(0, int(size), (n, 3))
    a_cells[:, 2] = 0
    t_cells = rng.integers(0, int(size), (m, 3))
    t_cells[:, 2] = 0
    speeds = rng.choice([3.0, 5.0], n)
    d = np.linalg.norm(a_cells[:, None, :] - t_cells[None, :, :], axis=-1)
    cost = d / speeds[:, None] * rng.uniform(1.0, 1.5, (n, m)) + 0.1
    cost[rng.random((n, m)) < p_inf] = np.inf
    agents = tuple(AgentView(100 + a, "uav", tuple(int(v) for v in a_cells[a]), float(speeds[a]))
                   for a in range(n))
    tasks = tuple(TaskView(500 + t, "ground", tuple(int(v) for v in t_cells[t]), 0.0)
                  for t in range(m))
    comm = comm_graph(a_cells + 0.5, comm_range)
    return AllocationProblem(time=0.0, agents=agents, tasks=tasks, cost=cost, comm=comm,
                             rng=np.random.default_rng(seed + 1), loss=loss)


def connected_cases(count=150, n_range=(2, 8), m_range=(1, 8), comm_range=12.0, loss=0.0):
    """Random spatial problems whose communication graph is connected (not complete, mostly)."""
    rng = np.random.default_rng(4242)
    found = 0
    seed = 0
    while found < count:
        seed += 1
        n = int(rng.integers(*n_range))
        m = int(rng.integers(*m_range))
        p = spatial_problem(seed, n, m, comm_range=comm_range, loss=loss)
        if components(p.comm)[0] == 1:
            found += 1
            yield seed, p


# ----------------------------------------------------------------------------- brute force


def brute_arrivals(p: AllocationProblem, i: int, path: list[int]) -> list[float]:
    """Arrival times along a path, written out independently of the allocator: first leg the
    cost, later legs straight-line metres / speed, never earlier than the task's own cost."""
    v = p.agents[i].speed
    out, t = [], 0.0
    for q, j in enumerate(path):
        if q == 0:
            t = p.cost[i, j]
        else:
            a, b = np.array(p.tasks[path[q - 1]].cell), np.array(p.tasks[j].cell)
            t = max(t + float(np.linalg.norm(a - b)) * p.cell_size / v, p.cost[i, j])
        out.append(t)
    return out


def brute_score(p, i, path, bundle_size, time_scale=60.0) -> float:
    if bundle_size == 1:
        return -sum(p.cost[i, j] for j in path)
    return sum(np.exp(-t / time_scale) for t in brute_arrivals(p, i, path))


def fixed_point_violations(p: AllocationProblem, res, bundle_size: int) -> list:
    """CBBA's fixed-point conditions, by brute force over every insertion position.

    For every agent, replaying bundle construction against the agreed winning bids must give
    back its bundle, step by step: at each step the task it added has the highest (warped)
    marginal score among the tasks it could win (no other agent's winning bid beats it), the
    recorded bid equals that score, and when its bundle is not full no task is left that it
    would win. In words: no agent would outbid the winner of any task.
    """
    n, m = p.cost.shape
    y, z = res.y[0], res.z[0]
    owner = {j: i for i, b in enumerate(res.bundles) for j in b}
    bad = []
    for i in range(n):
        b, path, last = res.bundles[i], [], np.inf
        for step in range(len(b) + 1):
            best = None
            for j in range(m):
                if j in b[:step] or not np.isfinite(p.cost[i, j]):
                    continue
                base = brute_score(p, i, path, bundle_size)
                c = max(brute_score(p, i, path[:q] + [j] + path[q:], bundle_size)
                        for q in range(len(path) + 1)) - base
                w = min(c, last)
                wins = owner.get(j) == i or bool(better(w, i, y[j], z[j]))
                if wins and (best is None or (w, c, -j) > (best[0], best[1], -best[2])):
                    best = (w, c, j)
            if step == len(b):
                if len(b) < bundle_size and best is not None:
                    bad.append(("agent would outbid a winner", i, best))
                break
            if best is None or best[2] != b[step] or not np.isclose(best[0], y[b[step]]):
                bad.append(("bundle is not the best response", i, step, best, b[step]))
                break
            j = b[step]
            path = max((path[:q] + [j] + path[q:] for q in range(len(path) + 1)),
                       key=lambda pp: brute_score(p, i, pp, bundle_size))
            last = y[j]
        if not bad and path != res.paths[i]:
            bad.append(("path order", i, path, res.paths[i]))
    return bad


def sequential_greedy(cost: np.ndarray) -> dict[int, int]:
    """Centralized sequential greedy: repeatedly the cheapest remaining pair (CBAA's answer)."""
    cost = np.array(cost, dtype=float)
    out = {}
    while np.isfinite(cost).any():
        a, t = np.unravel_index(np.argmin(cost), cost.shape)
        out[int(a)] = int(t)
        cost[a, :] = np.inf
        cost[:, t] = np.inf
    return out


# ----------------------------------------------------------------------------- connected graphs


@pytest.mark.parametrize("bundle_size", [1, 2, 3])
def test_connected_graphs_are_conflict_free_and_assign_every_task(bundle_size):
    for seed, p in connected_cases(120):
        auction = AuctionAllocator(bundle_size=bundle_size)
        a = auction.allocate(p)
        res = auction.last
        pairs = assert_valid(p, a)
        assert res.converged, seed
        assert a.conflicted_tasks() == set() and res.conflicts() == set(), seed
        n, m = p.cost.shape
        in_bundles = [j for b in res.bundles for j in b]
        assert len(in_bundles) == len(set(in_bundles)) == min(n * bundle_size, m), seed
        # one task per vehicle at a time: the first task of each path is handed out
        assert sorted(pairs) == sorted((i, pth[0]) for i, pth in enumerate(res.paths) if pth)
        if bundle_size == 1:
            assert len(pairs) == min(n, m)  # every task assigned when N >= M


def test_complete_graph_every_task_assigned_when_agents_suffice():
    rng = np.random.default_rng(5)
    for seed in range(100):
        m = int(rng.integers(1, 10))
        n = m + int(rng.integers(0, 4))
        p = random_problem(seed, n, m, integer=seed % 2 == 0)  # ties too
        a = AuctionAllocator().allocate(p)
        assert len(assert_valid(p, a)) == m
        assert a.conflicted_tasks() == set()


@pytest.mark.parametrize("bundle_size", [1, 2, 3])
def test_result_is_a_cbba_fixed_point_by_brute_force(bundle_size):
    checked = 0
    for seed, p in connected_cases(60, n_range=(2, 6), m_range=(1, 8)):
        auction = AuctionAllocator(bundle_size=bundle_size)
        auction.allocate(p)
        res = auction.last
        assert (res.z == res.z[0]).all() and (res.y == res.y[0]).all()  # consensus
        assert fixed_point_violations(p, res, bundle_size) == [], seed
        checked += 1
    assert checked == 60


def test_cbaa_matches_sequential_greedy():
    """With bundle size 1 the fixed point is the sequential greedy assignment (Choi et al.)."""
    for seed, p in connected_cases(100):
        auction = AuctionAllocator()
        a = auction.allocate(p)
        assert dict(index_pairs(p, a)) == sequential_greedy(p.cost), seed


def test_brute_force_checker_catches_a_wrong_answer():
    p = make_problem(np.array([[1.0, 5.0], [2.0, 3.0]]))
    auction = AuctionAllocator()
    auction.allocate(p)
    res = auction.last
    assert fixed_point_violations(p, res, 1) == []
    # swap the winners: agent 1 would outbid agent 0 on task 0 ... and the replay says so
    res.bundles, res.paths = [[1], [0]], [[1], [0]]
    res.z[:] = [1, 0]
    res.y[:] = [-2.0, -5.0]
    assert fixed_point_violations(p, res, 1)


def test_line_graph_needs_diameter_rounds():
    """One task, agents on a line, the best bidder at one end: the winning bid must travel the
    whole line, one hop per round, so consensus takes exactly the diameter in rounds; on a
    complete graph, one."""
    for n in (2, 3, 5, 8, 13):
        cost = (10.0 + np.arange(n)[::-1])[:, None]  # agent n-1 is the cheapest
        p = dataclasses.replace(make_problem(cost), comm=line(n))
        auction = AuctionAllocator()
        a = auction.allocate(p)
        assert auction.last.rounds == diameter(p.comm) == n - 1
        assert a.pairs == ((100 + n - 1, 500),)
        assert a.rounds == n - 1 + 1  # plus the claim round
        assert a.messages == (n - 1) * n + 1  # everyone broadcasts each round, one claim
        assert a.hops == (n - 1) + 2
        complete = make_problem(cost)
        auction.allocate(complete)
        assert auction.last.rounds == 1


def test_line_graph_rounds_grow_with_the_diameter():
    """Random costs on lines: never fewer rounds than a bid needs to cross the line when the
    best bidder of the most wanted task sits at an end, never more than CBAA's bound
    min(N, M) * D (Choi et al., Theorem 1), and all conflict-free."""
    for n in (4, 8, 12):
        for seed in range(15):
            p = dataclasses.replace(random_problem(seed, n, n), comm=line(n))
            auction = AuctionAllocator()
            a = auction.allocate(p)
            assert auction.last.converged and not a.conflicted_tasks()
            assert 1 <= auction.last.rounds <= n * (n - 1)


# ----------------------------------------------------------------------------- loss


def test_thirty_percent_loss_still_assigns_every_task_with_more_rounds():
    rounds = {0.0: [], 0.3: []}
    for seed, p in connected_cases(80, n_range=(3, 10), m_range=(1, 10)):
        n, m = p.cost.shape
        for loss in rounds:
            lossy = dataclasses.replace(p, loss=loss, rng=np.random.default_rng(seed))
            auction = AuctionAllocator()
            a = auction.allocate(lossy)
            pairs = assert_valid(lossy, a)
            assert auction.last.converged
            assert a.conflicted_tasks() == set()
            if n >= m:
                assert len(pairs) == m, (seed, loss)
            rounds[loss].append(auction.last.rounds)
    # stated: loss costs rounds (each bid needs more tries to cross a link)
    assert np.mean(rounds[0.3]) > np.mean(rounds[0.0])


def test_loss_is_reproducible_and_draws_only_from_problem_rng():
    p = spatial_problem(7, 8, 8, comm_range=12.0, loss=0.3)
    np.random.seed(0)
    random.seed(0)
    first = AuctionAllocator().allocate(p)
    np.random.seed(1)
    random.seed(1)
    again = AuctionAllocator().allocate(spatial_problem(7, 8, 8, comm_range=12.0, loss=0.3))
    assert first == again
    q = spatial_problem(7, 8, 8, comm_range=12.0, loss=0.0)
    before = q.rng.bit_generator.state
    AuctionAllocator().allocate(q)
    assert q.rng.bit_generator.state == before  # no loss: nothing drawn


# ----------------------------------------------------------------------------- disconnected


def test_disconnected_graph_reports_conflicts_and_the_conflict_rule_settles_them():
    # Agents 0 and 1 cannot talk; both bid for task 0 (agent 1 is cheaper). Both claim it, the
    # arbiter gives it to agent 1, and agent 0 goes on to task 1.
    cost = np.array([[2.0, 4.0], [1.0, 3.0]])
    p = dataclasses.replace(make_problem(cost), comm=np.eye(2, dtype=bool))
    auction = AuctionAllocator()
    a = auction.allocate(p)
    assert auction.last.conflicts() == {0}  # reported by the consensus
    assert a.conflicted_tasks() == {500}  # and in the request log
    assert sorted(a.pairs) == [(100, 501), (101, 500)]
    claim_round = auction.last.rounds
    log = sorted((r.round, r.agent_id, r.task_id, r.won) for r in a.requests)
    assert log == [(claim_round, 100, 500, False), (claim_round, 101, 500, True),
                   (claim_round + 1, 100, 501, True)]


@pytest.mark.parametrize("bundle_size", [1, 2])
def test_range_so_small_nobody_talks_still_gives_valid_allocations(bundle_size):
    rng = np.random.default_rng(8)
    for seed in range(80):
        n, m = (int(x) for x in rng.integers(1, 9, 2))
        p = spatial_problem(seed, n, m, comm_range=0.0, loss=0.3, p_inf=0.2)
        a = AuctionAllocator(bundle_size=bundle_size).allocate(p)
        pairs = assert_valid(p, a)
        assert a.messages >= len(a.requests)
        if bundle_size == 1:  # losers retry until no idle agent has a feasible open task
            busy = {x for x, _ in pairs}
            taken = {t for _, t in pairs}
            for x in set(range(n)) - busy:
                for t in set(range(m)) - taken:
                    assert not np.isfinite(p.cost[x, t])


def test_random_geometric_graphs_some_disconnected_always_valid():
    for seed in range(60):
        p = spatial_problem(seed, 10, 10, comm_range=8.0, loss=0.1)
        a = AuctionAllocator().allocate(p)
        assert len(assert_valid(p, a)) == 10
        if components(p.comm)[0] == 1:
            assert not a.conflicted_tasks()


# ----------------------------------------------------------------------------- accounting


def test_counts_rounds_messages_hops_and_agent_seconds():
    p = random_problem(2, 6, 6)
    auction = AuctionAllocator()
    a = auction.allocate(p)
    res = auction.last
    assert a.rounds == res.rounds + 1  # consensus rounds and one claim round
    assert a.messages == res.rounds * 6 + 6  # broadcasts of every agent, then six claims
    assert a.hops == res.rounds + 2
    assert len(a.agent_seconds) == 6 and all(s >= 0 for s in a.agent_seconds)
    assert sum(r.won for r in a.requests) == len(a.pairs) == 6


def test_mean_cost_hungarian_le_auction_le_random():
    totals = {"hungarian": [], "auction": [], "random": []}
    for seed in range(100):
        p = random_problem(seed, 8, 8)
        for name in totals:
            totals[name].append(total_cost(p, registry.load("allocator", name)().allocate(p)))
    h, a, r = (np.array(totals[k]) for k in ("hungarian", "auction", "random"))
    assert np.all(h <= a + 1e-9)
    assert h.mean() <= a.mean() <= r.mean()


def test_infeasible_pairs_empty_problems_and_lonely_agents():
    cost = np.array([[np.inf, 7.0], [np.inf, np.inf]])
    a = AuctionAllocator().allocate(make_problem(cost))
    assert a.pairs == ((100, 501),)
    for shape in [(0, 0), (0, 2), (2, 0)]:
        assert AuctionAllocator().allocate(make_problem(np.zeros(shape))).pairs == ()
    one = AuctionAllocator(bundle_size=3).allocate(make_problem([[3.0, 1.0, 2.0]]))
    assert one.pairs == ((100, 501),)  # its path starts with the cheapest task


def test_parameters_names_and_registry():
    assert AuctionAllocator.name == "auction" and AuctionAllocator.decentralized
    assert registry.load("allocator", "auction") is AuctionAllocator
    assert make_plugin("allocator", "auction", (("bundle_size", 2),)).bundle_size == 2
    for bad in ({"bundle_size": 0}, {"bundle_size": 1.5}, {"bundle_size": True},
                {"time_scale": 0.0}, {"time_scale": "slow"}, {"bogus": 1}):
        with pytest.raises(TypeError):
            AuctionAllocator(**bad)
    with pytest.raises(PluginError, match="rejected its parameters"):
        make_plugin("allocator", "auction", (("bundle_size", -1),))


# ----------------------------------------------------------------------------- compiled consensus


@pytest.mark.parametrize("bundle_size", [1, 3])
def test_compiled_exchange_equals_the_numpy_reference(bundle_size, monkeypatch):
    """The compiled consensus (allocators._cbba_fast) gives exactly the state, rounds and
    messages of the numpy reference of CBBA's Table 1, on limited-range graphs (connected or
    not), with and without message loss."""
    from allocators import auction

    def run(p, reference):
        if reference:
            monkeypatch.setattr(auction._CBBA, "exchange", auction._CBBA.exchange_reference)
        else:
            monkeypatch.undo()
        alloc = AuctionAllocator(bundle_size=bundle_size)
        a = alloc.allocate(p)
        return alloc.last, a

    rng = np.random.default_rng(7)
    for seed in range(60):
        n, m = int(rng.integers(2, 14)), int(rng.integers(1, 10))
        kw = dict(comm_range=float(rng.choice([5.0, 10.0, 15.0, 100.0])),
                  loss=float(rng.choice([0.0, 0.3])), p_inf=0.1)
        fast_res, fast = run(spatial_problem(seed, n, m, **kw), reference=False)
        ref_res, ref = run(spatial_problem(seed, n, m, **kw), reference=True)
        monkeypatch.undo()
        assert np.array_equal(fast_res.y, ref_res.y) and np.array_equal(fast_res.z, ref_res.z)
        assert fast_res.bundles == ref_res.bundles and fast_res.paths == ref_res.paths
        assert (fast.pairs, fast.rounds, fast.messages, fast.hops, fast.requests) == \
            (ref.pairs, ref.rounds, ref.messages, ref.hops, ref.requests)


def test_one_task_shortcut_equals_the_simulated_auction(monkeypatch):
    """One task on a complete graph without loss (immediate dispatch) is answered without
    simulating the rounds: the same state, pairs, rounds, messages and requests as the
    simulation (ties and infeasible agents included)."""
    from allocators import auction

    rng = np.random.default_rng(5)
    for trial in range(80):
        n = int(rng.integers(1, 30))
        cost = rng.choice([3.0, 5.0, 7.0, np.inf], size=(n, 1))  # ties, some infeasible
        if trial % 10 == 0:
            cost[:] = np.inf
        p = make_problem(cost)
        fast_alloc = AuctionAllocator()
        fast = fast_alloc.allocate(p)
        monkeypatch.setattr(auction._CBBA, "one_task", lambda self: None)
        ref_alloc = AuctionAllocator()
        ref = ref_alloc.allocate(make_problem(cost))
        monkeypatch.undo()
        assert np.array_equal(fast_alloc.last.y, ref_alloc.last.y)
        assert np.array_equal(fast_alloc.last.z, ref_alloc.last.z)
        assert fast_alloc.last.bundles == ref_alloc.last.bundles
        assert (fast.pairs, fast.rounds, fast.messages, fast.hops, fast.requests) == \
            (ref.pairs, ref.rounds, ref.messages, ref.hops, ref.requests)
        if np.isfinite(cost).any():  # the cheapest agent, ties to the lowest index
            assert fast.pairs == ((p.agents[int(np.argmin(cost[:, 0]))].id, p.tasks[0].id),)
