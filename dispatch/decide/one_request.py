"""The one-request decision without the general problem: an immediate decision's usual case.

An allocator that declares :attr:`dispatch.api.contracts.Allocator.one_by_minimum` answers a
problem of one request by the least finite cost of its column, the lowest agent id among equal
ones. For such a decision :func:`decided` gives the answer the allocator would give, checked as
the dispatcher checks it, without building the :class:`AllocationProblem`, asking the allocator
or checking its answer: the column's first minimum (the decision's agents ascend by id).
(``d``, a decision, is the :class:`dispatch.decide.pipeline.Decision` the pipeline built.)
What the hand-out and the recorder read of the problem (its time, sizes and cost) is
:class:`OneProblem`; anything else read of it builds the general problem then.

:data:`GENERAL` (a test switch) forces the general path: the two give the same results.
"""

from __future__ import annotations

import math
import time

from dispatch.api.problem import Allocation, Bid
from dispatch.decide.answers import Checked

#: True: every decision takes the general path (tests compare the two)
GENERAL = False


class OneProblem:
    """What a one-request decision's problem is to the hand-out and the recorder: its
    ``time``, ``cost`` (the decision's column), ``n_agents`` and ``n_tasks``; any other
    attribute is the general :class:`AllocationProblem`'s, built when first read."""

    __slots__ = ("time", "cost", "n_agents", "n_tasks", "_make", "_full")

    def __init__(self, d) -> None:
        self.time = d.now
        self.cost = d.cost
        self.n_agents, self.n_tasks = d.cost.shape
        if d.n_idle is not None:  # the vehicle cut costed fewer (dispatch.decide.nearest)
            self.n_agents = d.n_idle
        self._make, self._full = d.make, None

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        if self._full is None:
            self._full = self._make(self.cost)
        return getattr(self._full, name)


def fits(d) -> bool:
    """Whether :func:`decided` may answer decision ``d``: one request, agents in ascending id
    order (the first minimum is then the lowest id among equal costs), and the switch off."""
    return d.cost.shape[1] == 1 and d.agents.ascending and not GENERAL


def decided(d) -> Checked:
    """The answer of an allocator that decides one request by its cost minimum (see the
    module) to decision ``d``: its request to the agent of least finite cost, the first of
    equal ones, or nothing where no cost is finite; the seconds it took."""
    t0 = time.perf_counter()
    col = d.cost[:, 0]
    a = int(col.argmin())
    c = float(col[a])
    problem = OneProblem(d)
    if not math.isfinite(c):  # (argmin of a nan-free column: inf only where all are)
        allocation = Allocation(pairs=(), rounds=1, requests=(), messages=0, index=())
        return Checked(problem, allocation, time.perf_counter() - t0, {}, [])
    aid, tid = int(d.agents.ids[a]), d.requests[0].id
    allocation = Allocation(pairs=((aid, tid),), rounds=1, requests=(Bid(0, aid, tid, c, True),),
                            messages=0, index=((a, 0),))
    return Checked(problem, allocation, time.perf_counter() - t0, {}, [(a, 0)])
