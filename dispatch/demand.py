"""Where tasks come from in each space: generated draws and trace conversion.

* :class:`VoxelDemand`: the paper's point tasks, on the ground layer with probability
  ``ground_fraction`` (``ground`` tasks, any vehicle) or in the free cells above (``air``, UAVs
  only); a trace gives positions in metres (and, optionally, drop-offs).
* :class:`RoadDemand`: trips between network nodes, origin and destination uniform over the
  nodes with destination != origin; a trace gives node ids, metres or latitude / longitude,
  positions snapped to the nearest node (the snapping distance is kept per trip).

Every draw comes from the generator the demand is given.
"""

from __future__ import annotations

import math

import numpy as np

from dispatch.errors import ScenarioError
from dispatch.tasks import Demand, Request
from dispatch.traces import Trips
from dispatch.voxels import Grid


class VoxelDemand(Demand):
    def __init__(self, grid: Grid, ground_fraction: float, rng: np.random.Generator) -> None:
        free = grid.free_cells()
        self.grid = grid
        self.ground = free[free[:, 2] == 0]
        self.air = free[free[:, 2] > 0]
        self.ground_fraction = ground_fraction
        self.rng = rng

    def draw(self) -> Request:
        on_ground = self.rng.random() < self.ground_fraction or len(self.air) == 0
        pool = self.ground if on_ground else self.air
        c = pool[self.rng.integers(len(pool))]
        return Request("ground" if on_ground else "air", (int(c[0]), int(c[1]), int(c[2])))

    def from_trace(self, trips: Trips) -> list[Request]:
        out = []
        for i in range(len(trips)):
            cell = self.grid.cell_of(trips.origin[i])
            drop = None if trips.dest is None else self.grid.cell_of(trips.dest[i])
            kind = "ground" if cell[2] == 0 and (drop is None or drop[2] == 0) else "air"
            out.append(Request(kind, cell, drop, float(trips.max_wait[i]),
                               passengers=_int(trips.passengers, i),
                               max_delay=_float(trips.max_delay, i)))
        return out

    def valid(self, loc) -> bool:
        return self.grid.is_free(loc)


class RoadDemand(Demand):
    def __init__(self, network, rng: np.random.Generator) -> None:
        self.network, self.rng = network, rng

    def draw(self) -> Request:
        n = self.network.n
        o = int(self.rng.integers(n))
        d = int(self.rng.integers(n - 1))
        return Request("trip", o, d + (d >= o))  # uniform over the other nodes

    def from_trace(self, trips: Trips) -> list[Request]:
        net = self.network
        origin, snap_o = _nodes(net, trips, trips.origin)
        dest, snap_d = (None, None) if trips.dest is None else _nodes(net, trips, trips.dest)
        nan = math.nan
        return [Request("trip", int(origin[i]), None if dest is None else int(dest[i]),
                        float(trips.max_wait[i]), float(snap_o[i]),
                        nan if snap_d is None else float(snap_d[i]),
                        _int(trips.passengers, i), _float(trips.max_delay, i))
                for i in range(len(trips))]


def _int(column, i: int) -> int:
    return 1 if column is None else int(column[i])


def _float(column, i: int) -> float:
    return math.nan if column is None else float(column[i])


def _nodes(net, trips: Trips, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Node indices and snapping distances (metres; 0 for node ids) of a trace's columns."""
    if trips.layout == "node":
        idx = np.empty(len(cols), dtype=np.int64)
        for i, v in enumerate(cols[:, 0]):
            try:
                idx[i] = net.index_of(int(v))
            except ValueError as e:
                raise ScenarioError(trips.path, f"row {trips.row[i]}", str(e)) from None
        return idx, np.zeros(len(cols))
    if trips.layout == "metres":
        xy = cols[:, :2]
    else:  # latitude, longitude columns
        try:
            xy = net.lonlat_to_xy(cols[:, 1], cols[:, 0])
        except ValueError as e:
            raise ScenarioError(trips.path, "<file>", str(e)) from None
    return net.nearest(xy)


def trace_nodes_ok(net, trips: Trips) -> None:
    """Raise ScenarioError if a trace names a node the network lacks (validate-time check)."""
    if trips.layout == "node":
        _nodes(net, trips, trips.origin)
        if trips.dest is not None:
            _nodes(net, trips, trips.dest)
