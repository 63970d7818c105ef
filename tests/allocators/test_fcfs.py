"""fcfs: requests in release order, each to the soonest-arriving free vehicle (ties by id),
checked against a plain re-statement of the rule over random problems with ties and inf."""

from __future__ import annotations

import math

import numpy as np
import pytest

from allocators.fcfs import FcfsAllocator
from dispatch.api.problem import AgentView, AllocationProblem, TaskView
from dispatch.decide.answers import validate


def problem(cost, released, agent_ids=None) -> AllocationProblem:
    n, m = cost.shape
    agent_ids = agent_ids if agent_ids is not None else list(range(100, 100 + n))
    agents = tuple(AgentView(i, "car", (0, 0, 0), 10.0) for i in agent_ids)
    tasks = tuple(TaskView(500 + t, "trip", (0, 0, 0), float(released[t])) for t in range(m))
    return AllocationProblem(time=0.0, agents=agents, tasks=tasks, cost=cost,
                             comm=np.ones((n, n), bool), rng=np.random.default_rng(0))


def reference(p: AllocationProblem) -> set[tuple[int, int]]:
    """The rule, written the slow obvious way on ids."""
    taken, out = set(), set()
    for j in sorted(range(p.n_tasks), key=lambda j: (p.tasks[j].released_at, p.tasks[j].id)):
        options = [(p.cost[i, j], p.agents[i].id) for i in range(p.n_agents)
                   if p.agents[i].id not in taken and math.isfinite(p.cost[i, j])]
        if options:
            _, aid = min(options)
            taken.add(aid)
            out.add((aid, p.tasks[j].id))
    return out


@pytest.mark.parametrize("seed", range(40))
def test_fcfs_follows_the_rule(seed):
    rng = np.random.default_rng(seed)
    n, m = rng.integers(1, 8, size=2)
    cost = rng.integers(1, 5, size=(n, m)).astype(float)  # small integers: many ties
    cost[rng.random((n, m)) < 0.2] = np.inf
    released = rng.integers(0, 3, size=m).astype(float)  # ties in release time too
    ids = list(rng.permutation(np.arange(10, 10 + n)))  # ids not in index order
    p = problem(cost, released, ids)
    alloc = FcfsAllocator().allocate(p)
    validate(p, alloc)
    assert set(alloc.pairs) == reference(p)


def test_earlier_request_wins_the_nearest_vehicle_even_if_a_later_one_is_closer():
    cost = np.array([[5.0, 1.0], [9.0, 9.0]])
    p = problem(cost, released=[0.0, 1.0])
    assert set(FcfsAllocator().allocate(p).pairs) == {(100, 500), (101, 501)}


def test_unreachable_request_is_skipped_not_assigned():
    cost = np.array([[np.inf, 2.0]])
    p = problem(cost, released=[0.0, 1.0])
    assert FcfsAllocator().allocate(p).pairs == ((100, 501),)
