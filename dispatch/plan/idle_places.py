"""The idle vehicles by place: a grid of buckets that a decision searches nearest first.

A one-request decision that takes the least cost of a column (:mod:`dispatch.decide.nearest`)
visits the idle vehicles in order of a lower bound of their cost, the straight line from
where they stand to the pickup, and stops once no vehicle left can be cheaper; so it must
find the idle vehicles near a place without a pass over the fleet. :class:`IdlePlaces` keeps
them in square cells of the plane, by the node each stands on (or stopped part-way towards),
kept up to date by the fleet as a vehicle goes idle or busy, starts or ends a drive, or
moves (:meth:`dispatch.plan.vehicles.Fleet.place`). An idle vehicle that is driving (a
repositioning move) has no fixed place: it is kept apart, in :attr:`IdlePlaces.moving`, and
a decision costs it always.

:meth:`IdlePlaces.rings` yields the vehicles ring by ring around a point, each ring with the
distance that every vehicle of the later rings is at least away, so a search may stop as
soon as that distance rules them out.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

#: Idle vehicles per cell the grid is sized for (a fleet all idle): a search for the nearest
#: reads a ring or two of cells.
PER_CELL = 2
#: The most cells on a side of the grid.
MOST_SIDE = 1024

#: the key of a vehicle that is not idle (not in the index)
NOT_IDLE = -1
#: the key of an idle vehicle that is driving (in :attr:`IdlePlaces.moving`)
MOVING = -2


class IdlePlaces:
    """The idle vehicles of a fleet of ``n`` positions in square cells of the plane, by the
    node each stands on; ``xy``: the ``(nodes, 2)`` metres of the space's nodes.

    ``moving`` holds the idle vehicles that are driving (their place changes with the
    clock). Positions are the fleet's (``Vehicle._slot``)."""

    def __init__(self, xy: np.ndarray, n: int) -> None:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        #: the ``(nodes, 2)`` metres of the space's nodes
        self.xy = xy
        lo = xy.min(axis=0) if xy.size else np.zeros(2)
        extent = float((xy.max(axis=0) - lo).max()) if xy.size else 0.0
        side = max(1, min(MOST_SIDE, math.ceil(math.sqrt(max(n, 1) / PER_CELL))))
        #: metres of a cell's side
        self.size = extent / side if extent > 0 else 1.0
        ij = np.floor((xy - lo) / self.size).astype(np.int64) if xy.size \
            else np.zeros((0, 2), np.int64)
        self._lo = lo
        self._w = int(ij[:, 0].max()) + 1 if xy.size else 1
        self._h = int(ij[:, 1].max()) + 1 if xy.size else 1
        #: each node's cell key (``i * height + j``)
        self.cell_of_node = (ij[:, 0] * self._h + ij[:, 1]).tolist()
        self._cells: dict[int, set[int]] = {}
        #: each fleet position's key: a cell, :data:`NOT_IDLE` or :data:`MOVING`
        self.key = [NOT_IDLE] * n
        #: the idle vehicles that are driving
        self.moving: set[int] = set()

    def put(self, slot: int, key: int) -> None:
        """Vehicle ``slot`` is now at ``key`` (a cell of :attr:`cell_of_node`, :data:`NOT_IDLE`
        or :data:`MOVING`)."""
        old = self.key[slot]
        if old == key:
            return
        if old >= 0:
            cell = self._cells[old]
            cell.discard(slot)
            if not cell:
                del self._cells[old]
        elif old == MOVING:
            self.moving.discard(slot)
        if key >= 0:
            cell = self._cells.get(key)
            if cell is None:
                self._cells[key] = {slot}
            else:
                cell.add(slot)
        elif key == MOVING:
            self.moving.add(slot)
        self.key[slot] = key

    def standing(self) -> list[int]:
        """Every idle vehicle that stands (not driving), in no particular order."""
        return [s for cell in self._cells.values() for s in cell]

    def rings(self, x: float, y: float) -> Iterator[tuple[list[int], float]]:
        """``(slots, beyond)`` ring by ring around the point ``(x, y)``: the standing idle
        vehicles of the cells ``r`` cells away (``r`` = 0, 1, ...; in no particular order
        within a ring), and the metres that every vehicle of a later ring stands at least
        away from the point (``inf`` after the last ring)."""
        size, w, h = self.size, self._w, self._h
        ci = min(max(math.floor((x - self._lo[0]) / size), 0), w - 1)
        cj = min(max(math.floor((y - self._lo[1]) / size), 0), h - 1)
        last = max(ci, w - 1 - ci, cj, h - 1 - cj)
        cells = self._cells
        for r in range(last + 1):
            got: list[int] = []
            if len(cells):
                i0, i1, j0, j1 = ci - r, ci + r, cj - r, cj + r
                for i in range(max(i0, 0), min(i1, w - 1) + 1):
                    edge = i in (i0, i1)
                    # a column on the ring's side: all its cells; else its two ends
                    js = range(max(j0, 0), min(j1, h - 1) + 1) if edge else \
                        [j for j in (j0, j1) if 0 <= j < h]
                    for j in js:
                        cell = cells.get(i * h + j)
                        if cell:
                            got.extend(cell)
            # a cell r + 1 or more away lies beyond r whole cells from any point of the
            # centre cell (a point off the grid is further still from the cells past it)
            yield got, (r * size if r < last else math.inf)
