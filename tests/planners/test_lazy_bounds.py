"""The ``astar`` planner's lower bounds (lazy costs) against its exact costs.

The exact costs are the planner's distance fields (themselves checked against scipy in
``test_astar.py``); the components are checked against scipy's ``connected_components`` on the
reference graph built cell by cell there.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from dispatch.api.motion import octile
from dispatch.api.problem import AgentView, TaskView
from planners import graph as G
from planners.astar import AStarPlanner
from tests.planners.test_astar import random_world, reference_graph

SEEDS = range(6)


def random_pairs(seed: int, world, n_agents: int = 30, n_tasks: int = 25):
    """Random agents (UAVs and UGVs, some on blocked cells) and tasks (ground and air, some
    blocked) anywhere in ``world``."""
    rng = np.random.default_rng(1000 + seed)
    nx, ny, nz = world.grid.shape
    agents = []
    for i in range(n_agents):
        flies = bool(rng.random() < 0.7)
        k = int(rng.integers(nz)) if flies else 0
        agents.append(AgentView(i, "uav" if flies else "ugv",
                                (int(rng.integers(nx)), int(rng.integers(ny)), k),
                                float(rng.choice([1.0, 2.5, 5.0]))))
    tasks = []
    for j in range(n_tasks):
        ground = bool(rng.random() < 0.4)
        tasks.append(TaskView(100 + j, "ground" if ground else "air",
                              (int(rng.integers(nx)), int(rng.integers(ny)),
                               0 if ground else int(rng.integers(nz))), 0.0))
    return tuple(agents), tuple(tasks)


@pytest.mark.parametrize("seed", SEEDS)
def test_bounds_never_exceed_the_exact_costs(seed):
    """On random worlds (a quarter of the cells blocked, cells of 1 m and 0.7 m), thousands of
    pairs: every bound is <= the exact cost, the bound is inf exactly where the cost is, and
    entries marked exact equal the cost."""
    world = random_world(seed, blocked=0.25, cell=1.0 if seed % 2 else 0.7)
    planner = AStarPlanner(world)
    agents, tasks = random_pairs(seed, world)
    lower, known = planner.bounds(agents, tasks)  # before any UAV field exists
    uav = np.array([a.flies for a in agents])
    same_cell = np.array([[a.cell == t.cell for t in tasks] for a in agents])
    # a UAV pair is exact only where it is inf (across components, blocked) or on the cell
    assert np.array_equal(known[uav], np.isinf(lower[uav]) | same_cell[uav])
    exact_cost = planner.costs(agents, tasks)
    assert lower.shape == known.shape == exact_cost.shape
    assert np.array_equal(np.isinf(lower), np.isinf(exact_cost))
    finite = np.isfinite(exact_cost)
    assert finite.sum() > 200  # the test sees many reachable pairs
    assert (lower[finite] <= exact_cost[finite]).all()
    assert np.array_equal(lower[known & finite], exact_cost[known & finite])
    # the bound is the octile distance (by hand, motion.octile) over the speed, scaled down
    for a, agent in enumerate(agents):
        for t, task in enumerate(tasks):
            if agent.flies and finite[a, t] and not known[a, t]:
                want = octile(agent.cell, task.cell) * world.grid.cell / agent.speed
                assert lower[a, t] == pytest.approx(want, rel=1e-11, abs=1e-12)


def test_bounds_on_open_space_are_tight():
    """Without obstacles every UAV bound is the exact cost, up to the 1e-12 scale."""
    world = random_world(0, blocked=0.0)
    planner = AStarPlanner(world)
    agents, tasks = random_pairs(7, world)
    exact_cost = planner.costs(agents, tasks)
    lower, _ = planner.bounds(agents, tasks)
    uav = np.array([a.flies for a in agents])
    np.testing.assert_allclose(lower[uav], exact_cost[uav], rtol=1e-11)
    assert (lower[uav] <= exact_cost[uav]).all()


@pytest.mark.parametrize("seed", SEEDS)
def test_exact_pairs_agree_with_the_fields(seed):
    """``exact`` (one A* per UAV pair, remembered per task and cell) equals the distance
    field's cost to 1e-12 relative, for UGV pairs and unreachable pairs too."""
    world = random_world(seed, blocked=0.3)
    planner = AStarPlanner(world)
    agents, tasks = random_pairs(seed, world, 20, 15)
    # the reference on a copy of the world (its own cache: no field reaches the lazy planner)
    want = AStarPlanner(random_world(seed, blocked=0.3)).costs(agents, tasks)
    rows, cols = np.divmod(np.arange(want.size), want.shape[1])
    got = planner.exact(agents, tasks, rows, cols).reshape(want.shape)
    assert np.array_equal(np.isinf(got), np.isinf(want))
    f = np.isfinite(want)
    np.testing.assert_allclose(got[f], want[f], rtol=1e-12)
    # now remembered: the bounds mark every UAV pair exact and equal to what exact() gave
    lower, known = planner.bounds(agents, tasks)
    assert known.all()
    assert np.array_equal(lower[f], got[f])
    assert planner.stats.extra["pair_reuses"] > 0
    planner.task_closed(tasks[0].id)  # forgotten with its task
    _, known = planner.bounds(agents, tasks)
    uav_finite = np.array([a.flies and a.cell != tasks[0].cell for a in agents]) & f[:, 0]
    assert not known[uav_finite, 0].any()


@pytest.mark.parametrize("seed", (0, 1))
def test_components_match_scipy_on_the_reference_graph(seed):
    """Two free cells share a label iff scipy finds them connected on the graph built cell by
    cell; blocked cells are -1."""
    world = random_world(seed, shape=(8, 7, 5), blocked=0.45)
    grid = world.grid
    labels = G.components(grid, True)
    cells, adj = reference_graph(grid, True)
    _, ref = connected_components(adj, directed=False)
    free = np.array([grid.is_free(c) for c in cells])
    assert (labels[~free] == -1).all()
    fl, fr = labels[free], ref[free]
    assert np.array_equal(fl[:, None] == fl[None, :], fr[:, None] == fr[None, :])
    assert len(np.unique(fl)) > 1  # the test world is split


def test_lattice_bound_by_hand():
    """sqrt3 * 1 + sqrt2 * (2 - 1) + (5 - 2) cells for offsets (5, 2, 1), times the cell."""
    got = G.lattice_bound(np.array([[0, 0, 0]]), np.array([[5, -2, 1], [0, 0, 0]]), 0.5)
    want = (math.sqrt(3) + math.sqrt(2) + 3) * 0.5
    assert got[0, 0] <= want and got[0, 0] == pytest.approx(want, rel=1e-11)
    assert got[0, 1] == 0.0
