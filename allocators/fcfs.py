"""First come, first served: the ride-hailing baseline.

Open requests are taken in release order (ties by task id); each gets the idle vehicle that
reaches its pickup soonest (ties by vehicle id) among those not yet taken in this decision; a
request no remaining vehicle can reach stays open. This is the rule SUMO's taxi device calls
``greedy``, simobility's ``GreedyMatcher`` and most ride-hailing papers "nearest idle vehicle,
first come first served". Centralized and deterministic: it draws nothing from ``problem.rng``.
"""

from __future__ import annotations

import math

import numpy as np

from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem


class FcfsAllocator(Allocator):
    """Requests in release order, each to the soonest-arriving idle vehicle (ties: ids)."""

    name = "fcfs"
    decentralized = False
    one_by_minimum = True  # one request: the soonest vehicle, ties to the lowest id
    nearest_cut = True  # ... found among the vehicles a lower bound cannot rule out

    def allocate(self, problem: AllocationProblem) -> Allocation:
        return Allocation.centralized(problem, fcfs_pairs(problem))


def fcfs_pairs(problem: AllocationProblem) -> list[tuple[int, int]]:
    """Index pairs ``(agent, task)`` chosen by the rule of the module docstring. Its Python
    loop runs over the tasks; each task's choice is a numpy pass over the agents' column."""
    cost = problem.cost
    n, m = cost.shape
    if n == 0 or m == 0:
        return []
    if m == 1:  # one request (an immediate decision's usual problem): the soonest vehicle
        col = cost[:, 0]
        a = int(col.argmin())  # the first of the minima: the lowest id when ids ascend
        best = float(col[a])
        if not math.isfinite(best):
            return []
        if not (problem.agents.ascending or n < 2):
            agent_ids = problem.agent_ids
            if not bool((agent_ids[1:] > agent_ids[:-1]).all()):
                ties = np.flatnonzero(col == best)
                a = int(ties[np.argmin(agent_ids[ties])])
        return [(a, 0)]
    # lexsort keys, last one primary: tasks by (release time, id); agents by id among ties
    order = np.lexsort((problem.task_ids, [t.released_at for t in problem.tasks])).tolist()
    agent_ids = problem.agent_ids
    ascending = problem.agents.ascending or n < 2 \
        or bool((agent_ids[1:] > agent_ids[:-1]).all())
    taken = np.zeros(n, dtype=bool)
    pairs = []
    for t in order:
        col = cost[:, t]
        if pairs:
            col = np.where(taken, np.inf, col)
        a = int(np.argmin(col))  # the first of the minima: the lowest id when ids ascend
        best = float(col[a])
        if not math.isfinite(best):
            continue
        if not ascending:
            ties = np.flatnonzero(col == best)
            a = int(ties[np.argmin(agent_ids[ties])])
        taken[a] = True
        pairs.append((a, t))
        if len(pairs) == n:
            break
    return pairs
