"""The ``reservation`` planner: A* costs, SIPP timed routes that respect reservations.

References are independent of the planner: the ``astar`` planner (costs, lengths), the time
model of :func:`dispatch.api.motion.occupancy` (a route's reservations must overlap none of
the blocked intervals) and, for optimality, a breadth-first search over (cell, whole second)
states on mazes where every step takes one second (corridors one cell wide: only straight
steps are legal), with blocked intervals on whole seconds, where the earliest continuous-time
arrival is a whole second too.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import pytest

from dispatch.api import registry
from dispatch.api.motion import check_path, occupancy, overlaps, path_length
from dispatch.api.problem import AgentView, TaskView
from dispatch.api.voxels import Grid
from dispatch.space.world import World
from planners.astar import AStarPlanner
from planners.graph import distance_field
from planners.reservation import ReservationPlanner, safe_intervals, sipp

INF = math.inf


class Blocked:
    """Reservations as a plain dict ``cell -> sorted merged intervals``."""

    def __init__(self, table=None) -> None:
        self.table = table or {}

    def blocked(self, cell):
        return self.table.get(tuple(cell), ())


def random_world(seed: int, shape=(9, 8, 3), blocked=0.2) -> World:
    rng = np.random.default_rng(seed)
    occ = rng.random(shape) < blocked
    return World(size=tuple(float(s) for s in shape), grid=Grid(occ, 1.0), boxes=())


def free_cells(grid, rng, n, ground=False):
    cells = grid.free_cells(layer=0 if ground else None)
    pick = rng.choice(len(cells), size=n, replace=False)
    return [tuple(int(v) for v in cells[i]) for i in pick]


def check_route(grid, route, flies, speed, start, t0, goal, res: Blocked):
    """The route is legal, timed at ``speed``, from (t0, start) to goal, and overlaps no
    blocked interval under the time model (the goal held for good)."""
    assert route[0] == (t0, start)
    assert route[-1][1] == goal
    cells = [c for _, c in route]
    check_path(grid, cells, flies)
    for (ta, a), (tb, b) in zip(route, route[1:]):
        assert tb - ta >= math.dist(a, b) * grid.cell / speed - 1e-9
    for cell, s, e in occupancy(route, speed, grid.cell):
        for a, b in res.blocked(cell):
            assert not overlaps(s, e, a, b), (cell, (s, e), (a, b))


def agent(cell, flies=True, speed=5.0, aid=0):
    return AgentView(aid, "uav" if flies else "ugv", cell, speed)


# --------------------------------------------------------------------------- no reservations


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("flies", [True, False])
def test_without_reservations_the_route_is_a_shortest_path(seed, flies):
    world = random_world(seed)
    grid = world.grid
    rng = np.random.default_rng(seed)
    planner = ReservationPlanner(world)
    speed = 5.0 if flies else 3.0
    for _ in range(15):
        s, g = free_cells(grid, rng, 2, ground=not flies)
        field = distance_field(grid, g, flies)
        dist = field[s] if flies else field[s[0], s[1]]
        route = planner.plan_timed(agent(s, flies, speed), g, Blocked(), 2.5)
        if not math.isfinite(dist):
            assert route is None
            continue
        check_route(grid, route, flies, speed, s, 2.5, g, Blocked())
        assert route[-1][0] - 2.5 == pytest.approx(dist / speed, abs=1e-9)
        assert path_length([c for _, c in route]) == pytest.approx(dist, abs=1e-9)


def test_costs_and_untimed_plans_are_astar_s():
    world = random_world(7)
    rng = np.random.default_rng(7)
    cells = free_cells(world.grid, rng, 10, ground=True)
    agents = tuple(AgentView(i, "uav" if i % 2 else "ugv", c, 5.0 if i % 2 else 3.0)
                   for i, c in enumerate(cells[:5]))
    tasks = tuple(TaskView(i, "ground", c, 0.0) for i, c in enumerate(cells[5:]))
    ours, ref = ReservationPlanner(world), AStarPlanner(world)
    np.testing.assert_array_equal(ours.costs(agents, tasks), ref.costs(agents, tasks))
    assert ours.plan(agents[1], tasks[0].cell) == ref.plan(agents[1], tasks[0].cell)
    assert ours.reservation_aware and not ref.reservation_aware


# --------------------------------------------------------------------------- with reservations


def random_reservations(grid, rng, n, horizon=8.0, forever=0.1) -> Blocked:
    """``n`` random intervals on random free cells, merged per cell (some last forever)."""
    raw: dict = {}
    for c in free_cells(grid, rng, min(n, len(grid.free_cells()))):
        for _ in range(int(rng.integers(1, 3))):
            a = float(rng.uniform(0, horizon))
            b = INF if rng.random() < forever else a + float(rng.uniform(0.05, 2.0))
            raw.setdefault(c, []).append((a, b))
    out = {}
    for c, ivs in raw.items():
        merged: list[list[float]] = []
        for a, b in sorted(ivs):
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        out[c] = tuple((a, b) for a, b in merged)
    return Blocked(out)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("flies", [True, False])
def test_routes_never_cross_a_reservation(seed, flies):
    world = random_world(seed, blocked=0.12)
    grid = world.grid
    rng = np.random.default_rng([seed, flies])
    planner = ReservationPlanner(world)
    speed = 5.0 if flies else 3.0
    found = waited = 0
    for _ in range(20):
        s, g = free_cells(grid, rng, 2, ground=not flies)
        res = random_reservations(grid, rng, 60 if flies else 25)
        res.table.pop(s, None)  # the vehicle stands there now
        route = planner.plan_timed(agent(s, flies, speed), g, res, 0.0)
        if route is None:
            continue
        found += 1
        check_route(grid, route, flies, speed, s, 0.0, g, res)
        # never earlier than the static shortest path
        field = distance_field(grid, g, flies)
        dist = field[s] if flies else field[s[0], s[1]]
        assert route[-1][0] >= dist / speed - 1e-9
        waited += route[-1][0] > path_length([c for _, c in route]) / speed + 1e-9
    assert found >= 10
    assert planner.stats.extra["timed_plans"] == 20
    assert planner.stats.extra["waits_planned"] == waited


def maze(seed: int, n: int = 5) -> Grid:
    """A perfect maze on a (2n+1) x (2n+1) ground grid: corridors one cell wide, so no 2x2
    block is free and only straight steps are legal; a few extra openings make cycles."""
    rng = np.random.default_rng(seed)
    size = 2 * n + 1
    occ = np.ones((size, size, 1), dtype=bool)
    seen = {(0, 0)}
    stack = [(0, 0)]
    occ[1, 1, 0] = False
    while stack:
        i, j = stack[-1]
        nbrs = [(i + di, j + dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
                if 0 <= i + di < n and 0 <= j + dj < n and (i + di, j + dj) not in seen]
        if not nbrs:
            stack.pop()
            continue
        a, b = nbrs[int(rng.integers(len(nbrs)))]
        occ[2 * a + 1, 2 * b + 1, 0] = False
        occ[i + a + 1, j + b + 1, 0] = False
        seen.add((a, b))
        stack.append((a, b))
    for _ in range(n):  # knock down a few walls between two corridors (no 2x2 block opens)
        i, j = int(rng.integers(1, size - 1)), int(rng.integers(1, size - 1))
        if (i + j) % 2 == 1 and occ[i, j, 0]:
            occ[i, j, 0] = False
    return Grid(occ, 1.0)


def earliest_by_bfs(grid: Grid, start, goal, res: Blocked, horizon: int = 200):
    """Earliest whole-second arrival at ``goal`` (parked for good) with one-second steps, or
    None: breadth-first over (cell, second); standing or stepping during [k, k+1) needs the
    cell(s) free in that second."""

    def free(c, k, end=None):
        end = k + 1 if end is None else end
        return not any(overlaps(k, end, a, b) for a, b in res.blocked(c))

    if not free(start, 0):
        return None
    seen = {(start, 0)}
    q = deque([(start, 0)])
    while q:
        c, k = q.popleft()
        if c == goal and free(c, k, INF):
            return k
        if k >= horizon or not free(c, k):
            continue
        for d in ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)):
            n = (c[0] + d[0], c[1] + d[1], 0)
            if grid.is_free(n) and free(n, k) and (n, k + 1) not in seen:
                seen.add((n, k + 1))
                q.append((n, k + 1))
    return None


@pytest.mark.parametrize("seed", range(12))
def test_earliest_arrival_matches_a_time_expanded_search(seed):
    grid = maze(seed)
    world = World(size=tuple(float(s) for s in grid.shape), grid=grid, boxes=())
    planner = ReservationPlanner(world)
    rng = np.random.default_rng(seed)
    cells = [tuple(int(v) for v in c) for c in grid.free_cells()]
    compared = waits = 0
    for _ in range(25):
        s, g = (cells[i] for i in rng.choice(len(cells), 2, replace=False))
        table: dict = {}
        for c in (cells[i] for i in rng.choice(len(cells), len(cells) // 3, replace=False)):
            a = int(rng.integers(0, 25))
            b = INF if rng.random() < 0.05 else a + int(rng.integers(1, 4))
            table[c] = ((float(a), float(b)),)
        table.pop(s, None)
        res = Blocked(table)
        want = earliest_by_bfs(grid, s, g, res)
        route = planner.plan_timed(agent(s, False, 1.0), g, res, 0.0)
        if want is None:
            assert route is None
            continue
        assert route is not None, (s, g)
        check_route(grid, route, False, 1.0, s, 0.0, g, res)
        assert route[-1][0] == pytest.approx(want, abs=1e-9)
        compared += 1
        waits += route[-1][0] > len(route) - 1 + 1e-9
    assert compared >= 15 and waits >= 1


def test_it_waits_for_a_crossing_vehicle():
    """A straight corridor, 1 m/s: the vehicle holds (2,1) from the start of its step into it
    until the end of its step out of it, [0, 2) without waiting."""
    occ = np.ones((5, 3, 1), dtype=bool)
    occ[:, 1, 0] = False
    world = World((5.0, 3.0, 1.0), Grid(occ, 1.0), ())
    planner = ReservationPlanner(world)
    a = agent((1, 1, 0), False, 1.0)

    def route(blocked):
        return planner.plan_timed(a, (3, 1, 0), Blocked({(2, 1, 0): (blocked,)}), 0.0)

    # held during [0.5, 2): it cannot pass before, so it waits until 2 to step in
    assert route((0.5, 2.0)) == [(0, (1, 1, 0)), (3.0, (2, 1, 0)), (4.0, (3, 1, 0))]
    # held during [1.5, 2.5): [0, 2) overlaps it, so it waits until 2.5
    assert route((1.5, 2.5))[-1][0] == pytest.approx(4.5)
    # held from 2 on: it is out exactly then (touching is no conflict)
    assert route((2.0, 9.0)) == [(0, (1, 1, 0)), (1.0, (2, 1, 0)), (2.0, (3, 1, 0))]


def test_diagonal_corners_are_respected():
    """A diagonal step needs its corner cells free for the whole step."""
    world = World((3.0, 3.0, 1.0), Grid(np.zeros((3, 3, 1), dtype=bool), 1.0), ())
    d = math.sqrt(2)
    free = ReservationPlanner(world).plan_timed(agent((0, 0, 0), False, 1.0), (1, 1, 0),
                                                Blocked(), 0.0)
    assert free == [(0.0, (0, 0, 0)), (pytest.approx(d), (1, 1, 0))]
    res = Blocked({(1, 0, 0): ((0.0, 10.0),), (0, 1, 0): ((0.0, 10.0),)})
    route = ReservationPlanner(world).plan_timed(agent((0, 0, 0), False, 1.0), (1, 1, 0), res,
                                                 0.0)
    assert route == [(0.0, (0, 0, 0)), (pytest.approx(10.0 + d), (1, 1, 0))]  # waits


def test_goal_held_for_good_or_start_taken_means_no_route():
    world = random_world(1, blocked=0.0)
    planner = ReservationPlanner(world)
    a = agent((0, 0, 0))
    assert planner.plan_timed(a, (3, 3, 1), Blocked({(3, 3, 1): ((40.0, INF),)}), 0.0) is None
    assert planner.plan_timed(a, (3, 3, 1), Blocked({(0, 0, 0): ((0.0, 1.0),)}), 0.5) is None
    # the goal busy for a while: it arrives once it is free
    route = planner.plan_timed(a, (3, 3, 1), Blocked({(3, 3, 1): ((0.0, 40.0),)}), 0.0)
    assert route[-1][0] >= 40.0 - 1e-9 and route[-1][1] == (3, 3, 1)
    # already there and free: stay
    assert planner.plan_timed(a, (0, 0, 0), Blocked(), 3.0) == [(3.0, (0, 0, 0))]
    assert planner.stats.extra["timed_failures"] == 2


def test_parking_goes_to_the_nearest_cell_nobody_needs():
    occ = np.ones((6, 3, 1), dtype=bool)
    occ[:, 1, 0] = False
    world = World((6.0, 3.0, 1.0), Grid(occ, 1.0), ())
    planner = ReservationPlanner(world)
    a = agent((2, 1, 0), False, 1.0)
    assert planner.plan_timed(a, None, Blocked(), 0.0) == [(0.0, (2, 1, 0))]
    # its cell and the next two to the left are needed later; right is free from t = 3
    res = Blocked({(2, 1, 0): ((5.0, 6.0),), (1, 1, 0): ((5.0, 6.0),),
                   (0, 1, 0): ((7.0, 8.0),), (3, 1, 0): ((0.0, 3.0),)})
    route = planner.plan_timed(a, None, res, 0.0)
    assert route == [(0.0, (2, 1, 0)), (4.0, (3, 1, 0))]
    check_route(world.grid, route, False, 1.0, (2, 1, 0), 0.0, (3, 1, 0), res)


def test_search_limit_and_parameters():
    world = random_world(2, blocked=0.0)
    planner = ReservationPlanner(world, max_expansions=3)
    assert planner.plan_timed(agent((0, 0, 0)), (8, 7, 2), Blocked(), 0.0) is None
    assert ReservationPlanner(world).plan_timed(agent((0, 0, 0)), (8, 7, 2), Blocked(), 0.0)
    with pytest.raises(ValueError, match="max_expansions"):
        ReservationPlanner(world, max_expansions=0)
    with pytest.raises(ValueError, match="retry_after"):
        ReservationPlanner(world, retry_after=0)
    assert registry.load("planner", "reservation") is ReservationPlanner


def test_safe_intervals():
    assert safe_intervals([], 0.0) == [(-INF, INF)]
    assert safe_intervals([(1.0, 2.0), (2.0, 3.0), (5.0, INF)], 0.0) == [(-INF, 1.0), (3.0, 5.0)]
    # intervals over by t0 do not count
    assert safe_intervals([(0.0, 2.0), (4.0, 5.0)], 3.0) == [(-INF, 4.0), (5.0, INF)]


def test_sipp_rejects_bad_cells():
    grid = Grid(np.zeros((3, 3, 2), dtype=bool), 1.0)
    no = Blocked().blocked
    assert sipp(grid, False, 1.0, (0, 0, 1), 0.0, (2, 2, 0), no) == (None, 0)  # UGV in the air
    assert sipp(grid, True, 1.0, (0, 0, 0), 0.0, (5, 0, 0), no) == (None, 0)  # out of bounds
