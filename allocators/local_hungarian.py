"""``local_hungarian``: every agent solves the assignment over what it knows and requests its
own part (the decentralized Hungarian baseline of Ismail et al. 2017, cited by MAGNNET).

In each decision round every deciding agent takes its view, the deciding agents it knows of
(``view = "two_hop"``, default: within two communication hops, whose cost vectors reach it
over the links, as MAGNNET's graph network sees them; ``view = "component"``: its whole
connected component, as if cost vectors were flooded), and the tasks it believes open, solves
that assignment optimally (:func:`allocators.hungarian.optimal_pairs`) and requests the task
its own solution gives it. Different views can give one task to two agents: the shared
conflict rule of :class:`~dispatch.api.decentralized.DecentralizedAllocator` settles it, and the
losers solve again next round with what they learned. An agent its own solution leaves
without a task waits (:data:`~dispatch.api.decentralized.WAIT`) for ``patience`` rounds (default
3), then rejects. On a complete graph every agent solves the same problem: the answer is the
optimal assignment in one round, conflict-free.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from allocators.hungarian import optimal_pairs
from dispatch.api.comms import components
from dispatch.api.decentralized import WAIT, DecentralizedAllocator
from dispatch.api.problem import AllocationProblem

VIEWS = ("two_hop", "component")


class LocalHungarianAllocator(DecentralizedAllocator):
    """Each agent solves the assignment over its two-hop view and requests its own part.

    The decentralized Hungarian baseline of Ismail et al. 2017; conflicts settled by the shared
    rule (see the module doc)."""

    name = "local_hungarian"

    def __init__(self, view: str = "two_hop", patience: int = 3, value: str | None = None,
                 value_weight: float | None = None) -> None:
        """``value`` / ``value_weight``: a learned value of where a pair leaves the vehicle, as
        ``hungarian``'s (:class:`learning.value.ValueOption`): every agent solves its view on
        the value-adjusted costs (a pair's adjustment depends on its own agent only, so each
        agent computes its own row); requests record the travel times."""
        self.value = None
        if value is not None:
            from learning.value import ValueOption

            self.value = ValueOption(value, value_weight)
            self.value_function = self.value.value
        if view not in VIEWS:
            raise TypeError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
        if isinstance(patience, bool) or not isinstance(patience, int) or patience < 0:
            raise TypeError(f"patience must be a non-negative integer, got {patience!r}")
        self.view, self.patience = view, patience

    def describe(self) -> dict[str, str]:
        out = {"view": self.view}
        if self.value is not None:
            out.update(value=Path(self.value.path).name, value_weight=f"{self.value.weight:g}")
        return out

    def allocate(self, problem: AllocationProblem):
        """The decentralized decision (see the module doc), on the value-adjusted costs where
        there is a ``value`` (the requests then record the travel times)."""
        if self.value is None:
            return super().allocate(problem)
        from dataclasses import replace

        from learning.value import travel_costs

        adjusted = replace(problem, cost=np.ascontiguousarray(self.value.costs(problem)))
        return travel_costs(super().allocate(adjusted), problem)

    def members(self, comm: np.ndarray, i: int, deciding: np.ndarray,
                labels: np.ndarray | None) -> np.ndarray:
        """The deciding agents agent ``i`` knows of (its view, ``i`` included)."""
        if labels is not None:
            return np.flatnonzero((labels == labels[i]) & deciding)
        one = comm[i].copy()
        one[i] = True
        return np.flatnonzero((one | comm[one].any(axis=0)) & deciding)

    def choose(self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray,
               round_: int) -> np.ndarray:
        comm = problem.comm
        deciding = np.zeros(problem.n_agents, bool)
        deciding[agents] = True
        # everyone hears everyone (a city's fleet without a range): one view, no N x N work
        everyone = bool(comm[agents].all())
        labels = components(comm)[1] if self.view == "component" and not everyone else None
        tasks = np.flatnonzero(open_tasks)
        out = np.full(len(agents), -1, np.int64)
        solved: dict[bytes, dict[int, int]] = {}  # agents of one view compute one answer
        for k, i in enumerate(agents):
            members = (np.flatnonzero(deciding) if everyone
                       else self.members(comm, int(i), deciding, labels))
            key = members.tobytes()
            if key not in solved:
                pairs = optimal_pairs(problem.cost[np.ix_(members, tasks)])
                solved[key] = {int(members[a]): int(tasks[t]) for a, t in pairs}
            mine = solved[key].get(int(i))
            if mine is not None:
                out[k] = mine
            elif round_ < self.patience and problem.feasible[i, tasks].any():
                out[k] = WAIT
        return out
