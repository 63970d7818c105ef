"""The bench's metrics of one run, read from its tables, and the columns of ``bench.csv``.

Every row has every column (NaN where a metric does not apply to the instance): robots'
columns are filled in voxel worlds and on the faults instance, fleets' on road networks, the
timing columns everywhere.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pyarrow as pa

from paired.per_task import number, ratio

#: The columns naming a row, then its status (``ok``, ``failed: …``, ``unsupported: …``)
KEYS = ("world", "instance", "allocator", "seed")
#: The metrics, in the order of ``bench.csv``; what each means: :data:`DESCRIPTIONS`
METRICS = ("requests", "decisions", "total_cost", "cost_per_assignment", "gap",
           "conflict_free_share", "alloc_ms_per_decision", "messages",
           "served_share", "wait_mean", "wait_p90", "delay_mean", "detour_ratio", "occupancy",
           "shared_share", "vehicle_km", "empty_km", "riders_per_vehicle_hour", "kwh_per_rider",
           "ms_per_decision", "ms_per_request", "wall_s")
COLUMNS = (*KEYS, "status", *METRICS)
#: Columns that measure the machine, not the allocator's answers: left out of the
#: determinism check and flagged by ``--against`` only with the rest
TIMING = ("alloc_ms_per_decision", "ms_per_decision", "ms_per_request", "wall_s")
#: Metrics where less is better (the others: more is better; ``requests`` and ``decisions``
#: describe the instance and are never marked best)
LOWER_IS_BETTER = frozenset({"total_cost", "cost_per_assignment", "gap", "messages",
                             "wait_mean", "wait_p90", "delay_mean", "detour_ratio",
                             "vehicle_km", "empty_km", "kwh_per_rider", *TIMING})
NOT_RANKED = frozenset({"requests", "decisions"})
#: The columns each group's board shows
BOARD = {"robots": ("gap", "cost_per_assignment", "served_share", "conflict_free_share",
                    "messages", "alloc_ms_per_decision", "ms_per_decision", "ms_per_request"),
         "fleets": ("served_share", "wait_mean", "wait_p90", "delay_mean", "detour_ratio",
                    "occupancy", "shared_share", "vehicle_km", "empty_km",
                    "riders_per_vehicle_hour", "kwh_per_rider", "ms_per_decision",
                    "ms_per_request")}

DESCRIPTIONS = {
    "requests": "tasks (requests) released",
    "decisions": "allocation decisions made",
    "total_cost": "sum of the planned costs of the assignments (s)",
    "cost_per_assignment": "total_cost / tasks assigned (s)",
    "gap": "cost_per_assignment relative to hungarian's run of the same seed; in the static "
           "instances hungarian's is the optimum, so this is the gap to the optimum",
    "conflict_free_share": "share of decisions' assignments without a conflict",
    "alloc_ms_per_decision": "wall ms in the allocator per decision (cost matrices excluded)",
    "messages": "messages sent by a decentralized allocator (0 for central ones)",
    "served_share": "tasks completed / released",
    "wait_mean": "release to pickup, s, mean over the tasks picked up",
    "wait_p90": "release to pickup, s, 90th percentile",
    "delay_mean": "drop-off - release - direct time, s, mean over completed trips",
    "detour_ratio": "in-vehicle time / direct time, mean over completed trips",
    "occupancy": "passenger-km / vehicle-km",
    "shared_share": "share of completed rides shared with another request",
    "vehicle_km": "km driven by the fleet",
    "empty_km": "km driven without a passenger",
    "riders_per_vehicle_hour": "riders delivered / (vehicles x simulated hours)",
    "kwh_per_rider": "kWh drawn by the fleet / riders delivered (electric instances)",
    "ms_per_decision": "wall ms per decision: cost matrices + allocator",
    "ms_per_request": "the same wall ms per request released",
    "wall_s": "wall seconds of the whole run (simulation, planning, recording)",
}


def run_metrics(summary: Mapping, tasks: pa.Table | None, vehicles: pa.Table | None,
                road: bool) -> dict[str, float]:
    """The :data:`METRICS` of one run (``gap`` NaN: it needs the reference's run, see
    :func:`bench.stats.fill_gaps`; ``wall_s`` NaN: the runner's). ``road``: a road network
    (the fleet columns apply)."""
    s = summary.get
    n_tasks = number(s("n_tasks"))
    decisions = number(s("decisions"))
    out = dict.fromkeys(METRICS, math.nan)
    out.update({
        "requests": n_tasks, "decisions": decisions,
        "total_cost": number(s("total_cost")),
        "cost_per_assignment": ratio(s("total_cost"), s("tasks_assigned")),
        "served_share": ratio(s("tasks_completed"), n_tasks),
        "wait_mean": number(s("wait_time_mean")),
        "conflict_free_share": number(s("conflict_free_rate")),
        "alloc_ms_per_decision": ratio(1000 * number(s("decide_seconds")), decisions),
        "messages": number(s("messages")),
        "ms_per_decision": ratio(1000 * number(s("alloc_seconds")), decisions),
        "ms_per_request": ratio(1000 * number(s("alloc_seconds")), n_tasks),
    })
    if tasks is not None and tasks.num_rows:
        released = tasks.column("released_at").to_numpy(zero_copy_only=False)
        picked = tasks.column("picked_up_at").to_numpy(zero_copy_only=False)
        waits = (picked - released)[np.isfinite(picked)]
        out["wait_p90"] = float(np.quantile(waits, 0.9)) if waits.size else math.nan
    if road:
        out.update({
            "delay_mean": number(s("delay_mean")), "detour_ratio": number(s("detour_ratio")),
            "occupancy": number(s("occupancy")), "shared_share": number(s("shared_rate")),
            "vehicle_km": number(s("distance")) / 1000.0,
            "empty_km": number(s("empty_distance")) / 1000.0,
        })
        riders = _riders(tasks)
        hours = number(s("n_agents")) * number(s("sim_time")) / 3600.0
        out["riders_per_vehicle_hour"] = ratio(riders, hours)
        if vehicles is not None and vehicles.num_rows:
            kwh = vehicles.column("kwh_drawn").to_numpy(zero_copy_only=False)
            if np.isfinite(kwh).any():
                out["kwh_per_rider"] = ratio(float(np.nansum(kwh)), riders)
    return out


def _riders(tasks: pa.Table | None) -> float:
    """Passengers of the completed tasks (a task without a count carries one)."""
    if tasks is None or not tasks.num_rows:
        return 0.0
    done = np.asarray(tasks.column("state").to_pylist()) == "completed"
    pax = tasks.column("passengers").to_numpy(zero_copy_only=False).astype(float)
    pax = np.where(np.isfinite(pax) & (pax > 0), pax, 1.0)
    return float(pax[done].sum())
