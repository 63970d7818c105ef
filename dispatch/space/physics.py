"""PyBullet mirror of a run: obstacle boxes and one kinematic body per vehicle.

The simulation's truth is the grid and SimPy time; PyBullet mirrors it so that collisions can
be checked, rays cast (sampling planners) and images rendered. The client runs in DIRECT mode
(headless) unless ``gui=True``. A run in a voxel world builds its mirror with
:func:`mirror_of`, which reads the world's ``boxes`` and ``cell`` and so imports nothing of it.

The voxel world is drawn here once: PyBullet imported and connected quietly
(:func:`import_pybullet`, :func:`connect_direct`), a box (:func:`box_body`), a vehicle's body
(:func:`vehicle_body`) and their colours; :mod:`analysis.render` draws a run's pictures with
them.
"""

from __future__ import annotations

import contextlib
import ctypes
import os

UAV_RADIUS = 0.3  # of a cell: a vehicle body fits well inside its cell
UGV_HALF = (0.35, 0.35, 0.25)
#: colours (RGBA) of an obstacle, a UAV and a UGV
OBSTACLE_RGBA = (0.55, 0.55, 0.6, 1)
UAV_RGBA = (0.1, 0.4, 0.9, 1)
UGV_RGBA = (0.9, 0.5, 0.1, 1)


@contextlib.contextmanager
def quiet_c_output(fds: tuple[int, ...] = (1, 2)):
    """Inside the block, what C code writes to stdout and stderr (file descriptors 1 and 2)
    goes to the null device: PyBullet prints its build banner (``pybullet build time: ...``)
    with ``printf`` at import, to stdout or stderr depending on the build, and may print at
    ``connect``. Python's own buffered output is flushed before and C's after, so nothing of
    either is lost or reordered; a descriptor that is closed is left alone."""
    import sys

    def c_flush() -> None:
        with contextlib.suppress(Exception):
            ctypes.CDLL(None).fflush(None)

    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    c_flush()
    saved = {}
    for fd in fds:
        with contextlib.suppress(OSError):
            saved[fd] = os.dup(fd)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in saved:
            os.dup2(null, fd)
        yield
    finally:
        c_flush()
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def import_pybullet():
    """The pybullet module, imported without its build-time banner (see
    :func:`quiet_c_output`)."""
    with quiet_c_output():
        import pybullet
    return pybullet


def connect_direct(p, gui: bool = False) -> int:
    """``p.connect(DIRECT)`` (or GUI) without what the C library prints on connecting."""
    with quiet_c_output():
        return p.connect(p.GUI if gui else p.DIRECT)


def box_body(p, client: int, centre, half, rgba, *, solid: bool = False) -> int:
    """A fixed box of ``half`` extents around ``centre`` (metres) in colour ``rgba``;
    ``solid``: with a collision shape (contacts, rays), else drawn only."""
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client) \
        if solid else -1
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=rgba,
                              physicsClientId=client)
    return p.createMultiBody(0, col, vis, basePosition=centre, physicsClientId=client)


def vehicle_body(p, client: int, flies: bool, position, *, radius: float, half,
                 solid: bool = False) -> int:
    """A vehicle's body at ``position`` (metres): a UAV a sphere of ``radius``, a UGV a box of
    ``half`` extents, in their colours; ``solid``: with a collision shape, else drawn only."""
    if flies:
        col = p.createCollisionShape(p.GEOM_SPHERE, radius=radius, physicsClientId=client) \
            if solid else -1
        vis = p.createVisualShape(p.GEOM_SPHERE, radius=radius, rgbaColor=UAV_RGBA,
                                  physicsClientId=client)
    else:
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client) \
            if solid else -1
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=UGV_RGBA,
                                  physicsClientId=client)
    return p.createMultiBody(0, col, vis, basePosition=position, physicsClientId=client)


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
