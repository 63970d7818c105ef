"""The ``rrt_star`` planner: legal snapped paths, costs >= exact, seeded, usable in a run.

References: exact shortest paths from :func:`planners.graph.distance_field` (Dijkstra) and the
movement rules of :func:`dispatch.api.motion.check_path`.
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
from planners.rrt_star import RRTStarPlanner
from planners.sampling import RayWorld, collision_boxes, segment_cells, snap_polyline

SEEDS = (0, 1, 2)
FAST = dict(max_iterations=300, step=3.0, rewire_radius=6.0)


def box_world(seed: int, shape=(16, 14, 8), count=5) -> World:
    """A world as the simulator builds them: ground-standing boxes, one free cell apart."""
    rng = np.random.default_rng(seed)
    return build_world(tuple(float(s) for s in shape), 1.0, count, (2.0, 2.0, 2.0),
                       (5.0, 5.0, 8.0), rng)


def fleet_and_tasks(world: World, seed: int, n_agents=6, n_tasks=5):
    rng = np.random.default_rng(1000 + seed)
    free = world.grid.free_cells()
    ground = free[free[:, 2] == 0]
    air = free[free[:, 2] > 0]
    agents = []
    for i in range(n_agents):
        flies = i % 2 == 0
        c = (air if flies else ground)[rng.integers(len(air if flies else ground))]
        agents.append(AgentView(i, "uav" if flies else "ugv", tuple(int(v) for v in c),
                                5.0 if flies else 3.0))
    tasks = []
    for j in range(n_tasks):
        on_ground = j % 2 == 0
        c = (ground if on_ground else air)[rng.integers(len(ground if on_ground else air))]
        tasks.append(TaskView(j, "ground" if on_ground else "air", tuple(int(v) for v in c),
                              0.0))
    return tuple(agents), tuple(tasks)


def exact(world: World, agent: AgentView, task: TaskView) -> float:
    """Exact shortest metres (inf where the agent may not serve the task)."""
    if not agent.flies and (task.kind != "ground" or task.cell[2] != 0):
        return math.inf
    f = distance_field(world.grid, task.cell, agent.flies)
    return float(f[agent.cell] if agent.flies else f[agent.cell[:2]])


# --------------------------------------------------------------------------- helpers


def test_supercover_walk_is_face_connected_and_touches_the_segment():
    rng = np.random.default_rng(0)
    for _ in range(200):
        p, q = rng.random(3) * 10, rng.random(3) * 10
        cells = segment_cells(p, q)
        assert tuple(cells[0]) == tuple(np.floor(p).astype(int))
        assert tuple(cells[-1]) == tuple(np.floor(q).astype(int))
        steps = np.abs(np.diff(cells, axis=0)).sum(axis=1)
        assert (steps == 1).all()
        # every listed cell meets the segment (its box, slightly grown, is crossed)
        t = np.linspace(0, 1, 4001)[:, None]
        pts = p + t * (q - p)
        for c in cells:
            inside = ((pts >= c - 1e-3) & (pts <= c + 1 + 1e-3)).all(axis=1)
            assert inside.any()


def test_snap_polyline_is_always_legal_even_through_obstacles():
    for seed in SEEDS:
        world = box_world(seed)
        grid = world.grid
        rng = np.random.default_rng(seed)
        free = grid.free_cells()
        for flies in (True, False):
            pool = free if flies else free[free[:, 2] == 0]
            for _ in range(30):
                a, b = pool[rng.integers(len(pool))], pool[rng.integers(len(pool))]
                mid = rng.random((2, 3)) * np.array(world.size)  # may cross boxes
                pts = np.vstack([np.array(grid.centre(a)), mid, np.array(grid.centre(b))])
                path = snap_polyline(grid, pts, flies)
                assert path is not None
                check_path(grid, path, flies)
                assert path[0] == tuple(a) and path[-1] == tuple(b)


def test_rays_see_the_inflated_boxes():
    world = box_world(0)
    rays = RayWorld(world, 0.25)
    try:
        b = world.boxes[0]
        cx, cy, _ = b.centre()
        y = cy
        frm = np.array([[b.x0 - 0.5, y, 1.0], [b.x0 - 0.5, y, b.z1 + 0.5]])
        to = np.array([[b.x1 + 0.5, y, 1.0], [b.x1 + 0.5, y, b.z1 + 0.5]])
        if b.z1 + 0.5 < world.size[2]:
            assert rays.visible(frm, to).tolist() == [False, True]
        assert not rays.free([[cx, cy, 0.5]])[0]
        assert rays.free([[b.x0 - 0.3, cy, 0.5]])[0]  # outside the 0.25 m inflation
        assert rays.batches >= 1
    finally:
        rays.close()


def test_collision_boxes_rebuilt_from_a_grid_without_boxes():
    rng = np.random.default_rng(5)
    occ = rng.random((7, 6, 4)) < 0.3
    world = World(size=(7.0, 6.0, 4.0), grid=Grid(occ, 1.0), boxes=())
    boxes = collision_boxes(world)
    raster = np.zeros_like(occ)
    for b in boxes:
        raster[int(b.x0):int(b.x1), int(b.y0):int(b.y1), int(b.z0):int(b.z1)] = True
    assert np.array_equal(raster, occ)
    built = box_world(1)
    assert collision_boxes(built) == built.boxes


# --------------------------------------------------------------------------- the planner


@pytest.mark.parametrize("seed", SEEDS)
def test_costs_finite_at_least_exact_and_equal_to_planned_paths(seed):
    world = box_world(seed)
    agents, tasks = fleet_and_tasks(world, seed)
    planner = RRTStarPlanner(world, seed=seed, **FAST)
    cost = planner.costs(agents, tasks)
    assert cost.shape == (len(agents), len(tasks))
    for a, agent in enumerate(agents):
        for t, task in enumerate(tasks):
            opt = exact(world, agent, task)
            if math.isinf(opt):
                assert math.isinf(cost[a, t])
                continue
            # open worlds: every servable pair is found, never shorter than the optimum
            assert math.isfinite(cost[a, t]), (agent, task)
            metres = cost[a, t] * agent.speed
            assert metres >= opt - 1e-9
            path = planner.plan(agent, task.cell)
            check_path(world.grid, path, agent.flies)
            assert path[0] == agent.cell and path[-1] == task.cell
            assert path_length(path) * world.cell == pytest.approx(metres, abs=1e-9)
    ratio = np.array([cost[a, t] * agents[a].speed / exact(world, agents[a], tasks[t])
                      for a in range(len(agents)) for t in range(len(tasks))
                      if np.isfinite(cost[a, t]) and exact(world, agents[a], tasks[t]) > 0])
    assert ratio.mean() < 1.5  # near-optimal on average, even with few iterations
    assert planner.stats.extra["trees"] > 0 and planner.stats.extra["ray_batches"] > 0


def test_ugv_cannot_serve_an_air_task_and_blocked_cells_are_inf():
    world = box_world(0)
    grid = world.grid
    free = grid.free_cells()
    air = tuple(int(v) for v in free[free[:, 2] > 0][0])
    ground = tuple(int(v) for v in free[free[:, 2] == 0][-1])
    blocked = tuple(int(v) for v in np.argwhere(grid.occupied)[0])
    ugv = AgentView(0, "ugv", ground, 3.0)
    uav = AgentView(1, "uav", air, 5.0)
    stuck = AgentView(2, "uav", blocked, 5.0)
    tasks = (TaskView(0, "air", air, 0.0), TaskView(1, "ground", ground, 0.0))
    cost = RRTStarPlanner(world, **FAST).costs((ugv, uav, stuck), tasks)
    assert math.isinf(cost[0, 0])
    assert cost[0, 1] == 0.0
    assert np.isfinite(cost[1]).all()
    assert np.isinf(cost[2]).all()
    assert RRTStarPlanner(world, **FAST).plan(ugv, air) is None


def test_seeded_and_deterministic():
    world = box_world(2)
    agents, tasks = fleet_and_tasks(world, 2)

    def answer(seed):
        pl = RRTStarPlanner(world, seed=seed, **FAST)
        c = pl.costs(agents, tasks)
        return c, [pl.plan(a, t.cell) for a in agents for t in tasks]

    c1, p1 = answer(7)
    c2, p2 = answer(7)
    assert np.array_equal(c1, c2) and p1 == p2
    c3, _ = answer(8)
    assert not np.array_equal(c1, c3)  # another seed grows other trees


def test_hand_made_grid_without_boxes_still_gives_legal_paths():
    rng = np.random.default_rng(3)
    occ = rng.random((10, 9, 4)) < 0.2
    world = World(size=(10.0, 9.0, 4.0), grid=Grid(occ, 1.0), boxes=())
    free = world.grid.free_cells()
    planner = RRTStarPlanner(world, **FAST)
    for _ in range(15):
        a, b = free[rng.integers(len(free))], free[rng.integers(len(free))]
        agent = AgentView(0, "uav", tuple(int(v) for v in a), 5.0)
        path = planner.plan(agent, tuple(int(v) for v in b))
        opt = distance_field(world.grid, tuple(int(v) for v in b), True)[tuple(a)]
        if path is None:
            assert math.isinf(opt) or planner.stats.extra["joins_failed"] > 0
            continue
        check_path(world.grid, path, True)
        assert path_length(path) >= opt - 1e-9


def test_task_closed_drops_the_trees_and_params_are_checked():
    world = box_world(0)
    agents, tasks = fleet_and_tasks(world, 0, n_agents=2, n_tasks=2)
    planner = RRTStarPlanner(world, **FAST)
    planner.costs(agents, tasks)
    assert len(planner._cache) > 0
    for t in tasks:
        planner.task_closed(t.id)
    assert len(planner._cache) == 0
    with pytest.raises(ValueError):
        RRTStarPlanner(world, max_iterations=0)
    with pytest.raises(ValueError):
        RRTStarPlanner(world, clearance=0.6)
    with pytest.raises(TypeError):
        RRTStarPlanner(world, bogus=1)


def test_usable_as_the_scenarios_planner(make_scenario):
    assert registry.load("planner", "rrt_star") is RRTStarPlanner
    path = make_scenario(
        fleet={"agents": 4}, tasks={"ground_fraction": 0.5},
        dispatch={"planner": "rrt_star"},
        extra="[dispatch.planner_params]\nmax_iterations = 200\nseed = 3\n")
    spec = load_scenario(path).runs()[0]
    result = run_one(spec)
    assert result.summary["planner"] == "rrt_star"
    assert result.summary["tasks_completed"] == result.summary["n_tasks"]
    again = run_one(spec)
    assert again.summary["total_cost"] == result.summary["total_cost"]
