"""Greedy allocator: every agent asks for its cheapest task, round after round.

In each decision round each deciding agent requests its cheapest open task that it can serve
(ties to the lowest task index). It never rejects while it has such a task, so the rounds go on
until no unassigned agent has a feasible open task left. Conflicts are settled by the shared
rule in :mod:`dispatch.api.decentralized` (the cheaper requester wins).
"""

from __future__ import annotations

import numpy as np

from dispatch.api.decentralized import DecentralizedAllocator
from dispatch.api.problem import AllocationProblem


class GreedyAllocator(DecentralizedAllocator):
    """Each agent requests its cheapest feasible open task (ties: lowest task index)."""

    name = "greedy"

    def choose(
        self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray, round_: int
    ) -> np.ndarray:
        costs = np.where(open_tasks[None, :], problem.cost[agents], np.inf)
        best = np.argmin(costs, axis=1) if costs.shape[1] else np.zeros(len(agents), np.int64)
        has_task = np.isfinite(costs).any(axis=1)
        return np.where(has_task, best, -1)
