"""The fleet's array state and the lazy agent sequence a decision hands to plugins: they say
the same as the vehicles and their views, so a plugin that iterates sees what it always saw."""

from __future__ import annotations

import numpy as np
import pytest

from dispatch.api.legs import RoadPoint
from dispatch.api.problem import AgentView, AgentViews, Allocation, AllocationProblem
from dispatch.decide.answers import validate
from dispatch.errors import AllocationError
from dispatch.plan.vehicles import Fleet, Vehicle
from dispatch.space.roads import manhattan


def _fleet():
    vs = [Vehicle(i, "car", 10.0, n) for i, n in zip((5, 2, 9, 7), (3, 0, 3, 11))]
    return Fleet(vs, manhattan(4, 4))


def test_agent_views_behave_as_the_tuple_of_views():
    fleet = _fleet()
    views = fleet.views(fleet.idle_index(), 0.0)
    expected = tuple(v.view(0.0) for v in fleet.vehicles)
    assert len(views) == 4 and tuple(views) == expected and views == expected
    assert views[1:3] == expected[1:3] and views[-1] == expected[-1]
    assert views.ids.tolist() == [2, 5, 7, 9] and views.ascending
    assert views.nodes.tolist() == [0, 3, 11, 3] and not views.remaining.any()
    with pytest.raises(IndexError):
        views[4]


def test_fleet_arrays_follow_the_vehicles():
    fleet = _fleet()
    v = fleet.by_id[7]
    v.failed = True  # out of service: not idle
    fleet.refresh(v)
    assert fleet.idle_index().tolist() == [0, 1, 3]
    v.loc = RoadPoint(node=12, prev=11, remaining=2.5, remaining_m=25.0)
    v.failed = False
    fleet.refresh(v)
    views = fleet.views(fleet.idle_index(), 10.0)
    k = views.ids.tolist().index(7)
    assert views.nodes[k] == 12 and views.remaining[k] == 2.5
    assert views.points.tolist() == [k] and views[k].loc == v.loc
    net = manhattan(5, 5, 100.0, 10.0)
    leg = net.leg(12, [12, 13, 14])
    v.leg, v.leg_start = leg, 10.0
    views = fleet.views(fleet.idle_index(), 15.0)  # 5 s into the 10 s edge 12 -> 13
    assert views.nodes[k] == 13 and views.remaining[k] == pytest.approx(5.0)
    assert views[k].loc == leg.point_at(5.0)


def test_validate_finds_pairs_by_id_without_a_dict_over_the_agents():
    agents = AgentViews.of([AgentView(i, "car", i, 10.0) for i in (30, 10, 20)])
    problem = AllocationProblem(time=0.0, agents=agents, tasks=(), cost=np.zeros((3, 0)),
                                comm=np.broadcast_to(np.True_, (3, 3)),
                                rng=np.random.default_rng(0),
                                agent_pos=np.zeros((3, 3)), task_pos=np.zeros((0, 3)))
    validate(problem, Allocation(pairs=()))
    with pytest.raises(AllocationError, match="unknown agent id 11"):
        validate(problem, Allocation(pairs=((11, 0),)))
    with pytest.raises(AllocationError, match="unknown agent id 'x'"):
        validate(problem, Allocation(pairs=(("x", 0),)))


def test_one_task_cost_column_equals_scipy_and_the_general_path():
    """The road planner's one-task fast path (an immediate decision) gives the numbers of
    scipy's Dijkstra plus the seconds left on an edge, and those of its general path."""
    from scipy.sparse.csgraph import dijkstra

    from dispatch.api.problem import TaskView
    from dispatch.files.hourly import HourlyFactors
    from dispatch.space.congestion import CongestedPlanner
    from planners.road import RoadPlanner

    net = manhattan(5, 5, 100.0, 10.0)
    fleet = _fleet()
    fleet.by_id[7].loc = RoadPoint(node=12, prev=11, remaining=2.5, remaining_m=25.0)
    views = fleet.views(fleet.idle_index(), 0.0)
    nodes = [v.loc.node if isinstance(v.loc, RoadPoint) else v.loc for v in views]
    rem = np.array([v.loc.remaining if isinstance(v.loc, RoadPoint) else 0.0 for v in views])
    for goal in (24, 3, 24):  # a new field, another, then a cached one
        task = TaskView(goal, "ground", goal, 0.0)
        got = RoadPlanner(net).costs(views, (task,))
        want = dijkstra(net.time, indices=nodes)[:, [goal]] + rem[:, None]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        general = RoadPlanner(net).costs(list(views), (task,))  # plain views: general path
        np.testing.assert_array_equal(got, general)
        # congestion reads the remaining-seconds array: the same as from the views
        congested = CongestedPlanner(RoadPlanner(net), HourlyFactors((2.0,) * 24), lambda: 0.0)
        np.testing.assert_allclose(congested.costs(views, (task,)),
                                   rem[:, None] + (want - rem[:, None]) * 2.0, atol=1e-9)
