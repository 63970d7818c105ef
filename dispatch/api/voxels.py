"""The voxel grid's small types: obstacle boxes and the occupancy grid.

They stand below the voxel space (:class:`dispatch.space.world.World`) and below its parts (demand,
motion, drivers, reservations, planners), which all read the grid and none of which needs the
space. Cells are indexed ``(i, j, k)`` along x, y, z; cell ``(i, j, k)`` spans
``[i*cell, (i+1)*cell) x [j*cell, (j+1)*cell) x [k*cell, (k+1)*cell)`` metres.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from dispatch.locations import Cell

__all__ = ["Box", "Grid"]


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
