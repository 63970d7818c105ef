"""PyBullet mirror of a run: obstacle boxes and one kinematic body per vehicle.

The simulation's truth is the grid and SimPy time; PyBullet mirrors it so that collisions can
be checked, rays cast (sampling planners) and images rendered. The client runs in DIRECT mode
(headless) unless ``gui=True``. A run in a voxel world builds its mirror with
:func:`mirror_of`, which reads the world's ``boxes`` and ``cell`` and so imports nothing of it.

The bodies are drawn as :mod:`analysis.render` draws a run's pictures, by
:mod:`paired.voxel_bodies` (shared by both; neither imports the other).
"""

from __future__ import annotations

import contextlib

from paired.voxel_bodies import (OBSTACLE_RGBA, UAV_RADIUS, UGV_HALF, box_body,
                                  connect_direct, import_pybullet, vehicle_body)


class Physics:
    """A PyBullet client holding the world's obstacles and the vehicles' bodies (``world``: a
    :class:`dispatch.space.world.World`)."""

    def __init__(self, world, gui: bool = False) -> None:
        self.p = p = import_pybullet()
        self.world = world
        self.client = connect_direct(p, gui)
        self.obstacles: list[int] = [
            box_body(p, self.client, box.centre(), box.half_extents(), OBSTACLE_RGBA, solid=True)
            for box in world.boxes]
        self.vehicles: dict[int, int] = {}

    def add_vehicle(self, agent_id: int, flies: bool, position) -> int:
        """Create a vehicle's body at ``position`` (metres); returns the body id."""
        s = self.world.cell
        body = vehicle_body(self.p, self.client, flies, position, radius=UAV_RADIUS * s,
                            half=tuple(h * s for h in UGV_HALF), solid=True)
        self.vehicles[agent_id] = body
        return body

    def move(self, agent_id: int, position) -> None:
        """Put a vehicle's body at ``position`` (metres)."""
        self.p.resetBasePositionAndOrientation(
            self.vehicles[agent_id], position, (0, 0, 0, 1), physicsClientId=self.client
        )

    def position(self, agent_id: int) -> tuple[float, float, float]:
        pos, _ = self.p.getBasePositionAndOrientation(self.vehicles[agent_id],
                                                      physicsClientId=self.client)
        return tuple(pos)  # type: ignore[return-value]

    def contacts(self, margin: float = 0.0) -> list[tuple[int, int]]:
        """Pairs of bodies (vehicle-obstacle or vehicle-vehicle) closer than ``margin`` metres."""
        p, c = self.p, self.client
        bodies = list(self.vehicles.values())
        out = []
        for i, a in enumerate(bodies):
            for b in bodies[i + 1 :] + self.obstacles:
                if p.getClosestPoints(a, b, margin, physicsClientId=c):
                    out.append((a, b))
        return out

    def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.p.disconnect(physicsClientId=self.client)
            self.client = None

    def __enter__(self) -> Physics:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def mirror_of(world, bus, vehicles) -> Physics:
    """The PyBullet mirror of a run in a voxel ``world`` (``[world] physics``; a road network
    has none, which the scenario checks refuse): a :class:`Physics` that follows ``bus``."""
    physics = Physics(world)
    mirror(physics, bus, world, vehicles)
    return physics


def mirror(physics: Physics, bus, space, vehicles) -> None:
    """Make ``physics`` a subscriber of the run's event stream: a body per vehicle at its start,
    moved to the cell of every ``move`` event. Nothing in the run reads it back; it is there for
    contact checks, ray casts and pictures."""
    for v in vehicles:
        physics.add_vehicle(v.id, v.flies, space.position(v.loc))
    bus.subscribe(lambda e: physics.move(e.agent_id, space.position(e.loc)), ("move",))
