"""The road planner's paths (field descent for a cached pickup, A* elsewhere) are fastest
paths: their time equals scipy's Dijkstra distance, on Chicago and on a grid, from nodes and
from points part-way along an edge."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from dispatch.api.legs import RoadPoint
from dispatch.api.problem import AgentView, TaskView
from dispatch.space.roads import load_network, manhattan
from planners.road import RoadPlanner


def _path_seconds(net, path) -> float:
    return float(sum(net.edge(a, b)[0] for a, b in zip(path[:-1], path[1:])))


@pytest.fixture(scope="module")
def chicago():
    return load_network("chicago", base=".")


@pytest.mark.parametrize("which", ["grid", "chicago"])
def test_paths_are_fastest_with_and_without_a_cached_field(which, chicago):
    net = manhattan(9, 7, 100.0, 10.0) if which == "grid" else chicago
    rng = np.random.default_rng(1)
    starts = rng.integers(net.n, size=25)
    goals = rng.integers(net.n, size=25)
    truth = dijkstra(net.time, indices=starts)
    planner = RoadPlanner(net)
    for i, (s, g) in enumerate(zip(starts.tolist(), goals.tolist())):
        agent = AgentView(0, "car", s, 10.0)
        free = planner.plan(agent, g)  # no field cached: A*
        planner.costs((agent,), (TaskView(i, "trip", g, 0.0),))  # caches g's field
        walked = planner.plan(agent, g)  # descends the cached field
        for path in (free, walked):
            assert path[0] == s and path[-1] == g
            assert _path_seconds(net, path) == pytest.approx(truth[i, g], abs=1e-6)
        planner.task_closed(i)


def test_a_path_from_part_way_along_an_edge_starts_at_the_edge_end():
    net = manhattan(5, 5, 100.0, 10.0)
    planner = RoadPlanner(net)
    point = RoadPoint(node=7, prev=6, remaining=4.0, remaining_m=40.0)
    path = planner.plan(AgentView(0, "car", point, 10.0), 24)
    assert path[0] == 7 and path[-1] == 24
    cost = planner.costs((AgentView(0, "car", point, 10.0),), (TaskView(0, "trip", 24, 0.0),))
    assert cost[0, 0] == pytest.approx(4.0 + _path_seconds(net, path))
