"""Random allocator: every agent asks for a uniformly random task it can serve.

The paper's lower baseline. In each decision round each deciding agent requests one of its
feasible open tasks, chosen uniformly at random from ``problem.rng`` (the only source of
randomness: the same seed gives the same allocation). It never rejects while it has such a task.
"""

from __future__ import annotations

import numpy as np

from dispatch.api.decentralized import DecentralizedAllocator
from dispatch.api.problem import AllocationProblem


class RandomAllocator(DecentralizedAllocator):
    """Each agent requests a uniformly random feasible open task, drawn from ``problem.rng``."""

    name = "random"

    def choose(
        self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray, round_: int
    ) -> np.ndarray:
        choice = np.full(len(agents), -1, dtype=np.int64)
        options = problem.feasible[agents] & open_tasks[None, :]
        for i, row in enumerate(options):
            tasks = np.flatnonzero(row)
            if tasks.size:
                choice[i] = tasks[problem.rng.integers(tasks.size)]
        return choice
