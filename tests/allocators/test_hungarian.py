"""HungarianAllocator: maximum cardinality, then minimum cost; checked by brute force and on
Beasley's OR-Library assignment instances."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from allocators.hungarian import HungarianAllocator

from .helpers import assert_valid, make_problem, random_cost, total_cost
from tests.conftest import missing_data

ORLIB = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "orlib_assign"


def brute_force(cost: np.ndarray) -> tuple[int, float]:
    """(most pairs, least total cost among those) over every partial matching of finite pairs."""
    n, m = cost.shape
    for k in range(min(n, m), 0, -1):
        best = np.inf
        for agents in itertools.combinations(range(n), k):
            for tasks in itertools.permutations(range(m), k):
                total = sum(cost[a, t] for a, t in zip(agents, tasks))
                best = min(best, total)
        if np.isfinite(best):
            return k, float(best)
    return 0, 0.0


def random_instances(count: int = 400):
    rng = np.random.default_rng(12345)
    for _ in range(count):
        n, m = (int(x) for x in rng.integers(1, 7, 2))
        p_inf = float(rng.choice([0.0, 0.2, 0.5, 0.8]))
        cost = random_cost(rng, n, m, p_inf, integer=bool(rng.random() < 0.5))
        if rng.random() < 0.3:  # a row fully infeasible
            cost[rng.integers(n), :] = np.inf
        if rng.random() < 0.3:  # a column fully infeasible
            cost[:, rng.integers(m)] = np.inf
        yield cost


def deficient_instances(count: int = 150):
    """Matrices where no assignment covers the smaller side, although every row and column has
    a finite entry (Hall's condition broken: r of the ``small`` rows reach fewer than r
    columns; the other rows reach all, so no column is dead), so the allocator cannot use
    scipy's exact ``inf`` handling and must take its penalty path."""
    rng = np.random.default_rng(777)
    for _ in range(count):
        small, large = sorted(int(x) for x in rng.integers(3, 7, 2))
        cost = random_cost(rng, small, large, integer=bool(rng.random() < 0.5))
        r = int(rng.integers(2, small))
        members = rng.choice(small, size=r, replace=False)
        reach = rng.choice(large, size=int(rng.integers(1, r)), replace=False)
        cost[np.ix_(members, np.setdiff1d(np.arange(large), reach))] = np.inf
        yield cost.T.copy() if rng.random() < 0.5 else cost


def test_equals_brute_force_on_small_random_matrices():
    shapes = set()
    for cost in random_instances():
        shapes.add((cost.shape[0] > cost.shape[1]) - (cost.shape[0] < cost.shape[1]))
        problem = make_problem(cost)
        allocation = HungarianAllocator().allocate(problem)
        pairs = assert_valid(problem, allocation)
        count, best = brute_force(cost)
        assert len(pairs) == count, cost
        assert total_cost(problem, allocation) == pytest.approx(best, abs=1e-9), cost
    assert shapes == {-1, 0, 1}  # tall, square and wide matrices were all covered


def test_equals_brute_force_when_the_smaller_side_cannot_be_covered():
    for cost in deficient_instances():
        problem = make_problem(cost)
        allocation = HungarianAllocator().allocate(problem)
        pairs = assert_valid(problem, allocation)
        count, best = brute_force(cost)
        assert count < min(cost.shape)  # the instance really is deficient
        assert len(pairs) == count, cost
        assert total_cost(problem, allocation) == pytest.approx(best, abs=1e-9), cost


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_penalty_keeps_precision_across_cost_scales(scale):
    """The inf penalty scales with the data: tiny and huge costs still give the optimum."""
    rng = np.random.default_rng(7)
    for _ in range(60):
        n, m = (int(x) for x in rng.integers(2, 6, 2))
        cost = random_cost(rng, n, m, p_inf=0.5) * scale + 1000 * scale
        problem = make_problem(cost)
        allocation = HungarianAllocator().allocate(problem)
        count, best = brute_force(cost)
        assert len(assert_valid(problem, allocation)) == count
        assert total_cost(problem, allocation) == pytest.approx(best, rel=1e-12, abs=0)


def test_prefers_serving_more_tasks_over_lower_cost():
    # One pair of cost 1 blocks two pairs of cost 100: the two must win.
    cost = np.array([[1.0, 100.0], [100.0, np.inf]])
    problem = make_problem(cost)
    allocation = HungarianAllocator().allocate(problem)
    assert sorted(allocation.pairs) == [(100, 501), (101, 500)]


@pytest.mark.parametrize(
    "cost",
    [np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((3, 0)), np.full((3, 2), np.inf)],
    ids=["0x0", "0x3", "3x0", "all-inf"],
)
def test_empty_problems_give_empty_allocation(cost):
    allocation = HungarianAllocator().allocate(make_problem(cost))
    assert allocation.pairs == ()
    assert allocation.requests == ()


def test_answer_uses_ids_and_logs_round_zero_requests():
    cost = np.array([[3.0, 1.0, np.inf], [2.0, 5.0, 4.0]])
    problem = make_problem(cost)
    allocation = HungarianAllocator().allocate(problem)
    assert sorted(allocation.pairs) == [(100, 501), (101, 500)]
    assert allocation.rounds == 1 and allocation.messages == 0
    assert all(r.round == 0 and r.won for r in allocation.requests)
    assert sorted((r.agent_id, r.task_id, r.cost) for r in allocation.requests) == [
        (100, 501, 1.0),
        (101, 500, 2.0),
    ]
    assert allocation.conflicted_tasks() == set()
    assert HungarianAllocator.name == "hungarian" and not HungarianAllocator.decentralized


def _read_dense(path: Path) -> np.ndarray:
    tokens = path.read_text().split()
    n = int(tokens[0])
    assert len(tokens) == 1 + n * n, f"{path.name}: expected {n * n} costs"
    return np.array(tokens[1:], dtype=float).reshape(n, n)


def _read_sparse(path: Path) -> np.ndarray:
    tokens = path.read_text().split()
    n = int(tokens[0])
    triples = np.array(tokens[1:], dtype=float).reshape(-1, 3)
    cost = np.full((n, n), np.inf)
    cost[triples[:, 0].astype(int) - 1, triples[:, 1].astype(int) - 1] = triples[:, 2]
    return cost


def _optimal_values() -> dict[str, float]:
    text = (ORLIB / "assignopt.txt").read_text()
    return {name: float(v) for name, v in re.findall(r"^\s*(assign\w+)\s+([\d.]+)", text, re.M)}


ORLIB_NAMES = ["assign100", "assign200", "assign300", "assign400", "assignp800"]


@pytest.mark.parametrize("name", ORLIB_NAMES)
def test_reproduces_orlib_optimum(name):
    if not (ORLIB / "assignopt.txt").exists():
        pytest.skip(missing_data(ORLIB, "the OR-Library assignment problems"))
    optimum = _optimal_values()
    assert set(ORLIB_NAMES) <= set(optimum), f"assignopt.txt lists {sorted(optimum)}"
    path = ORLIB / f"{name}.txt"
    cost = _read_sparse(path) if name.startswith("assignp") else _read_dense(path)
    problem = make_problem(cost)
    allocation = HungarianAllocator().allocate(problem)
    pairs = assert_valid(problem, allocation)
    assert len(pairs) == cost.shape[0]
    assert total_cost(problem, allocation) == optimum[name]


def test_one_task_takes_the_row_scipys_solve_takes():
    """A one-column problem (an immediate decision's) takes the first cheapest finite row,
    the pair scipy's solve of the same column gives, ties, ``inf`` and ``nan`` included."""
    from scipy.optimize import linear_sum_assignment

    from allocators.hungarian import optimal_pairs

    rng = np.random.default_rng(7)
    for _ in range(3000):
        n = int(rng.integers(1, 10))
        cost = rng.integers(0, 3, (n, 1)).astype(float)  # many ties
        cost[rng.random(n) < 0.3] = np.inf
        if rng.random() < 0.1:
            cost[:] = np.inf
        if rng.random() < 0.1:
            cost[int(rng.integers(n))] = np.nan
        ok = np.isfinite(cost[:, 0])
        want = []
        if ok.any():  # scipy on the finite rows, as the general path solves it
            rows = np.flatnonzero(ok)
            r, c = linear_sum_assignment(cost[rows])
            want = [(int(rows[r[0]]), int(c[0]))]
        assert optimal_pairs(cost) == want, cost.ravel()
