"""The ``astar`` planner and its grid graphs are exact.

References are built independently here: plain Python loops over cells with
:func:`dispatch.api.motion.step_is_legal`, then scipy's Dijkstra; and the published optimal lengths
of
the MovingAI 2D benchmark.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from dispatch.api.motion import check_path, offsets, path_length, step_is_legal, step_length
from dispatch.api.problem import AgentView, TaskView
from dispatch.api.voxels import Grid
from dispatch.space.world import World
from planners import graph as G
from planners.astar import AStarPlanner
from tests.conftest import missing_data

SHAPE = (12, 10, 6)
SEEDS = (0, 1, 2, 3)
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "movingai_2d"


# --------------------------------------------------------------------------- helpers


def random_world(seed: int, shape=SHAPE, blocked=0.25, cell=1.0) -> World:
    rng = np.random.default_rng(seed)
    occ = rng.random(shape) < blocked
    size = tuple(s * cell for s in shape)
    return World(size=size, grid=Grid(occ, cell), boxes=())


def reference_graph(grid: Grid, flies: bool) -> tuple[list, csr_matrix]:
    """Cells (in C order) and the adjacency in metres, built cell by cell with step_is_legal."""
    nx, ny, nz = grid.shape
    cells = [(i, j, k) for i in range(nx) for j in range(ny) for k in range(nz if flies else 1)]
    index = {c: n for n, c in enumerate(cells)}
    rows, cols, w = [], [], []
    for a in cells:
        if not grid.is_free(a):
            continue
        for d in offsets(flies):
            b = (a[0] + d[0], a[1] + d[1], a[2] + d[2])
            if grid.is_free(b) and step_is_legal(grid, a, b, flies):
                rows.append(index[a])
                cols.append(index[b])
                w.append(step_length(a, b) * grid.cell)
    n = len(cells)
    return cells, csr_matrix((w, (rows, cols)), shape=(n, n))


_REF: dict = {}


def reference(seed: int, flies: bool, cell: float = 1.0):
    """``(world, cells, index, all-pairs metres)`` for a random world; cached per test session."""
    key = (seed, flies, cell)
    if key not in _REF:
        world = random_world(seed, cell=cell)
        cells, adj = reference_graph(world.grid, flies)
        dist = dijkstra(adj, directed=True)
        _REF[key] = (world, cells, {c: n for n, c in enumerate(cells)}, dist)
    return _REF[key]


def pair_sample(cells, dist, rng, count):
    """Pairs of cells, mostly free, with both reachable and unreachable pairs when they exist."""
    n = len(cells)
    pairs = [(int(a), int(b)) for a, b in rng.integers(0, n, size=(count, 2))]
    unreachable = np.argwhere(~np.isfinite(dist))
    if len(unreachable):
        pick = rng.choice(len(unreachable), size=min(count // 4, len(unreachable)), replace=False)
        pairs += [tuple(int(v) for v in unreachable[p]) for p in pick]
    return [(cells[a], cells[b], a, b) for a, b in pairs]


# --------------------------------------------------------------------------- graphs and fields


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
@pytest.mark.parametrize("seed", SEEDS)
def test_graph_equals_reference(seed, flies):
    world, cells, _, _ = reference(seed, flies)
    _, adj = reference_graph(world.grid, flies)
    g = G.graph(world.grid, flies)
    assert g.csr.shape == adj.shape
    assert abs(g.csr - adj).max() < 1e-12
    assert g.csr.nnz == adj.nnz
    assert G.graph(world.grid, flies) is g  # cached on the grid


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
@pytest.mark.parametrize("seed", SEEDS)
def test_distance_field_equals_reference(seed, flies):
    # seed 0 uses 2.5 m cells: fields are in metres
    world, cells, _, dist = reference(seed, flies, cell=2.5 if seed == 0 else 1.0)
    rng = np.random.default_rng(100 + seed)
    for goal in rng.choice(len(cells), size=15, replace=False):
        field = G.distance_field(world.grid, cells[goal], flies)
        assert field.shape == (SHAPE if flies else SHAPE[:2])
        assert not field.flags.writeable
        want = dist[:, goal] if world.grid.is_free(cells[goal]) else np.full(len(cells), np.inf)
        np.testing.assert_allclose(field.reshape(-1), want, rtol=0, atol=1e-9)
        assert G.distance_field(world.grid, cells[goal], flies) is field


def test_distance_field_edge_cases():
    world = random_world(5)
    grid = world.grid
    blocked = tuple(int(v) for v in np.argwhere(grid.occupied)[0])
    assert np.isinf(G.distance_field(grid, blocked, True)).all()
    with pytest.raises(ValueError, match="ground layer"):
        G.distance_field(grid, (0, 0, 3), False)
    with pytest.raises(ValueError, match="out of bounds"):
        G.distance_field(grid, (99, 0, 0), True)


def test_field_cache_is_bounded_in_count(monkeypatch):
    monkeypatch.setattr(G, "FIELD_CACHE_MAX_FIELDS", 3)
    grid = random_world(6).grid
    free = grid.free_cells()
    fields = [G.distance_field(grid, tuple(free[i]), True) for i in range(5)]
    cache = G.field_cache(grid)
    assert len(cache) == 3 and cache.evictions == 2
    g = G.graph(grid, True)
    assert cache.lru_keys() == [("field", True, g.node(tuple(free[i]))) for i in (2, 3, 4)]
    assert all(cache.get(k) is f for k, f in zip(cache.lru_keys(), fields[2:]))


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
@pytest.mark.parametrize("seed", SEEDS)
def test_values_rebuilt_from_dijkstra_trees_are_bit_identical(seed, flies):
    """What the cost path caches is a goal's Dijkstra tree (one byte a node); the values rebuilt
    from it equal the float64 field bit for bit at every node (and scipy's to 1e-9), cold and
    cached, unreachable nodes included."""
    world, cells, _, dist = reference(seed, flies)
    grid = Grid(world.grid.occupied.copy(), world.grid.cell)
    g = G.graph(grid, flies)
    every = np.arange(g.n_nodes)
    rng = np.random.default_rng(600 + seed)
    goals = [cells[int(i)] for i in rng.choice(len(cells), size=6, replace=False)]
    cold, computed = G.field_values(grid, goals, flies, every)
    assert computed == len(set(goals))
    cached, computed = G.field_values(grid, goals, flies, every)
    assert computed == 0
    for t, goal in enumerate(goals):
        field = G._field(g, g.node(goal)) if grid.is_free(goal) else np.full(len(cells), np.inf)
        np.testing.assert_array_equal(cold[:, t], field)
        np.testing.assert_array_equal(cached[:, t], field)
        want = dist[:, cells.index(goal)] if grid.is_free(goal) else np.inf
        np.testing.assert_allclose(cached[:, t], want, rtol=0, atol=1e-9)
    assert np.isinf(cached).any()
    assert all(k[0] == "tree" and G.field_cache(grid).get(k).parent.dtype == np.uint8
               for k in G.field_cache(grid).lru_keys())


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
def test_bounded_searches_stop_early_and_extend_exactly(flies):
    """Values for a few nodes near the goal come from a search that stops once they are
    settled; asking later for farther nodes searches again; every value equals the full field
    bit for bit."""
    world = random_world(10, shape=(40, 30, 20) if flies else (150, 150, 1), blocked=0.2)
    grid = world.grid
    g = G.graph(grid, flies)
    free = grid.free_cells(layer=None if flies else 0)
    goal = tuple(int(v) for v in free[len(free) // 2])
    full = G._field(g, g.node(goal))
    order = np.argsort(full, kind="stable")
    near = order[1:4]  # the three nodes nearest the goal
    vals, computed = G.field_values(grid, [goal], flies, near, bounded=True)
    np.testing.assert_array_equal(vals[:, 0], full[near])
    tree = G.field_cache(grid).get(("tree", flies, g.node(goal)))
    assert computed == 1 and tree.radius < np.inf
    assert (tree.parent == G._fast.UNREACHED).sum() > g.n_nodes // 2  # most never reached
    again, computed = G.field_values(grid, [goal], flies, near[::-1], bounded=True)
    assert computed == 0  # within the radius: read from the cached tree
    np.testing.assert_array_equal(again[:, 0], full[near[::-1]])
    reach = np.flatnonzero(np.isfinite(full))
    far = np.concatenate([near, reach[-3:], np.flatnonzero(~np.isfinite(full))[:2]])
    vals, computed = G.field_values(grid, [goal], flies, far, bounded=True)
    assert computed == 1  # beyond the radius: searched again
    np.testing.assert_array_equal(vals[:, 0], full[far])
    assert G.field_cache(grid).get(("tree", flies, g.node(goal))).radius == np.inf
    everything, computed = G.field_values(grid, [goal], flies, np.arange(g.n_nodes))
    assert computed == 0
    np.testing.assert_array_equal(everything[:, 0], full)


def test_field_cache_fills_past_its_byte_bound_and_recomputes_identically():
    """Many decisions over more tasks than the bound holds: the bytes the cache holds never
    exceed its bound, an evicted field is freed (nobody else keeps it: the planner holds keys,
    not arrays), and when it is needed again it is recomputed to the same values, which equal
    scipy's shortest paths."""
    import gc
    import weakref

    world = random_world(8, shape=(30, 20, 10), blocked=0.15)
    grid = world.grid
    tree_bytes = 30 * 20 * 10  # the cost path keeps one byte a node (a Dijkstra tree)
    planner = AStarPlanner(world, field_cache_mb=3.5 * tree_bytes / 2**20)
    cache = G.field_cache(grid)
    assert cache.max_bytes == int(3.5 * tree_bytes)
    rng = np.random.default_rng(8)
    free = grid.free_cells()
    cells = [tuple(int(v) for v in free[i]) for i in rng.choice(len(free), 12, replace=False)]
    tasks = tuple(TaskView(t, "air", c, 0.0) for t, c in enumerate(cells))
    agents = agents_for([tuple(int(v) for v in free[i])
                         for i in rng.choice(len(free), 25, replace=False)], True, 2.0)
    g = G.graph(grid, True)
    want = np.stack([dijkstra(g.csr, indices=g.node(c))[[g.node(a.cell) for a in agents]]
                     for c in cells], axis=1) / 2.0
    first = {}
    evicted = []
    for _ in range(4):  # decisions over sliding windows of five open tasks
        for lo in range(len(tasks) - 4):
            window = tasks[lo : lo + 5]
            held = {k: weakref.ref(cache.get(k).parent) for k in cache.lru_keys()}
            cost = planner.costs(agents, window)
            np.testing.assert_allclose(cost, want[:, lo : lo + 5], rtol=0, atol=1e-9)
            for t, task in enumerate(window):
                if task.id in first:  # recomputed or cached: the very same values
                    np.testing.assert_array_equal(cost[:, t], first[task.id])
                first[task.id] = cost[:, t]
            assert cache.nbytes <= cache.max_bytes
            assert sum(cache.get(k).nbytes for k in cache.lru_keys()) == cache.nbytes
            assert len(cache) == 3
            gc.collect()
            evicted += [ref for k, ref in held.items() if k not in cache]
    assert evicted and all(ref() is None for ref in evicted)
    assert cache.evictions > len(tasks)
    assert planner.stats.extra["fields_computed"] > len(tasks)  # evicted ones came back


def test_field_cache_keeps_nothing_larger_than_its_bound():
    world = random_world(9)
    planner = AStarPlanner(world, field_cache_mb=0)
    free = world.grid.free_cells()
    task = TaskView(0, "air", tuple(int(v) for v in free[0]), 0.0)
    agent = AgentView(0, "uav", tuple(int(v) for v in free[-1]), 1.0)
    one = planner.costs((agent,), (task,))
    assert len(G.field_cache(world.grid)) == 0
    np.testing.assert_array_equal(one, planner.costs((agent,), (task,)))
    assert planner.stats.extra["fields_computed"] == 2
    with pytest.raises(ValueError, match="field_cache_mb"):
        AStarPlanner(world, field_cache_mb=-1)
    from planners.reservation import ReservationPlanner

    ReservationPlanner(world, field_cache_mb=2)
    assert G.field_cache(world.grid).max_bytes == 2 * 2**20


# --------------------------------------------------------------------------- A*


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
@pytest.mark.parametrize("seed", SEEDS)
def test_astar_is_optimal_on_random_worlds(seed, flies):
    world, cells, _, dist = reference(seed, flies, cell=2.5 if seed == 0 else 1.0)
    grid = world.grid
    rng = np.random.default_rng(200 + seed)
    n_unreachable = 0
    for a, b, ia, ib in pair_sample(cells, dist, rng, 200):
        want = dist[ia, ib]
        if not (grid.is_free(a) and grid.is_free(b)):
            want = math.inf  # blocked endpoints are never reachable (even a == b)
        length, path = G.astar(grid, a, b, flies)
        if math.isinf(want):
            n_unreachable += 1
            assert math.isinf(length) and path is None
            continue
        assert path[0] == a and path[-1] == b
        check_path(grid, path, flies)
        assert abs(path_length(path) * grid.cell - want) < 1e-9
        assert abs(length - want) < 1e-9
    assert n_unreachable > 0


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
@pytest.mark.parametrize("seed", SEEDS)
def test_astar_without_move_masks_is_optimal(monkeypatch, seed, flies):
    """Huge grids read moves from the padded occupancy instead of per-node masks: same answers."""
    monkeypatch.setattr(G, "MASK_MAX_NODES", 0)
    world, cells, _, dist = reference(seed, flies)
    grid = Grid(world.grid.occupied.copy(), world.grid.cell)  # a fresh grid: nothing cached
    rng = np.random.default_rng(500 + seed)
    for a, b, ia, ib in pair_sample(cells, dist, rng, 100):
        want = dist[ia, ib] if grid.is_free(a) and grid.is_free(b) else math.inf
        length, path = G.astar(grid, a, b, flies)
        if math.isinf(want):
            assert math.isinf(length) and path is None
            continue
        assert abs(length - want) < 1e-9
        assert path[0] == a and path[-1] == b
        check_path(grid, path, flies)
    assert G._GRAPH_KEY not in grid.cache  # no masks were built


def test_astar_scratch_is_reused_and_wraps():
    """Reused scratch arrays (a generation number per search) give the same answers, also
    across the generation counter's wrap-around."""
    world, cells, _, dist = reference(1, True)
    grid = Grid(world.grid.occupied.copy(), 1.0)
    free = [c for c in cells if grid.is_free(c)]
    pairs = [(free[i], free[-1 - 3 * i], cells.index(free[i]), cells.index(free[-1 - 3 * i]))
             for i in range(6)]
    first = [G.astar(grid, a, b, True) for a, b, _, _ in pairs]
    (key, hit), = grid.cache[G._SCRATCH_KEY].items()
    hit[1] = 0xFFFFFFFF - 2  # three searches before the counter would overflow
    again = [G.astar(grid, a, b, True) for a, b, _, _ in pairs]
    assert grid.cache[G._SCRATCH_KEY][key][1] < 10  # wrapped: fresh arrays, counter restarted
    for (a, b, ia, ib), (l1, p1), (l2, p2) in zip(pairs, first, again):
        assert l1 == l2 and p1 == p2
        assert abs(l1 - dist[ia, ib]) < 1e-9 if np.isfinite(dist[ia, ib]) else p1 is None


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
def test_distance_fields_batch_equals_single(monkeypatch, flies):
    """Several fields computed together (on threads) equal fields computed one by one."""
    world = random_world(7, shape=(40, 30, 20) if flies else (150, 150, 1), blocked=0.2)
    grid = world.grid
    free = grid.free_cells(layer=None if flies else 0)
    goals = [tuple(int(v) for v in free[i]) for i in range(0, len(free), len(free) // 6)]
    goals.append(tuple(int(v) for v in np.argwhere(grid.occupied[:, :, :1])[0]))  # blocked
    goals.append(goals[0])  # repeated
    monkeypatch.setattr(G, "FIELD_THREADS", 2)
    batch = G.distance_fields(grid, goals, flies)
    assert batch[0] is batch[-1]
    assert np.isinf(batch[-2]).all()
    single = Grid(grid.occupied.copy(), grid.cell)
    monkeypatch.setattr(G, "FIELD_THREADS", 1)
    for goal, field in zip(goals, batch):
        np.testing.assert_array_equal(field, G.distance_field(single, goal, flies))
        assert not field.flags.writeable


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
def test_astar_on_obstacle_free_grid_matches_octile(flies):
    from dispatch.api.motion import octile

    grid = Grid(np.zeros((9, 7, 5), dtype=bool), 1.0)
    rng = np.random.default_rng(7)
    for _ in range(50):
        a = tuple(int(v) for v in rng.integers(0, (9, 7, 5)))
        b = tuple(int(v) for v in rng.integers(0, (9, 7, 5)))
        if not flies:
            a, b = (a[0], a[1], 0), (b[0], b[1], 0)
        length, path = G.astar(grid, a, b, flies)
        assert abs(length - octile(a, b)) < 1e-12
        check_path(grid, path, flies)


# --------------------------------------------------------------------------- the planner


def agents_for(cells, flies, speed):
    kind = "uav" if flies else "ugv"
    return tuple(AgentView(id=n, kind=kind, loc=c, speed=speed) for n, c in enumerate(cells))


@pytest.mark.parametrize("seed", SEEDS)
def test_costs_equal_reference(seed):
    w3 = reference(seed, True)
    w2 = reference(seed, False)
    world = w3[0]
    grid = world.grid
    planner = AStarPlanner(world)
    rng = np.random.default_rng(300 + seed)
    # every cell (blocked ones too) as a UAV; every ground cell as a UGV
    uavs = agents_for(w3[1], True, 2.0)
    ugvs = tuple(AgentView(id=len(uavs) + n, kind="ugv", loc=c, speed=0.5)
                 for n, c in enumerate(w2[1]))
    goals = [w3[1][int(i)] for i in rng.choice(len(w3[1]), size=12, replace=False)]
    goals += [w2[1][int(i)] for i in rng.choice(len(w2[1]), size=8, replace=False)]
    tasks = tuple(
        TaskView(id=10 + t, kind="ground" if c[2] == 0 else "air", loc=c, released_at=0.0)
        for t, c in enumerate(goals)
    )
    cost = planner.costs(uavs + ugvs, tasks)
    assert cost.shape == (len(uavs) + len(ugvs), len(tasks))
    for t, task in enumerate(tasks):
        g3 = w3[2][task.cell]
        want_uav = w3[3][:, g3] / 2.0
        if not grid.is_free(task.cell):
            want_uav = np.full(len(uavs), np.inf)
        want_uav[[not grid.is_free(c) for c in w3[1]]] = np.inf  # blocked agent cells
        np.testing.assert_allclose(cost[: len(uavs), t], want_uav, rtol=0, atol=1e-9)
        if task.kind == "ground":
            want_ugv = w2[3][:, w2[2][task.cell]] / 0.5
            if not grid.is_free(task.cell):
                want_ugv = np.full(len(ugvs), np.inf)
            want_ugv[[not grid.is_free(c) for c in w2[1]]] = np.inf
        else:
            want_ugv = np.full(len(ugvs), np.inf)
        np.testing.assert_allclose(cost[len(uavs) :, t], want_ugv, rtol=0, atol=1e-9)
    assert np.isinf(cost).any() and np.isfinite(cost).any()
    assert planner.stats.cost_queries == 1


@pytest.mark.parametrize("seed", SEEDS)
def test_plan_is_optimal_and_matches_costs(seed):
    world, cells, index, dist = reference(seed, True)
    grid = world.grid
    planner = AStarPlanner(world)
    rng = np.random.default_rng(400 + seed)
    free = [c for c in cells if grid.is_free(c)]
    for _ in range(40):
        flies = bool(rng.integers(2))
        a = free[int(rng.integers(len(free)))]
        b = free[int(rng.integers(len(free)))]
        if not flies:
            a, b = (a[0], a[1], 0), (b[0], b[1], 0)
        agent = AgentView(id=1, kind="uav" if flies else "ugv", loc=a, speed=3.0)
        task = TaskView(id=1, kind="ground" if b[2] == 0 else "air", loc=b, released_at=0.0)
        cost = planner.costs((agent,), (task,))[0, 0]
        path = planner.plan(agent, b)
        if path is None:
            assert math.isinf(cost)
            continue
        check_path(grid, path, flies)
        assert path[0] == a and path[-1] == b
        assert abs(path_length(path) * grid.cell / 3.0 - cost) < 1e-9
        planner.task_closed(1)
    assert planner.stats.plans == 40


def test_ugv_cannot_serve_air_task():
    grid = Grid(np.zeros((6, 6, 4), dtype=bool), 1.0)
    planner = AStarPlanner(World(size=(6.0, 6.0, 4.0), grid=grid, boxes=()))
    ugv = AgentView(id=0, kind="ugv", loc=(0, 0, 0), speed=1.0)
    uav = AgentView(id=1, kind="uav", loc=(0, 0, 0), speed=1.0)
    tasks = (
        TaskView(id=0, kind="air", loc=(3, 3, 2), released_at=0.0),
        TaskView(id=1, kind="ground", loc=(3, 3, 0), released_at=0.0),
        TaskView(id=2, kind="air", loc=(3, 3, 0), released_at=0.0),  # "air" kind wins
    )
    cost = planner.costs((ugv, uav), tasks)
    assert np.isinf(cost[0, 0]) and np.isinf(cost[0, 2])
    assert cost[0, 1] == pytest.approx(3 * math.sqrt(2))
    assert np.isfinite(cost[1]).all()
    assert planner.plan(ugv, (3, 3, 2)) is None
    # a UGV whose cell is off the ground cannot move at all
    lifted = AgentView(id=2, kind="ugv", loc=(0, 0, 1), speed=1.0)
    assert np.isinf(planner.costs((lifted,), tasks)).all()


def test_costs_reuse_cached_fields(monkeypatch):
    world = random_world(1)
    free = world.grid.free_cells(layer=0)
    calls = []
    real = G._field

    def counting(g, node, parents=False, targets=None):
        calls.append((g.flies, node))
        return real(g, node, parents, targets)

    monkeypatch.setattr(G, "_field", counting)
    planner = AStarPlanner(world)
    agents = (AgentView(0, "uav", tuple(int(v) for v in free[0]), 1.0),
              AgentView(1, "ugv", tuple(int(v) for v in free[1]), 1.0))
    tasks = tuple(TaskView(10 + t, "ground", tuple(int(v) for v in free[5 + t]), 0.0)
                  for t in range(3))
    first = planner.costs(agents, tasks)
    assert len(calls) == 6  # one field per (task, movement model)
    again = planner.costs(agents, tasks)
    assert len(calls) == 6  # reused at the next decision
    np.testing.assert_array_equal(first, again)
    assert planner.stats.extra["field_reuses"] == 6
    planner.task_closed(11)
    planner.task_closed(999)  # unknown ids are fine
    twin = (TaskView(20, "ground", tasks[0].cell, 0.0),)  # another task on a cached cell
    np.testing.assert_array_equal(planner.costs(agents, tasks + twin)[:, -1], first[:, 0])
    assert len(calls) == 6
    assert planner.stats.cost_queries == 3
    assert planner.stats.extra["fields_computed"] == 6


def test_empty_and_out_of_bounds_inputs():
    planner = AStarPlanner(random_world(2))
    assert planner.costs((), ()).shape == (0, 0)
    assert planner.costs((AgentView(0, "uav", (0, 0, 0), 1.0),), ()).shape == (1, 0)
    free = tuple(int(v) for v in planner.world.grid.free_cells(layer=0)[0])
    outside = (AgentView(0, "uav", (-1, 0, 0), 1.0), AgentView(1, "ugv", (0, 99, 0), 1.0))
    tasks = (TaskView(0, "ground", free, 0.0), TaskView(1, "ground", (50, 0, 0), 0.0))
    assert np.isinf(planner.costs(outside, tasks)).all()
    assert planner.plan(outside[0], free) is None
    inside = AgentView(2, "uav", free, 1.0)
    assert planner.costs((inside,), tasks)[0].tolist() == [0.0, math.inf]
    assert planner.plan(inside, (50, 0, 0)) is None


@pytest.mark.parametrize("flies", [True, False], ids=["uav", "ugv"])
def test_plan_start_equals_goal(flies):
    world = random_world(3)
    grid = world.grid
    cell = tuple(int(v) for v in grid.free_cells(layer=0)[0])
    planner = AStarPlanner(world)
    agent = AgentView(0, "uav" if flies else "ugv", cell, 1.0)
    assert planner.plan(agent, cell) == [cell]
    assert planner.costs((agent,), (TaskView(0, "ground", cell, 0.0),))[0, 0] == 0.0
    blocked = tuple(int(v) for v in np.argwhere(grid.occupied[:, :, :1])[0])
    stuck = AgentView(1, agent.kind, blocked, 1.0)
    assert planner.plan(stuck, blocked) is None
    assert planner.plan(agent, blocked) is None


# --------------------------------------------------------------------------- MovingAI 2D


def load_map(path: Path) -> Grid:
    """A MovingAI map as a one-layer grid: shape (W, H, 1), x = column, y = row."""
    lines = path.read_text().splitlines()
    assert lines[0].startswith("type")
    height = int(lines[1].split()[1])
    width = int(lines[2].split()[1])
    assert lines[3].strip() == "map"
    rows = lines[4 : 4 + height]
    chars = np.array([list(r[:width]) for r in rows])
    assert chars.shape == (height, width)
    occ = ~np.isin(chars, list(".GS"))
    return Grid(np.ascontiguousarray(occ.T[:, :, None]), 1.0)


def load_scen(path: Path) -> list[tuple[int, int, int, int, int, int, int, float]]:
    """Rows ``(bucket, width, height, sx, sy, gx, gy, optimal)``."""
    rows = []
    for line in path.read_text().splitlines()[1:]:
        if not line.strip():
            continue
        f = line.split("\t")
        rows.append((int(f[0]), int(f[2]), int(f[3]), int(f[4]), int(f[5]), int(f[6]),
                     int(f[7]), float(f[8])))
    return rows


MAPS = sorted(p.name for p in (DATA / "maps").glob("*.map")) if DATA.is_dir() else []
needs_data = pytest.mark.skipif(not MAPS,
                                reason=missing_data(DATA, "the MovingAI 2D benchmark maps"))


def sample_scenarios(rows, per_map: int):
    """A deterministic sample spread across buckets: evenly spaced buckets, first row each."""
    buckets: dict[int, list] = {}
    for r in rows:
        buckets.setdefault(r[0], []).append(r)
    keys = sorted(buckets)
    picks = np.unique(np.linspace(0, len(keys) - 1, num=min(per_map, len(keys))).round())
    out = []
    for p in picks.astype(int):
        group = buckets[keys[p]]
        out.append(group[(p * 7) % len(group)])
    return out


def check_scenarios(name: str, rows) -> None:
    grid = load_map(DATA / "maps" / name)
    for bucket, width, height, sx, sy, gx, gy, optimal in rows:
        assert grid.shape == (width, height, 1)
        start, goal = (sx, sy, 0), (gx, gy, 0)
        length, path = G.astar(grid, start, goal, False)
        assert path is not None, f"{name} bucket {bucket}: {start}->{goal} not found"
        assert abs(length - optimal) < 1e-4, (name, bucket, start, goal, length, optimal)
        assert abs(path_length(path) - optimal) < 1e-4
        assert path[0] == start and path[-1] == goal
        check_path(grid, path, False)


@needs_data
@pytest.mark.parametrize("name", MAPS)
def test_movingai_sample(name):
    rows = load_scen(DATA / "scen" / f"{name}.scen")
    check_scenarios(name, sample_scenarios(rows, per_map=40))


@needs_data
@pytest.mark.parametrize("name", MAPS)
def test_movingai_distance_field_sample(name):
    """The 2-D distance field agrees with the benchmark too (one field per sampled goal)."""
    grid = load_map(DATA / "maps" / name)
    rows = sample_scenarios(load_scen(DATA / "scen" / f"{name}.scen"), per_map=10)
    for _, _, _, sx, sy, gx, gy, optimal in rows:
        field = G.distance_field(grid, (gx, gy, 0), False)
        assert abs(field[sx, sy] - optimal) < 1e-4


FULL_CHUNK = 1000


def full_chunks():
    """``(map, first_row)`` per chunk of the full scenario sets, so they can be run piecemeal."""
    out = []
    for name in MAPS:
        with open(DATA / "scen" / f"{name}.scen") as f:
            n = sum(1 for line in f if line.strip()) - 1
        out += [pytest.param(name, i, id=f"{name}-{i // FULL_CHUNK}")
                for i in range(0, n, FULL_CHUNK)]
    return out


@pytest.mark.slow
@needs_data
@pytest.mark.parametrize(("name", "first"), full_chunks())
def test_movingai_full(name, first):
    rows = load_scen(DATA / "scen" / f"{name}.scen")
    check_scenarios(name, rows[first : first + FULL_CHUNK])


def test_kernels_compile_without_a_writable_cache(monkeypatch):
    """numba refuses cache=True where no cache directory is writable: compile per process."""
    from planners import _fast

    real = _fast.numba.njit

    def njit(*args, **kw):
        if kw.get("cache"):
            raise RuntimeError("cannot cache function 'f': no locator available for file 'x'")
        return real(*args, **kw)

    monkeypatch.setattr(_fast.numba, "njit", njit)
    assert _fast._jit(lambda x: x + 1)(41) == 42


# --------------------------------------------------------------------------- the paper's world


def test_costs_on_paper_world_equal_scipy_after_moves():
    """The paper's world (50x50x30, 10 boxes), N = M = 20 as `dispatch run` places them: the
    matrix equals scipy shortest paths on the explicit adjacency, cold and after every vehicle
    moved (fields reused: no new Dijkstra)."""
    from dispatch.fleet.placement import place_fleet
    from dispatch.plan.demand import VoxelDemand
    from dispatch.scenario.load import load_scenario
    from dispatch.space.world import world_for
    from dispatch.streams import STREAM_FLEET, STREAM_TASKS, rng_for

    root = Path(__file__).resolve().parents[2]
    scenario = load_scenario(root / "scenarios" / "paper_static.toml")
    spec = scenario.runs(allocator="hungarian", agents=20, seed=3)[0]
    world = world_for(scenario.world, 3)
    grid = world.grid
    agents = tuple(v.view() for v in place_fleet(world, spec, rng_for(3, STREAM_FLEET)))
    demand = VoxelDemand(grid, 0.5, rng_for(3, STREAM_TASKS))  # ground and air tasks
    tasks = tuple(TaskView(i, (r := demand.draw()).kind, r.loc, 0.0) for i in range(20))

    def want(agents):
        out = np.full((len(agents), len(tasks)), np.inf)
        for flies in (True, False):
            g = G.graph(grid, flies)
            for t, task in enumerate(tasks):
                if not flies and task.kind != "ground":
                    continue
                d = dijkstra(g.csr, directed=True, indices=g.node(task.cell))
                for a, ag in enumerate(agents):
                    if ag.flies == flies and g.node(ag.cell) is not None:
                        out[a, t] = d[g.node(ag.cell)] / ag.speed
        return out

    planner = AStarPlanner(world)
    cost = planner.costs(agents, tasks)
    np.testing.assert_allclose(cost, want(agents), rtol=0, atol=1e-9)
    assert np.isfinite(cost[: spec.fleet.n_uav]).all()
    computed = planner.stats.extra["fields_computed"]
    rng = np.random.default_rng(0)
    free = grid.free_cells()
    moved = tuple(
        AgentView(a.id, a.kind, tuple(int(v) for v in (
            free[rng.integers(len(free))] if a.flies else
            free[free[:, 2] == 0][rng.integers(int((free[:, 2] == 0).sum()))])), a.speed)
        for a in agents)
    again = planner.costs(moved, tasks)
    # searches that stopped short of a moved vehicle ran again, to the end: at most once each
    assert planner.stats.extra["fields_computed"] <= 2 * computed
    np.testing.assert_allclose(again, want(moved), rtol=0, atol=1e-9)
    planner.costs(agents, tasks)
    np.testing.assert_allclose(planner.costs(moved, tasks), want(moved), rtol=0, atol=1e-9)
    assert planner.stats.extra["fields_computed"] <= 2 * computed
