"""``benchmarks/peers.py``'s runner for RidePy (run by ``benchmarks/.peers-venv``'s Python).

``python benchmarks/peers_ridepy.py WORKLOAD_DIR OUT.json [manhattan|grid]``. RidePy's Cython
core, the ``BruteForceTotalTravelTimeMinimizingDispatcher`` (every request is inserted at once
into the stoplist of the vehicle where it adds the least total travel time, a busy vehicle's
queue included; ties to the first vehicle, then to the first positions), the workload's seat
capacity (1 unless the workload says otherwise), cut off at the workload's end. Two spaces:

* ``manhattan`` (default): the ``Manhattan2D`` space in units of blocks (intersections at
  integer ``(column, row)``, driven at ``speed / block`` blocks per second: travel times
  between intersections are the project grid's shortest paths; RidePy's ``Grid2D`` wraps this
  same C++ class, and its C++ core ignores ``Grid2D``'s ``dn``/``dm``, so a grid in metres there
  would be wrong). Continuous: a vehicle re-routed between two stops is where the straight
  line between them has got to (RidePy's ``interp_dist``), usually inside a block, and turns
  there; the project's vehicles drive streets and finish the edge they are on.
* ``grid``: RidePy's ``Graph`` space (Boost's Dijkstra, cached per source) on the workload's
  intersections and two-way streets, ``block`` metres each (or the workload's jittered
  lengths). A vehicle re-routed between two stops goes on to the next intersection of its path
  first (``interp_dist``'s jump), as the project's do; only which of the equally short grid
  paths it drives may differ (none with jittered streets).

Requests: without limits in the workload, none (nothing is rejected); with them (shared rides,
``benchmarks/pooling.py``) ``pickup_timewindow_max`` = release + ``max_wait`` and
``delivery_timewindow_max`` = release + direct time + ``max_delay``; RidePy rejects a request
no vehicle can insert within them, at once.

Wall time: building the space and the fleet and exhausting ``FleetState.simulate`` (imports and
the metrics excluded). Vehicle km: metres actually driven. A RidePy vehicle drives at constant
speed whenever its stoplist holds a stop (no service times, time windows open at the release:
it never waits) and stands still otherwise, and a request stays with the vehicle it was
inserted into, so a vehicle drives exactly while one of its requests is between release
(insertion) and drop-off: vehicle metres = speed x the union of those intervals per vehicle
(a request inserted but not picked up by the cut-off has no known vehicle and is left out:
the workloads here serve every insertion). RidePy's own ``total_dist_driven`` (the distances
between consecutive serviced stops) misses the turns of re-routed vehicles: it is written as
``stop_km``. Passenger metres: speed x each ride's in-vehicle time. A ride is shared when
another request was on board during it (the stop events of each vehicle in order, as the
project marks it).
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from peers_workload import Workload, metrics, read, save_pickups


def grid_space(w: Workload):
    """RidePy's ``Graph`` space of the workload's grid (node ids as the project numbers them,
    each street its length in metres, driven at ``speed``)."""
    from ridepy.util.spaces_cython import Graph

    u, v, metres = w.streets()
    return Graph(list(range(w.nodes)), list(zip(u.tolist(), v.tolist())), metres.tolist(),
                 velocity=w.speed)


def driven_seconds(vehicle: np.ndarray, start: np.ndarray, stop: np.ndarray) -> float:
    """Total length of the union, per vehicle, of the intervals ``[start, stop]`` of the
    requests with that ``vehicle`` (``-1``: none, left out)."""
    total = 0.0
    keep = vehicle >= 0
    vehicle, start, stop = vehicle[keep], start[keep], stop[keep]
    order = np.lexsort((start, vehicle))
    last_v, lo, hi = -1, 0.0, 0.0
    for v, a, b in zip(vehicle[order].tolist(), start[order].tolist(), stop[order].tolist()):
        if v != last_v or a > hi:
            total += hi - lo
            last_v, lo, hi = v, a, b
        elif b > hi:
            hi = b
    return total + hi - lo


def main(folder: Path, out: Path, space_name: str = "manhattan") -> None:
    from ridepy.data_structures_cython import TransportationRequest
    from ridepy.fleet_state import SlowSimpleFleetState
    from ridepy.util.dispatchers_cython import BruteForceTotalTravelTimeMinimizingDispatcher
    from ridepy.util.spaces_cython import Manhattan2D
    from ridepy.vehicle_state_cython import VehicleState

    w, t, origin, dest, start = read(folder)
    if space_name == "grid":
        origins, dests = origin.tolist(), dest.tolist()
        starts = dict(enumerate(start.tolist()))
        block = 1.0  # Graph distances are metres
    elif space_name == "manhattan":
        ox, oy = w.node_xy(origin)
        dx, dy = w.node_xy(dest)
        sx, sy = w.node_xy(start)
        origins = list(zip(ox.astype(float).tolist(), oy.astype(float).tolist()))
        dests = list(zip(dx.astype(float).tolist(), dy.astype(float).tolist()))
        starts = {i: (float(x), float(y)) for i, (x, y) in enumerate(zip(sx, sy))}
        block = w.block  # Manhattan2D distances are blocks
    else:
        raise SystemExit(f"peers_ridepy: unknown space {space_name!r} (manhattan or grid)")
    if w.jitter and space_name != "grid":
        raise SystemExit("peers_ridepy: jittered streets need the grid space")
    limits = w.max_wait is not None or w.max_delay is not None
    late_p, late_d = (x.tolist() for x in w.latest(t, origin, dest))

    t0, c0 = time.perf_counter(), time.process_time()
    space = grid_space(w) if space_name == "grid" else Manhattan2D(velocity=w.speed / w.block)
    fleet = SlowSimpleFleetState(
        initial_locations=starts, seat_capacities=w.capacity, space=space,
        dispatcher=BruteForceTotalTravelTimeMinimizingDispatcher(space.loc_type),
        vehicle_state_class=VehicleState)
    if limits:
        requests = (TransportationRequest(request_id=i, creation_timestamp=float(t[i]),
                                          origin=origins[i], destination=dests[i],
                                          pickup_timewindow_max=late_p[i],
                                          delivery_timewindow_max=late_d[i])
                    for i in range(t.size))
    else:
        requests = (TransportationRequest(request_id=i, creation_timestamp=float(t[i]),
                                          origin=origins[i], destination=dests[i])
                    for i in range(t.size))
    events = list(fleet.simulate(requests, t_cutoff=w.end))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0

    picked = np.full(t.size, np.nan)
    completed = np.full(t.size, np.nan)
    vehicle = np.full(t.size, -1)
    shared = np.zeros(t.size, dtype=bool)
    aboard: dict[int, list[int]] = {v: [] for v in starts}
    here = dict(starts)
    stop_units = 0.0
    rejected = 0
    for ev in events:
        kind = ev["event_type"]
        if kind == "PickupEvent" or kind == "DeliveryEvent":
            r, v = ev["request_id"], ev["vehicle_id"]
            on = aboard[v]
            if kind == "PickupEvent":
                picked[r], vehicle[r] = ev["timestamp"], v
                if on:
                    shared[r] = True
                    shared[on] = True
                on.append(r)
                loc = origins[r]
            else:
                completed[r] = ev["timestamp"]
                on.remove(r)
                loc = dests[r]
            stop_units += space.d(here[v], loc)
            here[v] = loc
        elif kind == "RequestRejectionEvent":
            rejected += 1
    busy_until = np.where(np.isfinite(completed), completed, w.end)
    vehicle_m = driven_seconds(vehicle, t, busy_until) * w.speed
    ride = np.where(np.isfinite(completed), completed, w.end) - picked
    passenger_m = float(np.nansum(ride)) * w.speed
    rides = {}
    if w.capacity > 1 or w.max_delay is not None:
        rides = {"direct": w.direct(origin, dest), "shared": shared, "passenger_m": passenger_m}
    row = metrics(t, picked, completed, vehicle_m, **rides)
    row.update(wall_s=wall, cpu_s=cpu,
               rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               rejected=rejected, expired=0, stop_km=stop_units * block / 1000.0,
               space=space_name)
    save_pickups(out.with_suffix(".npz"), t, picked, vehicle)
    out.write_text(json.dumps(row))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), *sys.argv[3:])
