"""First come, first served: the ride-hailing baseline.

Open requests are taken in release order (ties by task id); each gets the idle vehicle that
reaches its pickup soonest (ties by vehicle id) among those not yet taken in this decision; a
request no remaining vehicle can reach stays open. This is the rule SUMO's taxi device calls
``greedy``, simobility's ``GreedyMatcher`` and most ride-hailing papers "nearest idle vehicle,
first come first served". Centralized and deterministic: it draws nothing from ``problem.rng``.
"""

from __future__ import annotations

import numpy as np

from dispatch.contracts import Allocation, AllocationProblem, Allocator


class FcfsAllocator(Allocator):
    """Requests in release order, each to the soonest-arriving idle vehicle (ties: ids)."""

    name = "fcfs"
    decentralized = False

    def allocate(self, problem: AllocationProblem) -> Allocation:
        return Allocation.centralized(problem, fcfs_pairs(problem))


def fcfs_pairs(problem: AllocationProblem) -> list[tuple[int, int]]:
    """Index pairs ``(agent, task)`` chosen by the rule of the module docstring."""
    cost = problem.cost
    n, m = cost.shape
    if n == 0 or m == 0:
        return []
    # lexsort keys, last one primary: tasks by (release time, id); agents by id among ties
    task_order = np.lexsort(([t.id for t in problem.tasks],
                             [t.released_at for t in problem.tasks]))
    agent_ids = np.array([a.id for a in problem.agents])
    free = np.ones(n, dtype=bool)
    pairs = []
    for t in task_order:
        col = np.where(free, cost[:, t], np.inf)
        best = col.min()
        if not np.isfinite(best):
            continue
        a = int(np.flatnonzero(col == best)[np.argmin(agent_ids[col == best])])
        free[a] = False
        pairs.append((a, int(t)))
        if not free.any():
            break
    return pairs
