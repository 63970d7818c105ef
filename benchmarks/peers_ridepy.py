"""``benchmarks/peers.py``'s runner for RidePy (run by ``benchmarks/.peers-venv``'s Python).

``python benchmarks/peers_ridepy.py WORKLOAD_DIR OUT.json``. RidePy's Cython core: the
``Manhattan2D`` space in units of blocks (intersections at integer ``(column, row)``, driven at
``speed / block`` blocks per second: travel times are the project grid's shortest paths; RidePy's
``Grid2D`` wraps this same C++ class, and its C++ core ignores ``Grid2D``'s ``dn``/``dm``, so a
grid in metres there would be wrong), the
``BruteForceTotalTravelTimeMinimizingDispatcher`` (every request is inserted at once into the
stoplist of the vehicle where it adds the least total travel time, a busy vehicle's queue
included), seat capacity 1, no time windows (nothing is rejected), cut off at the workload's end.

Wall time: building the fleet and exhausting ``FleetState.simulate`` (imports and the metrics
excluded). Vehicle km is RidePy's own ``total_dist_driven`` definition (sum of the distances
between consecutive serviced stops of each vehicle), computed here without pandas.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from peers_workload import metrics, read, save_pickups


def main(folder: Path, out: Path) -> None:
    from ridepy.data_structures_cython import TransportationRequest
    from ridepy.fleet_state import SlowSimpleFleetState
    from ridepy.util.dispatchers_cython import BruteForceTotalTravelTimeMinimizingDispatcher
    from ridepy.util.spaces_cython import Manhattan2D
    from ridepy.vehicle_state_cython import VehicleState

    w, t, origin, dest, start = read(folder)
    ox, oy = w.node_xy(origin)
    dx, dy = w.node_xy(dest)
    sx, sy = w.node_xy(start)
    origins = list(zip(ox.astype(float).tolist(), oy.astype(float).tolist()))
    dests = list(zip(dx.astype(float).tolist(), dy.astype(float).tolist()))
    starts = {i: (float(x), float(y)) for i, (x, y) in enumerate(zip(sx, sy))}

    t0, c0 = time.perf_counter(), time.process_time()
    space = Manhattan2D(velocity=w.speed / w.block)
    fleet = SlowSimpleFleetState(
        initial_locations=starts, seat_capacities=1, space=space,
        dispatcher=BruteForceTotalTravelTimeMinimizingDispatcher(space.loc_type),
        vehicle_state_class=VehicleState)
    requests = (TransportationRequest(request_id=i, creation_timestamp=float(t[i]),
                                      origin=origins[i], destination=dests[i])
                for i in range(t.size))
    events = list(fleet.simulate(requests, t_cutoff=w.end))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0

    picked = np.full(t.size, np.nan)
    completed = np.full(t.size, np.nan)
    vehicle = np.full(t.size, -1)
    here = {v: starts[v] for v in starts}
    metres = 0.0
    for ev in events:
        kind = ev["event_type"]
        if kind == "PickupEvent" or kind == "DeliveryEvent":
            r, v = ev["request_id"], ev["vehicle_id"]
            loc = origins[r] if kind == "PickupEvent" else dests[r]
            (picked if kind == "PickupEvent" else completed)[r] = ev["timestamp"]
            if kind == "PickupEvent":
                vehicle[r] = v
            metres += (abs(loc[0] - here[v][0]) + abs(loc[1] - here[v][1])) * w.block
            here[v] = loc
    row = metrics(t, picked, completed, metres)
    row.update(wall_s=wall, cpu_s=cpu,
               rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    save_pickups(out.with_suffix(".npz"), t, picked, vehicle)
    out.write_text(json.dumps(row))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
