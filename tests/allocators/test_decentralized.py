"""Greedy and random allocators, run through the shared decision rounds and conflict rule."""

from __future__ import annotations

import random

import numpy as np
import pytest

from allocators.greedy import GreedyAllocator
from allocators.hungarian import HungarianAllocator
from allocators.randomized import RandomAllocator
from dispatch.api.decentralized import DecentralizedAllocator
from dispatch.errors import AllocationError

from .helpers import assert_valid, index_pairs, make_problem, random_problem, total_cost

DECENTRALIZED = [GreedyAllocator, RandomAllocator]


def _shapes():
    rng = np.random.default_rng(99)
    for seed in range(150):
        n, m = (int(x) for x in rng.integers(1, 9, 2))
        yield seed, n, m, float(rng.choice([0.0, 0.3, 0.7]))


@pytest.mark.parametrize("cls", DECENTRALIZED)
def test_answers_are_valid_and_maximal(cls):
    """No task or agent twice, only finite pairs, and no idle agent left with a feasible open
    task (neither method rejects while it has one, so the rounds run until then)."""
    for seed, n, m, p_inf in _shapes():
        problem = random_problem(seed, n, m, p_inf, integer=seed % 2 == 0)
        allocation = cls().allocate(problem)
        pairs = assert_valid(problem, allocation)
        busy_agents = {a for a, _ in pairs}
        taken = {t for _, t in pairs}
        for a in set(range(n)) - busy_agents:
            for t in set(range(m)) - taken:
                assert not np.isfinite(problem.cost[a, t]), (seed, a, t)
        assert allocation.messages == len(allocation.requests)
        assert sum(r.won for r in allocation.requests) == len(pairs)


@pytest.mark.parametrize("cls", DECENTRALIZED)
def test_every_task_assigned_when_agents_suffice(cls):
    """N >= M and every agent can serve every task: the rounds go on until all are assigned."""
    rng = np.random.default_rng(3)
    for seed in range(100):
        m = int(rng.integers(1, 9))
        n = m + int(rng.integers(0, 4))
        problem = random_problem(seed, n, m, integer=seed % 2 == 0)
        allocation = cls().allocate(problem)
        assert len(assert_valid(problem, allocation)) == m
        assert allocation.rounds <= m  # each round settles at least one task


def test_with_infeasible_pairs_rounds_give_a_maximal_not_maximum_matching():
    """A known limit of decentralized rounds (shared with the paper's method): agent 0 wins the
    task that agent 1 alone could serve, and the task only agent 0 wanted stays open, although
    Hungarian serves both. Every task was feasible for someone; not every task is assigned."""
    cost = np.array([[1.0, 2.0], [1.5, np.inf]])
    problem = make_problem(cost)
    allocation = GreedyAllocator().allocate(problem)
    assert allocation.pairs == ((100, 500),)
    assert len(HungarianAllocator().allocate(problem).pairs) == 2


def test_conflict_goes_to_cheaper_requester_and_loser_retries():
    # Both agents' cheapest task is task 0; agent 0 asks it for less and wins.
    cost = np.array([[1.0, 5.0], [2.0, 3.0]])
    problem = make_problem(cost)
    allocation = GreedyAllocator().allocate(problem)
    assert sorted(allocation.pairs) == [(100, 500), (101, 501)]
    assert allocation.rounds == 2
    log = [(r.round, r.agent_id, r.task_id, r.cost, r.won) for r in allocation.requests]
    assert sorted(log) == [
        (0, 100, 500, 1.0, True),
        (0, 101, 500, 2.0, False),
        (1, 101, 501, 3.0, True),
    ]
    assert allocation.conflicted_tasks() == {500}
    assert allocation.messages == 3


def test_conflict_tie_goes_to_lowest_agent_index():
    cost = np.array([[2.0, 9.0], [2.0, 4.0]])
    allocation = GreedyAllocator().allocate(make_problem(cost))
    assert sorted(allocation.pairs) == [(100, 500), (101, 501)]
    assert allocation.conflicted_tasks() == {500}


def test_greedy_matches_hand_computed_answer():
    cost = np.array(
        [
            [4.0, 1.0, 3.0],
            [2.0, 0.0, 5.0],
            [3.0, 2.0, 2.0],  # tie between tasks 1 and 2: asks for task 1
        ]
    )
    # Round 0: all three ask for task 1; agent 1 (cost 0) wins.
    # Round 1: agents 0 and 2 ask for task 2 (3 vs 2); agent 2 wins.
    # Round 2: agent 0 takes task 0. Total 4 + 0 + 2 = 6 (Hungarian finds 5).
    problem = make_problem(cost)
    allocation = GreedyAllocator().allocate(problem)
    assert sorted(index_pairs(problem, allocation)) == [(0, 0), (1, 1), (2, 2)]
    assert allocation.rounds == 3
    assert [(r.round, r.agent_id, r.task_id, r.won) for r in allocation.requests] == [
        (0, 100, 501, False),
        (0, 101, 501, True),
        (0, 102, 501, False),
        (1, 100, 502, False),
        (1, 102, 502, True),
        (2, 100, 500, True),
    ]
    assert allocation.conflicted_tasks() == {501, 502}
    assert total_cost(problem, allocation) == 6.0
    assert total_cost(problem, HungarianAllocator().allocate(problem)) == 5.0


def test_greedy_skips_infeasible_and_has_no_agents_or_tasks_to_decide():
    cost = np.array([[np.inf, 7.0], [np.inf, np.inf]])
    allocation = GreedyAllocator().allocate(make_problem(cost))
    assert allocation.pairs == ((100, 501),)
    for shape in [(0, 0), (0, 2), (2, 0)]:
        assert GreedyAllocator().allocate(make_problem(np.zeros(shape))).pairs == ()
        assert RandomAllocator().allocate(make_problem(np.zeros(shape))).pairs == ()


def test_random_same_seed_same_allocation_and_seeds_differ():
    cost = np.random.default_rng(0).uniform(1, 10, (6, 6))
    first = RandomAllocator().allocate(make_problem(cost, seed=42))
    again = RandomAllocator().allocate(make_problem(cost, seed=42))
    assert first == again
    others = {RandomAllocator().allocate(make_problem(cost, seed=s)).pairs for s in range(20)}
    assert len(others) > 1


def test_random_draws_only_from_problem_rng():
    cost = np.random.default_rng(0).uniform(1, 10, (6, 6))
    np.random.seed(0)
    first = RandomAllocator().allocate(make_problem(cost, seed=5))
    np.random.seed(1)
    random.seed(1)
    second = RandomAllocator().allocate(make_problem(cost, seed=5))
    assert first == second
    problem = make_problem(cost, seed=5)
    before = problem.rng.bit_generator.state
    RandomAllocator().allocate(problem)
    assert problem.rng.bit_generator.state != before  # it did draw from problem.rng


def test_random_choice_is_uniform_over_feasible_open_tasks():
    # One agent, three feasible tasks of different cost and one infeasible: each feasible task
    # about a third of the time, whatever its cost.
    cost = np.array([[1.0, np.inf, 50.0, 9.0]])
    counts = np.zeros(4)
    for seed in range(3000):
        problem = make_problem(cost, seed=seed)
        [(_, t)] = index_pairs(problem, RandomAllocator().allocate(problem))
        counts[t] += 1
    assert counts[1] == 0
    assert np.all(np.abs(counts[[0, 2, 3]] / 3000 - 1 / 3) < 0.04)


class _AlwaysFirstTask(DecentralizedAllocator):
    """Broken on purpose: asks for task 0 whether or not it is open or feasible."""

    name = "bad"

    def choose(self, problem, agents, open_tasks, round_):
        return np.zeros(len(agents), dtype=np.int64)


def test_requesting_a_closed_task_raises():
    # Round 0: both ask task 0, agent 0 wins. Round 1: agent 1 asks the now closed task 0.
    problem = make_problem(np.array([[1.0, 2.0], [3.0, 4.0]]))
    with pytest.raises(AllocationError, match="not an open task"):
        _AlwaysFirstTask().allocate(problem)


def test_requesting_an_infeasible_task_raises():
    problem = make_problem(np.array([[np.inf, 2.0]]))
    with pytest.raises(AllocationError, match="not an open task"):
        _AlwaysFirstTask().allocate(problem)


def test_mean_cost_hungarian_le_greedy_le_random():
    totals = {"hungarian": [], "greedy": [], "random": []}
    rng = np.random.default_rng(2024)
    for seed in range(200):
        n = int(rng.integers(2, 10))
        m = int(rng.integers(2, 10))
        problem = random_problem(seed, n, m)
        for cls in (HungarianAllocator, GreedyAllocator, RandomAllocator):
            allocation = cls().allocate(problem)
            assert len(allocation.pairs) == min(n, m)
            totals[cls.name].append(total_cost(problem, allocation))
    hungarian, greedy, random_ = (np.array(totals[k]) for k in ("hungarian", "greedy", "random"))
    assert np.all(hungarian <= greedy + 1e-9)
    assert np.all(hungarian <= random_ + 1e-9)
    assert hungarian.mean() <= greedy.mean() <= random_.mean()


def test_names_and_flags():
    assert GreedyAllocator.name == "greedy" and GreedyAllocator.decentralized
    assert RandomAllocator.name == "random" and RandomAllocator.decentralized
    with pytest.raises(TypeError):
        GreedyAllocator(bogus=1)


@pytest.mark.parametrize("cls", DECENTRALIZED)
def test_complete_graph_shortcut_gives_the_general_delivery_answer(cls, monkeypatch):
    """Everyone hearing everyone without loss takes a shortcut (one OR over the senders per
    round, no relay matrix); it must give exactly what the general broadcast delivery gives:
    pairs, request log, rounds, messages and hops."""
    from dispatch.api import decentralized
    def answers():
        out = []
        for seed, n, m, p_inf in _shapes():
            a = cls().allocate(random_problem(seed, n, m, p_inf, integer=seed % 2 == 0))
            out.append((a.pairs, a.requests, a.rounds, a.messages, a.hops))
        return out

    fast = answers()
    monkeypatch.setattr(decentralized, "_everyone_hears", lambda problem: False)
    general = answers()
    assert fast == general
    assert sum(len(f[1]) for f in fast) > 500  # the log is not empty: requests were compared
