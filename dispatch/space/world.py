"""The static world: a voxel occupancy grid and the obstacle boxes it was made from.

Cells are indexed ``(i, j, k)`` along x, y, z; cell ``(i, j, k)`` spans
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell) x [k*cell, (k+1)*cell)`` metres. Layer ``k = 0`` is
the ground layer, where UGVs drive. Obstacles are axis-aligned boxes standing on the ground,
aligned to cell boundaries, separated by at least one free cell so that the free space stays
passable between them.

The grid and box types (:class:`~dispatch.api.voxels.Grid`, :class:`~dispatch.api.voxels.Box`) are
:mod:`dispatch.api.voxels`'s, below this module, where the voxel space's parts (demand, motion,
drivers, reservations) read them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import ClassVar

import numpy as np

from dispatch.api import registry
from dispatch.api.space import Space
from dispatch.api.voxels import Box, Grid
from dispatch.errors import ScenarioError, WorldError
from dispatch.locations import Cell
from dispatch.streams import STREAM_WORLD, rng_for


@dataclass(frozen=True, eq=False)
class World(Space):
    """The voxel space of one run: size in metres, the grid, and the obstacle boxes.
    A location is a cell; its position is the cell's centre."""

    kind: ClassVar[str] = "voxel"
    default_planner: ClassVar[str] = "astar"
    start_z: ClassVar[float] = 0.0  # a start file's vehicles without z are on the ground

    size: tuple[float, float, float]
    grid: Grid
    boxes: tuple[Box, ...]

    @property
    def cell(self) -> float:
        return self.grid.cell

    def position(self, loc: Cell) -> tuple[float, float, float]:
        return self.grid.centre(loc)

    def positions(self, locs) -> np.ndarray:
        return (np.asarray(locs, dtype=float).reshape(len(locs), 3) + 0.5) * self.grid.cell

    def describe(self) -> dict[str, str]:
        return {"dispatch.space": "voxel", "dispatch.world_size": json.dumps(list(self.size)),
                "dispatch.cell": str(self.cell)}

    # ------------------------------------------------------------ of its configuration
    @classmethod
    def load(cls, cfg, seed: int, scenario_path=None) -> World:
        return world_for(cfg, seed)

    @classmethod
    def label(cls, cfg) -> str:
        return f"world {cfg.shape}, {cfg.obstacles.count} obstacles"

    @classmethod
    def trace_bounds(cls, cfg) -> tuple[float, float, float]:
        return cfg.size

    @classmethod
    def check_size(cls, cfg, limits, refuse) -> None:
        cells = math.prod(cfg.shape)
        if cells > limits.cells:
            raise refuse("world.cell", f"the world has {cells:,} cells {cfg.shape} (more than "
                                       f"{limits.cells:,})")

    @classmethod
    def check_fleet(cls, sc, agents: int, key: str) -> None:
        """Vehicles start in distinct free cells: the fleet must fit beside the largest
        obstacles."""
        nx, ny, _ = sc.world.shape
        o = sc.world.obstacles
        cover = o.count * round(o.max_size[0] / sc.world.cell) * round(o.max_size[1]
                                                                       / sc.world.cell)
        if agents > max(nx * ny - cover, 0):
            raise ScenarioError(sc.path, key,
                                f"{agents} vehicles may not find distinct free cells in the world")

    @classmethod
    def work_cells(cls, cfg) -> int:
        return math.prod(cfg.shape)

    @classmethod
    def check_runs(cls, sc, planners) -> None:
        if sc.tasks.trips is not None and sc.tasks.trips.dest is not None \
                and any(registry.load("planner", p).reservation_aware for p in planners):
            raise ScenarioError(sc.path, "tasks.trace", "trips with drop-offs are not supported "
                                                        "with reservation-based execution yet")

    @classmethod
    def small(cls, seed: int = 0) -> World:
        """A 12 x 12 x 6 m world of 1 m cells with 4 obstacles."""
        return build_world((12.0, 12.0, 6.0), 1.0, 4, (1.0, 1.0, 1.0), (3.0, 3.0, 6.0),
                           np.random.default_rng(seed))

    # ------------------------------------------------------------ once built
    def driver(self, planner, bus, cfg, clock):
        from dispatch.space.drivers import CellDriver

        return CellDriver(self, planner, bus)

    def tables(self) -> dict[str, tuple[dict[str, str], list[dict]]]:
        meta = {"dispatch.world_size": json.dumps(list(self.size), sort_keys=True),
                "dispatch.cell": str(self.cell)}
        rows = [dict(x0=b.x0, y0=b.y0, z0=b.z0, x1=b.x1, y1=b.y1, z1=b.z1) for b in self.boxes]
        return {"obstacles": (meta, rows)}

    def reaches(self, path, start, goal) -> bool:
        return path[0] == start and path[-1] == goal


@lru_cache(maxsize=8)
def world_for(cfg, seed: int) -> World:
    """The voxel world of a ``[world]`` configuration and a seed. Cached: runs that share it
    (other allocators, other fleet sizes) also share everything planners cache on its
    immutable grid."""
    o = cfg.obstacles
    return build_world(cfg.size, cfg.cell, o.count, o.min_size, o.max_size,
                       rng_for(seed, STREAM_WORLD))


def place_obstacles(
    shape: tuple[int, int, int],
    count: int,
    min_cells: tuple[int, int, int],
    max_cells: tuple[int, int, int],
    rng: np.random.Generator,
    *,
    max_tries: int = 2_000,
    max_restarts: int = 50,
) -> list[tuple[int, int, int, int, int, int]]:
    """Draw ``count`` ground-standing boxes in cell units, ``(i0, j0, 0, i1, j1, k1)`` exclusive.

    Sizes are uniform integers in ``[min_cells, max_cells]``; footprints are kept one free cell
    apart (and may touch the world's border). A layout that gets stuck is drawn again, up to
    ``max_restarts`` times; then :class:`WorldError`.
    """
    nx, ny, nz = shape
    for _attempt in range(max_restarts):
        taken = np.zeros((nx, ny), dtype=bool)  # footprints grown by the one-cell margin
        boxes: list[tuple[int, int, int, int, int, int]] = []
        tries = 0
        while len(boxes) < count and tries < max_tries:
            tries += 1
            w = int(rng.integers(min_cells[0], max_cells[0] + 1))
            d = int(rng.integers(min_cells[1], max_cells[1] + 1))
            h = int(rng.integers(min_cells[2], max_cells[2] + 1))
            i0 = int(rng.integers(0, nx - w + 1))
            j0 = int(rng.integers(0, ny - d + 1))
            if taken[i0 : i0 + w, j0 : j0 + d].any():
                continue
            taken[max(i0 - 1, 0) : i0 + w + 1, max(j0 - 1, 0) : j0 + d + 1] = True
            boxes.append((i0, j0, 0, i0 + w, j0 + d, min(h, nz)))
        if len(boxes) == count:
            return boxes
        # A crowded early layout can leave no room; start over rather than fail the seed.
    raise WorldError(
        f"could not place {count} obstacles in a {nx}x{ny} ground in {max_restarts} layouts "
        f"of {max_tries} tries; use fewer or smaller obstacles"
    )


def build_world(
    size: tuple[float, float, float],
    cell: float,
    count: int,
    min_size: tuple[float, float, float],
    max_size: tuple[float, float, float],
    rng: np.random.Generator,
) -> World:
    """Build the world's grid and obstacle boxes; every random draw comes from ``rng``."""
    shape = tuple(int(round(s / cell)) for s in size)
    min_cells = tuple(max(1, int(round(s / cell))) for s in min_size)
    max_cells = tuple(max(1, int(round(s / cell))) for s in max_size)
    occupied = np.zeros(shape, dtype=bool)
    boxes = []
    for i0, j0, k0, i1, j1, k1 in place_obstacles(shape, count, min_cells, max_cells, rng):
        occupied[i0:i1, j0:j1, k0:k1] = True
        boxes.append(Box(i0 * cell, j0 * cell, k0 * cell, i1 * cell, j1 * cell, k1 * cell))
    return World(size=tuple(float(s) for s in size), grid=Grid(occupied, float(cell)),
                  boxes=tuple(boxes))
