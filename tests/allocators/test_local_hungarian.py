"""local_hungarian: each agent solves the assignment over its own view, requests its part."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from allocators.hungarian import optimal_pairs
from allocators.local_hungarian import LocalHungarianAllocator
from dispatch.api.decentralized import WAIT

from .helpers import assert_valid, index_pairs, make_problem, random_problem, total_cost


def _line(n: int) -> np.ndarray:
    return np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)


def _brute_force_min(cost: np.ndarray) -> float:
    n, m = cost.shape
    k = min(n, m)
    best = np.inf
    for rows in itertools.permutations(range(n), k) if n >= m else [None]:
        if rows is None:
            for cols in itertools.permutations(range(m), n):
                best = min(best, sum(cost[i, j] for i, j in enumerate(cols)))
        else:
            best = min(best, sum(cost[i, j] for j, i in enumerate(rows)))
    return best


@pytest.mark.parametrize("view", ["two_hop", "component"])
def test_complete_graph_gives_the_optimal_assignment_in_one_round(view):
    """Every agent solves the same whole problem: brute-force optimal, one round, no
    conflict."""
    for seed in range(30):
        rng = np.random.default_rng(seed)
        n, m = (int(x) for x in rng.integers(1, 6, 2))
        p = random_problem(seed, n, m)
        a = LocalHungarianAllocator(view=view).allocate(p)
        assert len(assert_valid(p, a)) == min(n, m)
        assert total_cost(p, a) == pytest.approx(_brute_force_min(p.cost))
        assert a.rounds == 1 and not a.conflicted_tasks()


def test_decision_ignores_agents_beyond_two_hops():
    """Line 0-1-2-3-4-5: agent 0's request depends on agents 0-2 only; changing agent 2
    can change it (a hand-made case) while agents 3-5 never do."""
    n = 6
    alloc = LocalHungarianAllocator()
    rng = np.random.default_rng(4)

    def request_of_0(cost):
        p = dataclasses.replace(make_problem(cost), comm=_line(n))
        return int(alloc.choose(p, np.arange(n), np.ones(n, bool), 0)[0])

    for _ in range(20):
        base_cost = rng.uniform(1, 20, (n, n))
        base = request_of_0(base_cost)
        # its own answer: the optimal assignment of agents 0-2 over all tasks
        own = dict(optimal_pairs(base_cost[:3]))
        assert base == own[0]
        for far in (3, 4, 5):
            c = base_cost.copy()
            c[far] = rng.uniform(0.1, 30, n)
            assert request_of_0(c) == base
    # agent 2 (second hop) matters: it is cheaper for agent 0's task, so 0 goes elsewhere
    cost = np.full((n, n), 10.0)
    cost[0, 0], cost[0, 1] = 1.0, 2.0
    assert request_of_0(cost) == 0
    cost[2, 0] = 0.1
    assert request_of_0(cost) == 1


def test_component_view_solves_each_component():
    """Two cliques {0, 1, 2} and {3, 4}: with ``view = "component"`` each agent requests its
    part of its own component's optimal assignment."""
    n, m = 5, 5
    comm = np.zeros((n, n), bool)
    comm[:3, :3] = True
    comm[3:, 3:] = True
    rng = np.random.default_rng(0)
    cost = rng.uniform(1, 20, (n, m))
    p = dataclasses.replace(make_problem(cost), comm=comm)
    req = LocalHungarianAllocator(view="component").choose(p, np.arange(n), np.ones(m, bool), 0)
    for group in (np.arange(3), np.arange(3, 5)):
        for a, t in optimal_pairs(cost[group]):
            assert req[group[a]] == t


def test_left_out_agents_wait_then_reject():
    """Three agents, one task: the two its own solution leaves out wait for ``patience``
    rounds, then reject."""
    cost = np.array([[1.0], [2.0], [3.0]])
    p = make_problem(cost)
    alloc = LocalHungarianAllocator(patience=2)
    assert alloc.choose(p, np.arange(3), np.ones(1, bool), 0).tolist() == [0, WAIT, WAIT]
    assert alloc.choose(p, np.arange(3), np.ones(1, bool), 2).tolist() == [0, -1, -1]


def test_partial_graphs_and_loss_still_assign_every_task():
    """No links at all, a line, random graphs, 30 % loss: the answer is valid and, with
    N >= M and every pair feasible, every task is assigned."""
    rng = np.random.default_rng(7)
    for seed in range(60):
        m = int(rng.integers(1, 8))
        n = m + int(rng.integers(0, 3))
        comm = rng.random((n, n)) < rng.choice([0.0, 0.2, 0.5])
        comm = comm | comm.T | np.eye(n, dtype=bool)
        p = dataclasses.replace(random_problem(seed, n, m), comm=comm,
                                loss=float(rng.choice([0.0, 0.3])))
        a = LocalHungarianAllocator(view=str(rng.choice(["two_hop", "component"]))).allocate(p)
        assert len(assert_valid(p, a)) == m
        assert len(index_pairs(p, a)) == m


def test_bad_parameters():
    with pytest.raises(TypeError, match="view"):
        LocalHungarianAllocator(view="all")
    with pytest.raises(TypeError, match="patience"):
        LocalHungarianAllocator(patience=-1)
    assert LocalHungarianAllocator().describe() == {"view": "two_hop"}
