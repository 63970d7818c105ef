"""The static world: a voxel occupancy grid and the obstacle boxes it was made from.

Cells are indexed ``(i, j, k)`` along x, y, z; cell ``(i, j, k)`` spans
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell) x [k*cell, (k+1)*cell)`` metres. Layer ``k = 0`` is
the ground layer, where UGVs drive. Obstacles are axis-aligned boxes standing on the ground,
aligned to cell boundaries, separated by at least one free cell so that the free space stays
passable between them.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np

from dispatch.errors import WorldError
from dispatch.space import Space

Cell = tuple[int, int, int]


@dataclass(frozen=True)
class Box:
    """An axis-aligned obstacle box in metres, ``(x0, y0, z0)`` to ``(x1, y1, z1)``."""

    x0: float
    y0: float
    z0: float
    x1: float
    y1: float
    z1: float

    def centre(self) -> tuple[float, float, float]:
        return ((self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2, (self.z0 + self.z1) / 2)

    def half_extents(self) -> tuple[float, float, float]:
        return ((self.x1 - self.x0) / 2, (self.y1 - self.y0) / 2, (self.z1 - self.z0) / 2)


@dataclass(frozen=True, eq=False)
class Grid:
    """A voxel occupancy grid. ``occupied[i, j, k]`` is True where an obstacle fills the cell.

    The array is made read-only on construction; a grid never changes after it is built, so
    anything derived from it (graphs, distance fields) may be cached on it.
    """

    occupied: np.ndarray
    cell: float
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.occupied.ndim != 3 or self.occupied.dtype != bool:
            raise ValueError("occupied must be a 3-D boolean array")
        self.occupied.setflags(write=False)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.occupied.shape)  # type: ignore[return-value]

    @cached_property
    def fingerprint(self) -> str:
        """A hash of the occupancy and cell size: equal grids have equal fingerprints."""
        h = hashlib.sha1(np.packbits(self.occupied).tobytes())
        h.update(repr((self.shape, self.cell)).encode())
        return h.hexdigest()

    def in_bounds(self, c: Cell) -> bool:
        return all(0 <= c[a] < self.occupied.shape[a] for a in range(3))

    def is_free(self, c: Cell) -> bool:
        return self.in_bounds(c) and not bool(self.occupied[c])

    def cell_of(self, point) -> Cell:
        """The cell holding a point given in metres."""
        return tuple(int(np.floor(float(p) / self.cell)) for p in point)  # type: ignore[return-value]

    def centre(self, c: Cell) -> tuple[float, float, float]:
        """The centre of a cell, in metres."""
        return tuple((float(v) + 0.5) * self.cell for v in c)  # type: ignore[return-value]

    def free_cells(self, layer: int | None = None) -> np.ndarray:
        """Free cells as an ``(n, 3)`` int array, in C order; only layer ``k`` if given."""
        cells = np.argwhere(~self.occupied)
        if layer is not None:
            cells = cells[cells[:, 2] == layer]
        return cells


@dataclass(frozen=True, eq=False)
class World(Space):
    """The voxel space of one run: size in metres, the grid, and the obstacle boxes.
    A location is a cell; its position is the cell's centre."""

    kind: ClassVar[str] = "voxel"

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


def place_obstacles(
    shape: tuple[int, int, int],
    count: int,
    min_cells: tuple[int, int, int],
    max_cells: tuple[int, int, int],
    rng: np.random.Generator,
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
