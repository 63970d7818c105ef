"""The ``rstar`` planner (R*, randomized A*): legal paths within ``w`` x optimal, seeded.

What the implementation guarantees (see :mod:`planners.rstar`): with ``enforce_bound`` (the
default) every returned path is legal and its length is at most ``w`` times the optimum, and
equal to the optimum for ``w = 1``; unreachable pairs cost ``inf``. The optimum comes from
:func:`planners.graph.distance_field` (Dijkstra).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dispatch.api import registry
from dispatch.api.motion import check_path, path_length
from dispatch.api.problem import AgentView, TaskView
from dispatch.api.voxels import Grid
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.world import World, build_world
from planners.graph import distance_field
from planners.rstar import RStarPlanner

W = (1.0, 1.2, 1.5, 2.5)


def random_world(seed: int, shape=(14, 12, 6), blocked=0.25) -> World:
    """Scattered blocked cells: narrow passages and unreachable pockets."""
    rng = np.random.default_rng(seed)
    occ = rng.random(shape) < blocked
    return World(size=tuple(float(s) for s in shape), grid=Grid(occ, 1.0), boxes=())


def box_world(seed: int, shape=(24, 20, 10)) -> World:
    rng = np.random.default_rng(seed)
    return build_world(tuple(float(s) for s in shape), 1.0, 6, (2.0, 2.0, 2.0),
                       (6.0, 6.0, 10.0), rng)


WORLDS = [("random", s) for s in (0, 1, 2)] + [("boxes", s) for s in (0, 1)]


def make_world(kind: str, seed: int) -> World:
    return random_world(seed) if kind == "random" else box_world(seed)


def pairs(world: World, seed: int, count: int, flies: bool):
    rng = np.random.default_rng(500 + seed)
    free = world.grid.free_cells()
    if not flies:
        free = free[free[:, 2] == 0]
    for _ in range(count):
        a, b = free[rng.integers(len(free))], free[rng.integers(len(free))]
        yield tuple(int(v) for v in a), tuple(int(v) for v in b)


def optimum(world: World, start, goal, flies: bool) -> float:
    f = distance_field(world.grid, goal, flies)
    return float(f[start] if flies else f[start[:2]])


@pytest.mark.parametrize("kind,seed", WORLDS)
@pytest.mark.parametrize("w", W)
def test_paths_are_legal_and_within_w_of_optimal(kind, seed, w):
    world = make_world(kind, seed)
    planner = RStarPlanner(world, w=w, delta=4, k=6, local_expansions=60, seed=seed)
    for flies in (True, False):
        for start, goal in pairs(world, seed, 12, flies):
            agent = AgentView(0, "uav" if flies else "ugv", start, 5.0 if flies else 3.0)
            opt = optimum(world, start, goal, flies)
            path = planner.plan(agent, goal)
            if math.isinf(opt):
                assert path is None
                continue
            assert path is not None
            check_path(world.grid, path, flies)
            assert path[0] == start and path[-1] == goal
            length = path_length(path) * world.cell
            assert opt - 1e-9 <= length <= w * opt + 1e-9, (start, goal, length, opt)
            if w == 1.0:
                assert length == pytest.approx(opt, abs=1e-9)
    extra = planner.stats.extra
    assert extra["searches"] > 0 and extra["high_expansions"] > 0


def test_costs_match_paths_and_the_bound():
    world = box_world(3)
    rng = np.random.default_rng(3)
    free = world.grid.free_cells()
    ground = free[free[:, 2] == 0]
    agents = tuple(AgentView(i, "uav" if i % 2 == 0 else "ugv",
                             tuple(int(v) for v in (free if i % 2 == 0 else ground)[
                                 rng.integers(len(free) if i % 2 == 0 else len(ground))]),
                             5.0 if i % 2 == 0 else 3.0) for i in range(6))
    tasks = tuple(TaskView(j, "ground" if j % 2 == 0 else "air",
                           tuple(int(v) for v in (ground if j % 2 == 0 else free[free[:, 2] > 0])[
                               rng.integers(len(ground) if j % 2 == 0
                                            else int((free[:, 2] > 0).sum()))]), 0.0)
                  for j in range(5))
    planner = RStarPlanner(world, w=1.5, seed=1)
    cost = planner.costs(agents, tasks)
    for a, agent in enumerate(agents):
        for t, task in enumerate(tasks):
            if not agent.flies and task.kind == "air":
                assert math.isinf(cost[a, t])  # a UGV cannot serve an air task
                assert planner.plan(agent, task.cell) is None
                continue
            opt = optimum(world, agent.cell, task.cell, agent.flies)
            metres = cost[a, t] * agent.speed
            assert opt - 1e-9 <= metres <= 1.5 * opt + 1e-9
            path = planner.plan(agent, task.cell)  # the very path that was costed
            assert path_length(path) * world.cell == pytest.approx(metres, abs=1e-9)
    searches = planner.stats.extra["searches"]
    planner.costs(agents, tasks)  # cached per task until it closes
    assert planner.stats.extra["searches"] == searches
    for t in tasks:
        planner.task_closed(t.id)
    assert len(planner._cache) == 0


def test_seeded_and_independent_of_query_order():
    world = random_world(4, blocked=0.2)
    qs = list(pairs(world, 4, 25, True))

    def answers(order, seed=0):
        pl = RStarPlanner(world, w=2.0, delta=4, k=6, local_expansions=60, seed=seed)
        out = {}
        for i in order:
            s, g = qs[i]
            out[i] = pl.plan(AgentView(0, "uav", s, 5.0), g)
        return out

    forward = answers(range(len(qs)))
    assert answers(range(len(qs))) == forward
    assert answers(reversed(range(len(qs)))) == forward
    other = answers(range(len(qs)), seed=9)
    assert any(other[i] != forward[i] for i in forward)  # another seed samples other subgoals


def test_hard_local_searches_are_avoided_and_the_bound_still_holds():
    world = random_world(6, blocked=0.3)
    planner = RStarPlanner(world, w=1.3, delta=5, k=6, local_expansions=5, seed=6)
    for start, goal in pairs(world, 6, 30, True):
        path = planner.plan(AgentView(0, "uav", start, 5.0), goal)
        opt = optimum(world, start, goal, True)
        if math.isinf(opt):
            assert path is None
            continue
        check_path(world.grid, path, True)
        assert path_length(path) <= 1.3 * opt + 1e-9
    assert planner.stats.extra["avoid_labels"] > 0


def test_without_bound_enforcement_paths_stay_legal():
    world = box_world(1)
    planner = RStarPlanner(world, w=1.5, enforce_bound=False, seed=2)
    for start, goal in pairs(world, 1, 20, True):
        path = planner.plan(AgentView(0, "uav", start, 5.0), goal)
        check_path(world.grid, path, True)
        assert path[0] == start and path[-1] == goal
        assert path_length(path) >= optimum(world, start, goal, True) - 1e-9
    assert planner.stats.extra["certified"] > 0


def test_parameters_are_checked():
    world = random_world(0)
    with pytest.raises(ValueError):
        RStarPlanner(world, w=0.9)
    with pytest.raises(ValueError):
        RStarPlanner(world, delta=0)
    with pytest.raises(TypeError):
        RStarPlanner(world, bogus=1)


def test_usable_as_the_scenarios_planner(make_scenario):
    assert registry.load("planner", "rstar") is RStarPlanner
    path = make_scenario(
        fleet={"agents": 4}, tasks={"ground_fraction": 0.5}, dispatch={"planner": "rstar"},
        extra="[dispatch.planner_params]\nw = 1.0\n")
    spec = load_scenario(path).runs()[0]
    result = run_one(spec)
    assert result.summary["tasks_completed"] == result.summary["n_tasks"]
    astar = run_one(load_scenario(make_scenario(
        "astar.toml", fleet={"agents": 4}, tasks={"ground_fraction": 0.5})).runs()[0])
    # w = 1: R* is exact, so the run matches the exact planner's
    assert result.summary["total_cost"] == pytest.approx(astar.summary["total_cost"], abs=1e-9)
