"""The paper's decision rounds and conflict rule, shared by every decentralized allocator.

In each round every agent that is still unassigned and still has a feasible open task either
rejects (``-1``; the paper's action 0) or requests one open task. A task requested by several
agents in the same round is a *conflict*: it goes to the requester with the smallest cost (ties
to the lowest agent index), the others stay unassigned and may request again next round.
Rounds repeat until every task is assigned, no agent requests, or ``problem.max_rounds``.

Putting the loop here means every decentralized method is measured the same way: the same
rounds, the same request log, the same conflict counting.
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from dispatch.contracts import Allocation, AllocationProblem, Allocator, Request
from dispatch.errors import AllocationError


class DecentralizedAllocator(Allocator):
    """Base class of allocators whose agents decide per round from their own information.

    Subclasses implement :meth:`choose`; they must not look at other agents' choices of the
    same round (that is what the conflict rule is for).
    """

    decentralized = True

    @abstractmethod
    def choose(
        self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray, round_: int
    ) -> np.ndarray:
        """Each agent's request this round.

        Args:
            problem: the decision (read-only).
            agents: indices (into ``problem.agents``) of the agents deciding this round.
            open_tasks: boolean mask over ``problem.tasks`` of tasks not yet assigned.
            round_: the round number, from 0.

        Returns:
            An int array aligned with ``agents``: a task index that is open and feasible for
            that agent, or ``-1`` to reject.
        """

    def allocate(self, problem: AllocationProblem) -> Allocation:
        return run_rounds(problem, self.choose)


def run_rounds(problem: AllocationProblem, choose) -> Allocation:
    """Run decision rounds with the conflict rule; ``choose`` is :meth:`DecentralizedAllocator.choose`."""
    n, m = problem.cost.shape
    feasible = problem.feasible
    agent_task = np.full(n, -1, dtype=np.int64)
    open_tasks = np.ones(m, dtype=bool)
    requests: list[Request] = []
    rounds = 0
    for r in range(problem.max_rounds):
        deciding = np.flatnonzero((agent_task < 0) & (feasible & open_tasks).any(axis=1))
        if deciding.size == 0:
            break
        choice = np.asarray(choose(problem, deciding, open_tasks.copy(), r), dtype=np.int64)
        if choice.shape != deciding.shape:
            raise AllocationError(
                f"choose() returned {choice.shape[0] if choice.ndim else 'a scalar'} "
                f"requests for {deciding.size} deciding agents"
            )
        rounds = r + 1
        asked = choice >= 0
        if not asked.any():
            break
        for a, t in zip(deciding[asked], choice[asked]):
            if t >= m or not open_tasks[t] or not feasible[a, t]:
                raise AllocationError(
                    f"agent {problem.agents[a].id} requested task index {t}, which is not an "
                    "open task it can serve"
                )
        winners = _resolve(problem.cost, deciding[asked], choice[asked])
        for a, t in zip(deciding[asked], choice[asked]):
            won = winners[t] == a
            requests.append(
                Request(r, problem.agents[a].id, problem.tasks[t].id, float(problem.cost[a, t]), won)
            )
        for t, a in winners.items():
            agent_task[a] = t
            open_tasks[t] = False
        if not open_tasks.any():
            break
    pairs = tuple(
        (problem.agents[a].id, problem.tasks[t].id) for a, t in enumerate(agent_task) if t >= 0
    )
    return Allocation(pairs=pairs, rounds=rounds, requests=tuple(requests), messages=len(requests))


def _resolve(cost: np.ndarray, agents: np.ndarray, tasks: np.ndarray) -> dict[int, int]:
    """The conflict rule: for each requested task, the requester with the smallest cost."""
    winners: dict[int, int] = {}
    for a, t in zip(agents.tolist(), tasks.tolist()):
        best = winners.get(t)
        if best is None or (cost[a, t], a) < (cost[best, t], best):
            winners[t] = a
    return winners
