"""Where the fleet starts: at random (seeded), or where a start file puts it.

:func:`place_fleet` places a run's fleet in its space with the function of the space's kind
(:data:`PLACERS`; the space itself answers only where things are). Voxel world
(:func:`place_voxel`): UAVs (the first ``n_uav`` vehicles) in free
cells at or below the start altitude, UGVs in free ground cells, no two in one cell. Road
network (:func:`place_cars`): cars on nodes drawn uniformly
(several may share one, as taxis share a rank), or with ``[fleet] placement = "demand"`` on the
empirical sample's pickup nodes, each drawn with its share of the trips. A start file
(``[fleet] start``) gives each vehicle's id and node or position (snapped to the nearest node
on roads).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from dispatch.api.space import Space
from dispatch.config.scenario import RunSpec
from dispatch.errors import ScenarioError
from dispatch.files.empirical import load_sample, pickup_weights
from dispatch.plan.vehicles import Vehicle


def place_fleet(space: Space, spec: RunSpec, rng: np.random.Generator) -> list[Vehicle]:
    """The run's vehicles at their start locations (:data:`PLACERS` of the space's kind; random
    draws from ``rng``), with their seats (``[fleet] capacity``, or a start file's
    ``capacity`` column)."""
    vehicles = PLACERS[space.kind](space, spec, rng)
    fleet = spec.fleet
    if fleet.capacity != 1 or fleet.capacities:
        seats = fleet.capacities
        for k, v in enumerate(vehicles):  # start-file rows are in the vehicles' order
            v.capacity = seats[k] if k < len(seats) and seats[k] else fleet.capacity
    return vehicles


def place_cars(net, spec: RunSpec, rng: np.random.Generator) -> list[Vehicle]:
    """Road network: cars on nodes (see the module docstring)."""
    fleet = spec.fleet
    rows = fleet.start[: fleet.agents]
    # a car's speed is informational (costs are the network's travel times): its mean speed
    speed = float(net.length.data.sum() / net.time.data.sum())
    if not rows and fleet.placement == "demand":
        ids, p = pickup_weights(load_sample(), spec.scenario.tasks.weekday)
        nodes = [net.index_of(int(i)) for i in rng.choice(ids, size=fleet.agents, p=p)]
        return [Vehicle(i, "car", speed, int(n)) for i, n in enumerate(nodes)]
    if not rows:
        nodes = rng.integers(net.n, size=fleet.agents)
        return [Vehicle(i, "car", speed, int(n)) for i, n in enumerate(nodes)]
    out = []
    for i, (vid, a, b, _) in enumerate(rows, 1):
        if math.isnan(b):
            try:
                node = net.index_of(int(a))
            except ValueError as e:
                raise ScenarioError(fleet.start_file, f"row {i}", str(e)) from None
        else:
            node = int(net.nearest(np.array([[a, b]]))[0][0])
        out.append(Vehicle(vid, "car", speed, node))
    return out


def place_voxel(world, spec: RunSpec, rng: np.random.Generator) -> list[Vehicle]:
    """:func:`place_fleet` places a run's fleet in its space with the function of the space's kind
(:data:`PLACERS`; the space itself answers only where things are). Voxel world: UAVs and UGVs in
distinct free cells (see the module docstring)."""
    fleet, grid = spec.fleet, world.grid
    rows = fleet.start[: fleet.agents]
    taken: set = set()
    vehicles = []
    if rows:
        for i, (vid, x, y, z) in enumerate(rows):
            flies = i < fleet.n_uav
            cell = grid.cell_of((x, y, z))
            why = ("is outside the world" if not grid.in_bounds(cell) else
                   "is inside an obstacle" if not grid.is_free(cell) else
                   "is above the ground layer for a UGV" if not flies and cell[2] != 0 else
                   "is taken by another vehicle" if cell in taken else None)
            if why:
                raise ScenarioError(fleet.start_file, f"row {i + 1}",
                                    f"vehicle {vid} at ({x}, {y}, {z}) {why}")
            taken.add(cell)
            vehicles.append(Vehicle(vid, "uav" if flies else "ugv",
                                    fleet.uav_speed if flies else fleet.ugv_speed, cell))
        return vehicles
    free = grid.free_cells()
    max_k = int(math.floor(fleet.uav_max_start_altitude / grid.cell + 1e-9))
    air_pool = free[free[:, 2] <= max_k]
    for i in range(fleet.agents):
        flies = i < fleet.n_uav
        pool = air_pool if flies else free[free[:, 2] == 0]
        while True:
            c = pool[rng.integers(len(pool))]
            cell = (int(c[0]), int(c[1]), int(c[2]))
            if cell not in taken:
                break
        taken.add(cell)
        vehicles.append(Vehicle(i, "uav" if flies else "ugv",
                                fleet.uav_speed if flies else fleet.ugv_speed, cell))
    return vehicles


#: how each space kind places a fleet: ``(space, run, generator) -> vehicles``, seats aside
PLACERS: dict[str, Callable[[Space, RunSpec, np.random.Generator], list[Vehicle]]] = {
    "voxel": place_voxel, "road": place_cars}
