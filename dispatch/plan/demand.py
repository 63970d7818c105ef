"""Where tasks come from in each space: generated draws and trace conversion.

* :class:`VoxelDemand`: the paper's point tasks, on the ground layer with probability
  ``ground_fraction`` (``ground`` tasks, any vehicle) or in the free cells above (``air``, UAVs
  only); a trace gives positions in metres (and, optionally, drop-offs).
* :class:`RoadDemand`: trips between network nodes, origin and destination uniform over the
  nodes with destination != origin; a trace gives node ids, metres or latitude / longitude,
  positions snapped to the nearest node (the snapping distance is kept per trip).

Every draw comes from the generator the demand is given. :func:`demand_for` builds a run's
demand from its space: each space kind of :data:`dispatch.api.space.KINDS` has its builder in
:data:`BUILDERS` (the space itself answers only where things are).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from dispatch.api.space import Space
from dispatch.api.voxels import Grid
from dispatch.config.tasks import TaskConfig
from dispatch.errors import ScenarioError
from dispatch.files.traces import Trips
from dispatch.plan.tasks import Demand, Request


class VoxelDemand(Demand):
    def __init__(self, grid: Grid, ground_fraction: float, rng: np.random.Generator) -> None:
        free = grid.free_cells()
        self.grid = grid
        self.ground = free[free[:, 2] == 0]
        self.air = free[free[:, 2] > 0]
        self.ground_fraction = ground_fraction
        self.rng = rng

    def draw(self, request_id: int | None = None) -> Request:
        on_ground = self.rng.random() < self.ground_fraction or len(self.air) == 0
        pool = self.ground if on_ground else self.air
        c = pool[self.rng.integers(len(pool))]
        return Request("ground" if on_ground else "air", (int(c[0]), int(c[1]), int(c[2])),
                       request_id=request_id)

    def from_trace(self, trips: Trips) -> Iterator[Request]:
        grid, dest = self.grid, trips.dest
        for i in range(len(trips)):
            cell = grid.cell_of(trips.origin[i])
            drop = None if dest is None else grid.cell_of(dest[i])
            kind = "ground" if cell[2] == 0 and (drop is None or drop[2] == 0) else "air"
            yield Request(kind, cell, drop, float(trips.max_wait[i]),
                          passengers=_int(trips.passengers, i),
                          max_delay=_float(trips.max_delay, i), request_id=_id(trips.ids, i))

    def valid(self, loc) -> bool:
        return self.grid.is_free(loc)


class RoadDemand(Demand):
    def __init__(self, network, rng: np.random.Generator) -> None:
        self.network, self.rng = network, rng

    def draw(self, request_id: int | None = None) -> Request:
        n = self.network.n
        o = int(self.rng.integers(n))
        d = int(self.rng.integers(n - 1))
        # uniform over the other nodes
        return Request("trip", o, d + (d >= o), request_id=request_id)

    def from_trace(self, trips: Trips) -> Iterator[Request]:
        net = self.network
        # every trip's nodes at once (a node the network lacks is an error now, not when the
        # clock reaches its row); the requests are made one by one as they are asked for
        origin, snap_o = _nodes(net, trips, trips.origin)
        dest, snap_d = (None, None) if trips.dest is None else _nodes(net, trips, trips.dest)
        return _road_requests(trips, origin, snap_o, dest, snap_d)


#: the demand of each space kind: ``(space, [tasks] configuration, generator) -> Demand``
BUILDERS: dict[str, Callable[[Space, TaskConfig, np.random.Generator], Demand]] = {
    "voxel": lambda world, tasks, rng: VoxelDemand(world.grid, tasks.ground_fraction, rng),
    "road": lambda net, tasks, rng: RoadDemand(net, rng),
}


def demand_for(space: Space, tasks: TaskConfig, rng: np.random.Generator) -> Demand:
    """The run's demand in ``space``: generated requests and a trace's trips as requests there
    (:class:`VoxelDemand`, :class:`RoadDemand`); every draw from ``rng``."""
    return BUILDERS[space.kind](space, tasks, rng)


def _road_requests(trips: Trips, origin: np.ndarray, snap_o: np.ndarray,
                   dest: np.ndarray | None, snap_d: np.ndarray | None) -> Iterator[Request]:
    nan = math.nan
    for i in range(len(trips)):
        yield Request("trip", int(origin[i]), None if dest is None else int(dest[i]),
                      float(trips.max_wait[i]), float(snap_o[i]),
                      nan if snap_d is None else float(snap_d[i]),
                      _int(trips.passengers, i), _float(trips.max_delay, i),
                      _float(trips.max_walk, i), _float(trips.walk_speed, i),
                      _id(trips.ids, i))


def _int(column, i: int) -> int:
    return 1 if column is None else int(column[i])


def _id(column, i: int) -> int | str | None:
    """Trip ``i``'s id, a Python int or str (None where the trips have none: the task's own
    id stands)."""
    if column is None:
        return None
    v = column[i]
    return int(v) if column.dtype.kind == "i" else v


def _float(column, i: int) -> float:
    return math.nan if column is None else float(column[i])


def _nodes(net, trips: Trips, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Node indices and snapping distances (metres; 0 for node ids) of a trace's columns."""
    if trips.layout == "node":
        ids, inverse = np.unique(cols[:, 0], return_inverse=True)
        known = np.empty(len(ids), dtype=np.int64)
        for k, v in enumerate(ids):  # each distinct id looked up once
            try:
                known[k] = net.index_of(int(v))
            except ValueError:
                known[k] = -1
        if (known < 0).any():
            i = int(np.flatnonzero(known[inverse] < 0)[0])  # the first trip naming one
            try:
                net.index_of(int(cols[i, 0]))
            except ValueError as e:
                raise ScenarioError(trips.path, f"row {trips.row[i]}", str(e)) from None
        return known[inverse.reshape(-1)], np.zeros(len(cols))
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
