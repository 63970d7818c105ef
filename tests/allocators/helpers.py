"""Random allocation problems for allocator tests."""

from __future__ import annotations

import numpy as np

from dispatch.api.problem import AgentView, AllocationProblem, TaskView


def make_problem(cost, seed: int = 0, max_rounds: int = 1000) -> AllocationProblem:
    """A problem around a given ``(N, M)`` cost matrix, with dummy agents and tasks.

    Agent ids are ``100 + index`` and task ids ``500 + index``, so that a mix-up of ids and
    indices shows in the answer.
    """
    cost = np.array(cost, dtype=float).reshape(np.shape(cost))
    n, m = cost.shape
    agents = tuple(
        AgentView(id=100 + a, kind="uav" if a % 2 else "ugv", loc=(a, 0, 0), speed=3.0)
        for a in range(n)
    )
    tasks = tuple(
        TaskView(id=500 + t, kind="ground", loc=(t, 1, 0), released_at=0.0) for t in range(m)
    )
    return AllocationProblem(
        time=0.0,
        agents=agents,
        tasks=tasks,
        cost=cost,
        comm=np.ones((n, n), dtype=bool),
        rng=np.random.default_rng(seed),
        max_rounds=max_rounds,
    )


def random_cost(
    rng: np.random.Generator, n: int, m: int, p_inf: float = 0.0, integer: bool = False
) -> np.ndarray:
    """An ``(n, m)`` cost matrix: uniform in [1, 20) (or integers 1..5, for ties), ``inf``
    with probability ``p_inf``."""
    cost = rng.integers(1, 6, (n, m)).astype(float) if integer else rng.uniform(1.0, 20.0, (n, m))
    cost[rng.random((n, m)) < p_inf] = np.inf
    return cost


def random_problem(
    seed: int, n: int, m: int, p_inf: float = 0.0, integer: bool = False
) -> AllocationProblem:
    """A random problem whose cost matrix and ``rng`` both come from ``seed``."""
    return make_problem(random_cost(np.random.default_rng(seed), n, m, p_inf, integer), seed)


def index_pairs(problem: AllocationProblem, allocation) -> list[tuple[int, int]]:
    """The answer's pairs as ``(agent_index, task_index)``, checking every id is known."""
    a_index = {a.id: i for i, a in enumerate(problem.agents)}
    t_index = {t.id: j for j, t in enumerate(problem.tasks)}
    return [(a_index[a], t_index[t]) for a, t in allocation.pairs]


def assert_valid(problem: AllocationProblem, allocation) -> list[tuple[int, int]]:
    """Check the answer: known ids, no agent or task twice, every pair finite; return indices."""
    pairs = index_pairs(problem, allocation)
    agents = [a for a, _ in pairs]
    tasks = [t for _, t in pairs]
    assert len(set(agents)) == len(agents), f"an agent got two tasks: {allocation.pairs}"
    assert len(set(tasks)) == len(tasks), f"a task went to two agents: {allocation.pairs}"
    for a, t in pairs:
        assert np.isfinite(problem.cost[a, t]), f"infeasible pair {(a, t)} chosen"
    return pairs


def total_cost(problem: AllocationProblem, allocation) -> float:
    return float(sum(problem.cost[a, t] for a, t in index_pairs(problem, allocation)))
