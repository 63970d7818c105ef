"""Metrics as DESIGN.md defines them, grouped by allocator and fleet size N.

Two tables, both pandas DataFrames with one row per (scenario, planner, allocator, n_agents):

:func:`allocator_metrics` (the MAGNNET paper's Tables I and III)
    ``runs``; ``total_cost_mean`` / ``total_cost_ci95`` (sum of the planned costs c_ij of the
    assignments, seconds; mean over seeds and the half-width of its 95 % Student-t interval);
    ``gap_mean`` / ``gap_ci95`` (per instance (cost - Hungarian cost) / Hungarian cost, paired
    with the Hungarian run of the same scenario, planner, N and seed); ``conflict_free_rate_mean``
    / ``_ci95``; ``alloc_seconds_mean`` / ``_ci95`` (wall seconds of the first decision: cost
    matrix + allocator, as the paper's Table III) and ``alloc_seconds_total_mean`` (all
    decisions of the run); ``rounds_mean``, ``messages_mean``, ``conflicts_mean``,
    ``agent_seconds_mean`` (per-agent critical path of decentralized allocators, where recorded).

:func:`taxi_metrics` (dispatch-style service quality; names as MATSim DRT's
``drt_customer_stats`` / ``drt_vehicle_stats`` print them, FleetPy's label in brackets)
    ``requests`` (tasks released), ``rides`` (completed), ``rejections`` (not completed:
    expired, unreachable or cancelled), ``rejectionRate``, ``service_rate`` = rides / requests
    [FleetPy "served users [%]"]; ``wait_average``, ``wait_median``, ``wait_p90``, ``wait_p95``,
    ``wait_max``: release -> arrival of a vehicle, seconds, over every task reached, pooled over
    the group's runs [FleetPy "waiting time", "waiting time (median)", "waiting time (90%
    quantile)"]; ``assignment_delay_average``: release -> assignment; ``approach_time_average``:
    assignment -> arrival; ``detour_time_average``: realized approach time minus planned cost
    (waits, replans) [FleetPy "detour time"]; ``rel_detour``: the same relative to the planned
    cost [FleetPy "rel detour"]; ``detourDistanceRatio_mean``: distance driven / straight-line
    distance per trip (from the events table; obstacles make it > 1); ``vehicles``,
    ``totalDistance`` (m) [FleetPy "total vkm" x 1000], ``averageDrivenDistance``,
    ``totalEmptyDistance`` and ``emptyRatio`` [FleetPy "% empty vkm"]: every metre here is driven
    to reach a task with nothing on board, so empty distance is all distance; ``utilization``:
    busy seconds / (vehicles x simulated time) [FleetPy "% fleet utilization"].

:func:`run_metrics` gives the taxi-style columns per run instead of per group.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from analysis.stats import mean_ci

GROUP = ["scenario", "planner", "allocator", "n_agents"]
PREFERRED_ORDER = ("hungarian", "local_hungarian", "magnnet", "auction", "greedy", "random")

#: FleetPy's labels of the taxi-style columns that have one (for users who compare).
FLEETPY_LABELS = {
    "service_rate": "served users [%]",
    "wait_average": "waiting time",
    "wait_median": "waiting time (median)",
    "wait_p90": "waiting time (90% quantile)",
    "detour_time_average": "detour time",
    "rel_detour": "rel detour",
    "utilization": "% fleet utilization",
    "emptyRatio": "% empty vkm",
}


def allocator_order(names) -> list[str]:
    """Allocators in the paper's order (Hungarian first), then the rest alphabetically."""
    names = set(names)
    first = [n for n in PREFERRED_ORDER if n in names]
    return first + sorted(names - set(first))


def sort_groups(df: pd.DataFrame) -> pd.DataFrame:
    """Rows ordered by scenario, planner, allocator (paper order) and N."""
    if df.empty:
        return df
    rank = {a: i for i, a in enumerate(allocator_order(df["allocator"].unique()))}
    keys = [k for k in GROUP if k in df.columns]
    return (df.assign(_rank=df["allocator"].map(rank))
              .sort_values([k if k != "allocator" else "_rank" for k in keys])
              .drop(columns="_rank").reset_index(drop=True))


# --------------------------------------------------------------------------- Tables I and III


def paired_gaps(summary: pd.DataFrame, reference: str = "hungarian") -> pd.Series:
    """Per run: (total cost - reference's total cost) / reference's total cost on the same
    instance (scenario, planner, N, seed); NaN where there is no reference run or it costs 0."""
    inst = ["scenario", "planner", "n_agents", "seed"]
    ref = (summary.loc[summary["allocator"] == reference, [*inst, "total_cost"]]
                  .drop_duplicates(inst).rename(columns={"total_cost": "_ref"}))
    merged = summary[inst + ["total_cost"]].merge(ref, on=inst, how="left")
    with np.errstate(divide="ignore", invalid="ignore"):
        gap = (merged["total_cost"] - merged["_ref"]) / merged["_ref"]
    gap[~(merged["_ref"] > 0)] = math.nan
    gap.index = summary.index
    return gap


def allocator_metrics(summary: pd.DataFrame, reference: str = "hungarian",
                      level: float = 0.95) -> pd.DataFrame:
    """Tables I and III per (scenario, planner, allocator, N); see the module docstring."""
    s = summary.copy()
    s["gap"] = paired_gaps(s, reference)
    rows = []
    for key, g in s.groupby(GROUP, sort=False):
        row = dict(zip(GROUP, key))
        row["runs"] = len(g)
        for col, name in (("total_cost", "total_cost"), ("gap", "gap"),
                          ("conflict_free_rate", "conflict_free_rate"),
                          ("first_decision_seconds", "alloc_seconds")):
            m, h, _ = mean_ci(g[col], level)
            row[f"{name}_mean"], row[f"{name}_ci95"] = m, h
        row["alloc_seconds_total_mean"] = _mean(g["alloc_seconds"])
        for col in ("rounds", "messages", "conflicts", "agent_seconds", "tasks_completed"):
            row[f"{col}_mean"] = _mean(g[col]) if col in g else math.nan
        rows.append(row)
    return sort_groups(pd.DataFrame(rows))


def _mean(col) -> float:
    v = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else math.nan


# --------------------------------------------------------------------------- taxi-style


def trip_distances(events: pd.DataFrame) -> pd.DataFrame:
    """Per trip (run, agent, task): distance driven (sum of the move steps from the departure
    cell) and straight-line distance from the departure cell to the arrival cell, metres."""
    cols = ["run_id", "agent_id", "task_id", "driven", "direct"]
    if events.empty:
        return pd.DataFrame(columns=cols)
    e = events.loc[events["event"].isin(["depart", "move"]) & (events["task_id"] >= 0),
                   ["run_id", "t", "event", "agent_id", "task_id", "x", "y", "z"]]
    out = []
    for (run, agent, task), g in e.groupby(["run_id", "agent_id", "task_id"], sort=False):
        p = g[["x", "y", "z"]].to_numpy(dtype=float)
        if len(p) < 2:
            continue
        driven = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        direct = float(np.linalg.norm(p[-1] - p[0]))
        out.append((run, agent, task, driven, direct))
    return pd.DataFrame(out, columns=cols)


def _taxi_row(tasks: pd.DataFrame, vehicles: pd.DataFrame, summary: pd.DataFrame,
              trips: pd.DataFrame | None) -> dict:
    requests = len(tasks)
    rides = int((tasks["state"] == "completed").sum())
    reached = tasks.loc[tasks["picked_up_at"].notna()]
    wait = (reached["picked_up_at"] - reached["released_at"]).to_numpy(dtype=float)
    assigned = tasks.loc[tasks["assigned_at"].notna() & (tasks["agent_id"] >= 0)]
    approach = (reached["picked_up_at"] - reached["assigned_at"]).to_numpy(dtype=float)
    planned = reached["cost"].to_numpy(dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(planned > 0, approach / planned - 1.0, np.nan)
    distance = float(vehicles["distance"].sum())
    # results written before trips existed have no empty_distance: every metre was empty then
    empty = (float(vehicles["empty_distance"].sum()) if "empty_distance" in vehicles
             and vehicles["empty_distance"].notna().all() else distance)
    horizon = (summary.set_index("run_id")["sim_time"]
               .reindex(vehicles["run_id"]).to_numpy(dtype=float))
    capacity = float(np.nansum(horizon))
    row = {
        "requests": requests, "rides": rides, "rejections": requests - rides,
        "rejectionRate": (requests - rides) / requests if requests else math.nan,
        "service_rate": rides / requests if requests else math.nan,
        "wait_average": _stat(wait, np.mean), "wait_median": _stat(wait, np.median),
        "wait_p90": _stat(wait, lambda v: np.quantile(v, 0.9)),
        "wait_p95": _stat(wait, lambda v: np.quantile(v, 0.95)),
        "wait_max": _stat(wait, np.max),
        "assignment_delay_average": _stat(
            (assigned["assigned_at"] - assigned["released_at"]).to_numpy(dtype=float), np.mean),
        "approach_time_average": _stat(approach, np.mean),
        "detour_time_average": _stat(approach - planned, np.mean),
        "rel_detour": _stat(rel[np.isfinite(rel)], np.mean),
        "vehicles": len(vehicles), "totalDistance": distance,
        "averageDrivenDistance": distance / len(vehicles) if len(vehicles) else math.nan,
        "totalEmptyDistance": empty, "emptyRatio": empty / distance if distance > 0 else math.nan,
        "utilization": float(vehicles["busy_seconds"].sum()) / capacity if capacity > 0
        else math.nan,
    }
    if trips is not None:
        ok = trips.loc[trips["direct"] > 0]
        row["detourDistanceRatio_mean"] = (float((ok["driven"] / ok["direct"]).mean())
                                           if len(ok) else math.nan)
    return row


def _stat(values: np.ndarray, fn) -> float:
    values = values[np.isfinite(values)]
    return float(fn(values)) if len(values) else math.nan


def _taxi(summary, tasks, vehicles, events, keys) -> pd.DataFrame:
    trips = trip_distances(events) if events is not None else None
    rows = []
    t_groups = dict(iter(tasks.groupby(keys, sort=False)))
    v_groups = dict(iter(vehicles.groupby(keys, sort=False)))
    trip_groups = {}
    if trips is not None and len(trips):
        cols = list(dict.fromkeys(["run_id", *keys]))
        trips = trips.merge(summary[cols].drop_duplicates("run_id"), on="run_id")
        trip_groups = dict(iter(trips.groupby(keys, sort=False)))
    empty_t, empty_v = tasks.iloc[:0], vehicles.iloc[:0]
    for key, s in summary.groupby(keys, sort=False):
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,)))
        row["runs"] = len(s)
        tr = trip_groups.get(key, trips.iloc[:0] if trips is not None else None)
        row.update(_taxi_row(t_groups.get(key, empty_t), v_groups.get(key, empty_v), s, tr))
        rows.append(row)
    return sort_groups(pd.DataFrame(rows))


def taxi_metrics(summary: pd.DataFrame, tasks: pd.DataFrame, vehicles: pd.DataFrame,
                 events: pd.DataFrame | None = None) -> pd.DataFrame:
    """Taxi-style metrics per (scenario, planner, allocator, N), tasks pooled over the group's
    runs (see the module docstring). ``events`` adds ``detourDistanceRatio_mean``."""
    return _taxi(summary, tasks, vehicles, events, GROUP)


def run_metrics(summary: pd.DataFrame, tasks: pd.DataFrame, vehicles: pd.DataFrame,
                events: pd.DataFrame | None = None) -> pd.DataFrame:
    """Taxi-style metrics per run (the same columns as :func:`taxi_metrics`)."""
    out = _taxi(summary, tasks, vehicles, events, [*GROUP, "seed", "run_id"])
    return out.drop(columns="runs")


def wait_times(tasks: pd.DataFrame) -> pd.DataFrame:
    """One row per task reached by a vehicle: the group keys, seed and ``wait`` (seconds)."""
    reached = tasks.loc[tasks["picked_up_at"].notna()]
    cols = [c for c in [*GROUP, "seed", "run_id", "task_id"] if c in reached.columns]
    return reached[cols].assign(wait=reached["picked_up_at"] - reached["released_at"])
