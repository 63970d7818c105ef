"""The voxel world's bodies, drawn once for the simulation's PyBullet mirror
(:mod:`dispatch.space.physics`) and the pictures of a run (:mod:`analysis.render`): PyBullet
imported and connected quietly (:func:`import_pybullet`, :func:`connect_direct`), a box
(:func:`box_body`), a vehicle's body (:func:`vehicle_body`) and their colours. PyBullet is
imported when first asked for, so importing this module costs nothing."""

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
