"""The PyBullet mirror: obstacle bodies are the world's boxes, vehicle bodies follow their
vehicles, and a vehicle at a free cell centre touches no obstacle."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from dispatch.plan.tasks import TaskState
from dispatch.run.runner import make_recorder
from dispatch.run.sim import Simulation
from dispatch.scenario.load import load_scenario
from dispatch.space.physics import Physics
from dispatch.space.world import build_world, world_for
from tests.conftest import write_scenario

SEEDS = (0, 1, 2)


def tiny_world(seed: int):
    return build_world((12.0, 12.0, 6.0), 1.0, 3, (1.0, 1.0, 1.0), (3.0, 3.0, 6.0),
                       np.random.default_rng(seed))


def obstacle_contacts(ph: Physics) -> list[tuple[int, int]]:
    obstacles = set(ph.obstacles)
    return [(a, b) for a, b in ph.contacts() if a in obstacles or b in obstacles]


@pytest.mark.parametrize("seed", SEEDS)
def test_obstacle_bodies_are_the_world_boxes(seed):
    world = tiny_world(seed)
    assert len(world.boxes) == 3
    with Physics(world) as ph:
        p, c = ph.p, ph.client
        assert len(ph.obstacles) == len(world.boxes)
        assert p.getNumBodies(physicsClientId=c) == len(world.boxes)
        for body, box in zip(ph.obstacles, world.boxes):
            lo, hi = p.getAABB(body, physicsClientId=c)
            assert lo == pytest.approx((box.x0, box.y0, box.z0), abs=1e-6)
            assert hi == pytest.approx((box.x1, box.y1, box.z1), abs=1e-6)
            pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=c)
            assert pos == pytest.approx(box.centre())
            assert orn == pytest.approx((0, 0, 0, 1))
            (shape,) = p.getCollisionShapeData(body, -1, physicsClientId=c)
            assert shape[2] == p.GEOM_BOX
            assert shape[3] == pytest.approx([2 * h for h in box.half_extents()])
            assert p.getDynamicsInfo(body, -1, physicsClientId=c)[0] == 0  # static
        # the grid's occupied cells are exactly the cells inside the boxes
        grid = world.grid
        occupied = np.zeros(grid.shape, bool)
        for box in world.boxes:
            i0, j0, k0 = grid.cell_of((box.x0, box.y0, box.z0))
            i1, j1, k1 = grid.cell_of((box.x1, box.y1, box.z1))
            occupied[i0:i1, j0:j1, k0:k1] = True
        assert (occupied == grid.occupied).all()
    assert ph.client is None


def test_world_of_a_run_is_mirrored(tmp_path):
    """The world a run uses (``world_for``) is the one its Physics holds."""
    spec = load_scenario(write_scenario(tmp_path)).runs(seed=4)[0]
    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"))
    try:
        assert sim.world is world_for(spec.scenario.world, spec.seed)
        p, c = sim.physics.p, sim.physics.client
        boxes = [p.getAABB(b, physicsClientId=c) for b in sim.physics.obstacles]
        want = [((b.x0, b.y0, b.z0), (b.x1, b.y1, b.z1)) for b in sim.world.boxes]
        assert np.allclose(np.array(boxes), np.array(want), atol=1e-6)
        assert set(sim.physics.vehicles) == {v.id for v in sim.vehicles}
    finally:
        sim.physics.close()


@pytest.mark.parametrize("seed", SEEDS)
def test_vehicle_bodies_follow_their_vehicles(tmp_path, seed):
    """Step a run event by event: after every event each body sits at its vehicle's cell
    centre and no vehicle touches an obstacle."""
    spec = load_scenario(write_scenario(
        tmp_path, fleet={"agents": 4, "uav_fraction": 0.5},
        tasks={"source": "poisson", "rate": 1.0, "count": 8, "service_time": 0.5},
    )).runs(seed=seed)[0]
    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"))
    env, grid, ph = sim.env, sim.world.grid, sim.physics
    moves = 0
    try:
        env.timeout(spec.scenario.duration)  # the horizon, as Simulation.run sets it
        while not sim.finished.triggered and env.peek() <= spec.scenario.duration:
            before = {v.id: v.cell for v in sim.vehicles}
            env.step()
            for v in sim.vehicles:
                moves += v.cell != before[v.id]
                assert ph.position(v.id) == pytest.approx(grid.centre(v.cell), abs=1e-9), v
                assert grid.is_free(v.cell)
            assert obstacle_contacts(ph) == []
        assert sim.finished.triggered
        assert moves > 0
        assert sim.book.live == 0 and sim.stats.count[TaskState.COMPLETED] == sim.book.released
    finally:
        ph.close()


@pytest.mark.parametrize("seed", SEEDS)
def test_free_cell_centres_touch_no_obstacle(seed):
    world = tiny_world(seed)
    grid = world.grid
    with Physics(world) as ph:
        ph.add_vehicle(0, True, (0.5, 0.5, 0.5))
        ph.add_vehicle(1, False, (0.5, 0.5, 0.5))
        ph.move(1, (-50.0, -50.0, 0.5))  # out of the way while the UAV visits every cell
        for c in grid.free_cells():
            ph.move(0, grid.centre(tuple(c)))
            assert obstacle_contacts(ph) == [], f"UAV at free cell {tuple(c)} touches an obstacle"
        ph.move(0, (-50.0, 50.0, 0.5))
        for c in grid.free_cells(layer=0):
            ph.move(1, grid.centre(tuple(c)))
            assert obstacle_contacts(ph) == [], f"UGV at free cell {tuple(c)} touches an obstacle"
        # and the check is not vacuous: inside an obstacle both kinds touch it
        blocked = tuple(np.argwhere(grid.occupied)[0])
        for vid in (0, 1):
            ph.move(vid, grid.centre(blocked))
            assert obstacle_contacts(ph), vid
            ph.move(vid, (-50.0, 50.0 * vid, 0.5))


def test_vehicles_in_neighbouring_cells_do_not_touch():
    world = build_world((6.0, 6.0, 6.0), 1.0, 0, (1.0, 1.0, 1.0), (1.0, 1.0, 1.0),
                        np.random.default_rng(0))
    grid = world.grid
    with Physics(world) as ph:
        ph.add_vehicle(0, True, grid.centre((2, 2, 0)))
        ph.add_vehicle(1, False, grid.centre((4, 4, 0)))
        assert ph.contacts() == []
        for d in itertools.product((-1, 0, 1), repeat=2):
            if d == (0, 0):
                continue
            ph.move(1, grid.centre((2 + d[0], 2 + d[1], 0)))
            assert ph.contacts() == [], d
        ph.move(1, grid.centre((2, 2, 0)))  # the same cell: they collide
        assert ph.contacts() == [(ph.vehicles[0], ph.vehicles[1])]
        assert ph.position(1) == pytest.approx(grid.centre((2, 2, 0)))


def test_close_is_idempotent():
    ph = Physics(tiny_world(0))
    ph.close()
    ph.close()
    assert ph.client is None
