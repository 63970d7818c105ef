"""Metrics as DESIGN.md defines them, grouped by allocator and fleet size N.

Tables are pandas DataFrames with one row per (scenario, planner, allocator, n_agents):

:func:`allocator_metrics` (the MAGNNET paper's Tables I and III, for static scenarios)
    ``runs``; ``total_cost_mean`` / ``total_cost_ci95`` (sum of the planned costs c_ij of the
    assignments, seconds; mean over seeds and the half-width of its 95 % Student-t interval);
    ``gap_mean`` / ``gap_ci95`` (per instance (cost - Hungarian cost) / Hungarian cost, paired
    with the Hungarian run of the same scenario, planner, N and seed); ``conflict_free_rate_mean``
    / ``_ci95``; ``alloc_seconds_mean`` / ``_ci95`` (wall seconds of the first decision: cost
    matrix + allocator, as the paper's Table III) and ``alloc_seconds_total_mean`` (all
    decisions of the run); ``rounds_mean``, ``messages_mean``, ``conflicts_mean``,
    ``agent_seconds_mean`` (per-agent critical path of decentralized allocators, where recorded).

:func:`dynamic_metrics` (Tables I and III for dynamic scenarios: per task, never summed)
    ``served_share`` (completed / released), ``wait_mean`` (release -> pickup, s, over the tasks
    picked up), ``cost_per_assignment`` (planned seconds from the vehicle to the pickup, mean
    over the assignments made: ``total_cost / tasks_assigned``), ``conflict_free_rate``,
    ``decision_ms`` (wall milliseconds per decision, mean), each a mean over seeds with
    ``_ci95``; each run's figures are :func:`paired.per_task.per_task`'s, as in the CLI's
    tables. Summed planned costs are not comparable across allocators in a dynamic run: each
    allocator drives its own trajectory through the run, and one that serves fewer tasks sums
    fewer costs.

:func:`taxi_metrics` (ride-hailing service quality; names as MATSim DRT's
``drt_customer_stats`` / ``drt_vehicle_stats`` print them where they mean the same thing,
FleetPy's evaluation label in :data:`FLEETPY_LABELS`), tasks pooled over the group's runs:

    customers
        ``requests`` (tasks released); ``rides`` (served: completed); ``rejections`` (requests
        the fleet did not serve in time: ``rejected`` at once (no vehicle could reach the pickup
        within ``max_wait``), ``expired`` while open (``max_wait`` / ``ttl`` ran out) or
        ``unreachable``); ``cut_off`` (still waiting or aboard when the run ended: tasks of
        state ``cut_off``, cut off by the run's ``duration``, not a rider's choice) and
        ``failed`` (a breakdown with the passenger aboard), so that rides + rejections +
        cut_off + failed = requests; ``rejectionRate`` = rejections / requests;
        ``service_rate`` = rides / requests; ``cutOffRate`` = cut_off / requests;
        ``wait_average``, ``wait_median``, ``wait_p90``, ``wait_p95``, ``wait_max``: release ->
        pickup, seconds, over every request picked up (quantiles by linear interpolation); ``inVehicleTravelTime_mean``: pickup -> drop-off
        (s, rides with a drop-off); ``directTravelTime_mean``: the trip's free-flow fastest
        path (s; from the tasks' ``direct_seconds`` when the kernel records it, else from the
        network rebuilt by :mod:`analysis.network`); ``detour_ratio_mean`` / ``_median``:
        in-vehicle time / direct free-flow time per ride (1: the direct trip at free flow);
        ``assignment_delay_average``: release -> assignment; ``approach_time_average``:
        assignment -> pickup; ``approach_delay_average``: realized approach time minus its
        planned cost (reservation waits, replans; 0 without them).
    vehicles
        ``vehicles``; ``totalDistance``, ``totalEmptyDistance`` (without a passenger: to
        pickups, repositioning), ``totalPassengerDistanceTraveled`` (with one), metres;
        ``emptyRatio`` = empty / total distance (only where tasks are trips with a drop-off;
        NaN for the paper's point tasks, which carry nothing); ``vkm_per_ride`` = total km /
        rides; ``utilization``: share of the vehicles' available time (simulated time minus
        time broken down) spent driving to a pickup or with a passenger (states of
        :func:`analysis.timeline.fleet_states`; repositioning and idle do not count).
    voxel paths
        ``path_stretch_mean``: per leg, metres driven / straight line from departure to
        arrival (from ``move`` events: voxel runs; obstacles make it > 1).
    energy (electric runs; NaN without energy)
        ``kwh_drawn_per_vehicle``, ``kwh_charged_per_vehicle``, ``charges``, ``strandings``,
        ``soc_min``, ``soc_end_mean``, ``queue_seconds_per_vehicle``: see
        :mod:`analysis.energy_metrics`.

:func:`hourly_customers` and :func:`hourly_fleet` give the per-hour series (customers by the
hour of their release, the fleet by clock hour); :func:`run_metrics` gives the taxi columns per
run.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from analysis.energy_metrics import energy_events, energy_stats
from paired import compare
from paired.compare import KEY_DEFAULTS, RUN_KEYS_ATTR, allocator_order
from paired.per_task import PER_TASK, per_task
from paired.stats import mean_ci

def run_keys(df: pd.DataFrame) -> list[str]:
    """The run keys of ``df``'s runs that it has as columns: the writer's list
    (``df.attrs["run_keys"]``, from the files), else :data:`paired.compare.FALLBACK_RUN_KEYS`."""
    keys = df.attrs.get(RUN_KEYS_ATTR) or compare.FALLBACK_RUN_KEYS
    return [k for k in keys if k in df.columns]


def group_keys(df: pd.DataFrame) -> list[str]:
    """What the allocator tables group by: every run key of ``df`` but the seed (the runs of
    a group) and the repositioner (scenario, allocator, planner, batch window, N)."""
    return [k for k in run_keys(df) if k not in ("seed", "reposition")]


def series_keys(df: pd.DataFrame) -> list[str]:
    """The keys of one series of a taxi study: every run key of ``df`` but the seed
    (scenario, allocator, planner, repositioner, batch window, N)."""
    return [k for k in run_keys(df) if k != "seed"]


#: The allocator groups of runs that do not list their run keys (see :func:`group_keys`).
GROUP = [k for k in compare.FALLBACK_RUN_KEYS if k not in ("seed", "reposition")]
#: Their series (see :func:`series_keys`).
SERIES = [k for k in compare.FALLBACK_RUN_KEYS if k != "seed"]


def with_series(df: pd.DataFrame, summary: pd.DataFrame) -> pd.DataFrame:
    """``df`` (rows with ``run_id``) with the series keys it lacks taken from ``summary``; a
    key a run lacks reads :data:`~paired.compare.KEY_DEFAULTS`' value (runs written before
    repositioning or batch windows were run keys)."""
    keys = series_keys(summary)
    missing = [k for k in keys if k not in df.columns]
    if missing and "run_id" in df.columns:
        df = df.merge(summary[["run_id", *missing]].drop_duplicates("run_id"), on="run_id",
                      how="left")
    return _defaults(df)


def _defaults(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with a null repositioner read ``stay`` and a null batch window 0."""
    fill = {}
    if "reposition" in df.columns:
        fill["reposition"] = df["reposition"].fillna(KEY_DEFAULTS["reposition"]).astype(str)
    if "batch_window" in df.columns:
        fill["batch_window"] = pd.to_numeric(df["batch_window"], errors="coerce").astype(
            float).fillna(KEY_DEFAULTS["batch_window"])
    return df.assign(**fill) if fill else df


#: The order of a table's rows: these keys first (then any other run key).
_ROW_ORDER = ("scenario", "planner", "allocator", "batch_window", "n_agents", "reposition")


def sort_groups(df: pd.DataFrame) -> pd.DataFrame:
    """Rows ordered by scenario, planner, allocator (paper order), batch window, N and
    repositioner (``stay`` first)."""
    if df.empty:
        return df
    rank = {a: i for i, a in enumerate(allocator_order(df["allocator"].unique()))}
    present = [k for k in (*compare.FALLBACK_RUN_KEYS, *df.attrs.get(RUN_KEYS_ATTR, ()))
               if k in df.columns and k != "seed"]
    keys = [k for k in _ROW_ORDER if k in present] + [k for k in present if k not in _ROW_ORDER]
    out = df.assign(_rank=df["allocator"].map(rank))
    if "reposition" in out:
        out = out.assign(_rep=out["reposition"].fillna("stay").astype(str)
                         .map(lambda r: (r != "stay", r)))
    sub = {"allocator": "_rank", "reposition": "_rep"}
    return (out.sort_values([sub.get(k, k) for k in dict.fromkeys(keys)])
               .drop(columns=[c for c in ("_rank", "_rep") if c in out])
               .reset_index(drop=True))


# --------------------------------------------------------------------------- Tables I and III


def paired_gaps(summary: pd.DataFrame, reference: str = "hungarian") -> pd.Series:
    """Per run: its gap to the ``reference`` allocator's run on the same instance (scenario,
    planner, repositioner, N, seed), as :func:`paired.compare.paired_gaps` defines it (the
    CLI's tables use the same); NaN where there is no reference run or it costs 0."""
    gaps = compare.paired_gaps(summary.to_dict("records"), reference,
                               run_keys=summary.attrs.get(RUN_KEYS_ATTR))
    return pd.Series(gaps, index=summary.index, dtype=float)


def allocator_metrics(summary: pd.DataFrame, reference: str = "hungarian",
                      level: float = 0.95) -> pd.DataFrame:
    """Tables I and III per (scenario, planner, allocator, N); see the module docstring."""
    s = _defaults(summary.copy())
    s["gap"] = paired_gaps(s, reference)
    keys = group_keys(s)
    rows = []
    for key, g in s.groupby(keys, sort=False):
        row = dict(zip(keys, key))
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


# --------------------------------------------------------------------------- dynamic benchmarks


def dynamic_metrics(summary: pd.DataFrame, level: float = 0.95) -> pd.DataFrame:
    """Tables I and III of dynamic runs, per task (see the module docstring): per (scenario,
    planner, allocator, N) the mean over seeds and 95 % half-width of ``served_share``,
    ``wait_mean``, ``cost_per_assignment``, ``conflict_free_rate`` and ``decision_ms``."""
    s = _defaults(summary.copy())
    figures = pd.DataFrame([per_task(r) for r in s.to_dict("records")], columns=list(PER_TASK),
                           index=s.index, dtype=float)
    s[list(PER_TASK)] = figures
    keys = group_keys(s)
    rows = []
    for key, g in s.groupby(keys, sort=False):
        row = dict(zip(keys, key))
        row["runs"] = len(g)
        for col in ("served_share", "wait_mean", "cost_per_assignment", "conflict_free_rate",
                    "decision_ms"):  # PER_TASK (paired.per_task) and the conflict-free rate
            m, h, _ = mean_ci(g[col], level)
            row[f"{col}_mean"], row[f"{col}_ci95"] = m, h
        row["tasks_mean"] = _mean(g["n_tasks"])
        rows.append(row)
    return sort_groups(pd.DataFrame(rows))


# --------------------------------------------------------------------------- taxi-style

REJECTED_STATES = ("rejected", "expired", "unreachable")


def trip_table(tasks: pd.DataFrame, events: pd.DataFrame | None = None,
               direct: pd.Series | np.ndarray | None = None) -> pd.DataFrame:
    """One row per task: the run keys, ``task_id``, ``state``, ``released_at``, ``hour`` (of
    the release), ``wait`` (release -> pickup), ``dropped_off_at`` (the last ``dropoff`` event
    of the task, NaN without events), ``in_vehicle`` (pickup -> drop-off), ``direct_seconds``
    (free-flow fastest path; the tasks' own column if recorded, else ``direct``, else NaN) and
    ``detour_ratio`` (in_vehicle / direct_seconds, completed trips only)."""
    keys = [c for c in [*GROUP, "seed", "run_id"] if c in tasks.columns]
    t = tasks[keys + ["task_id", "state", "released_at", "picked_up_at"]
              + (["shared"] if "shared" in tasks else [])].copy()
    t["hour"] = np.floor(t["released_at"].to_numpy(dtype=float) / 3600).astype(int)
    t["wait"] = t["picked_up_at"] - t["released_at"]
    t["dropped_off_at"] = np.nan
    if events is not None and len(events) and "run_id" in t:
        drops = (events.loc[events["event"] == "dropoff"].groupby(["run_id", "task_id"])["t"]
                 .max().rename("_drop"))
        if len(drops):
            t = t.merge(drops, left_on=["run_id", "task_id"], right_index=True, how="left")
            t["dropped_off_at"] = t.pop("_drop")
    t["in_vehicle"] = t["dropped_off_at"] - t["picked_up_at"]
    if "direct_seconds" in tasks.columns and tasks["direct_seconds"].notna().any():
        t["direct_seconds"] = tasks["direct_seconds"].to_numpy(dtype=float)
    elif "direct_time" in tasks.columns and tasks["direct_time"].notna().any():
        # the simulator's own free-flow time (set when a decision first considers the trip)
        t["direct_seconds"] = tasks["direct_time"].to_numpy(dtype=float)
    elif direct is not None:
        t["direct_seconds"] = np.asarray(direct, dtype=float)
    else:
        t["direct_seconds"] = np.nan
    ok = (t["state"] == "completed") & (t["direct_seconds"] > 0)
    t["detour_ratio"] = np.where(ok, t["in_vehicle"] / t["direct_seconds"], np.nan)
    return t


def customer_stats(trips: pd.DataFrame) -> dict:
    """The customer columns of :func:`taxi_metrics` over the rows of :func:`trip_table`."""
    requests = len(trips)
    rides = int((trips["state"] == "completed").sum())
    rejections = int(trips["state"].isin(REJECTED_STATES).sum())
    # the tasks table's state "cut_off": the run's end cut the trip off
    cut_off = int((trips["state"] == "cut_off").sum())
    wait = trips["wait"].to_numpy(dtype=float)
    return {
        "requests": requests, "rides": rides, "rejections": rejections,
        "cut_off": cut_off, "failed": int((trips["state"] == "failed").sum()),
        "rejectionRate": rejections / requests if requests else math.nan,
        "service_rate": rides / requests if requests else math.nan,
        "cutOffRate": cut_off / requests if requests else math.nan,
        "wait_average": _stat(wait, np.mean), "wait_median": _stat(wait, np.median),
        "wait_p90": _stat(wait, lambda v: np.quantile(v, 0.9)),
        "wait_p95": _stat(wait, lambda v: np.quantile(v, 0.95)),
        "wait_max": _stat(wait, np.max),
        "inVehicleTravelTime_mean": _stat(trips["in_vehicle"].to_numpy(dtype=float), np.mean),
        "directTravelTime_mean": _stat(
            trips.loc[trips["state"] == "completed", "direct_seconds"].to_numpy(dtype=float),
            np.mean),
        "detour_ratio_mean": _stat(trips["detour_ratio"].to_numpy(dtype=float), np.mean),
        "detour_ratio_median": _stat(trips["detour_ratio"].to_numpy(dtype=float), np.median),
        # shared rides: rides during which another request was on board; delay = drop-off -
        # release - direct free-flow time (s), over the rides
        "shared_rate": (float(trips.loc[trips["state"] == "completed", "shared"].mean())
                        if "shared" in trips and rides else math.nan),
        "delay_mean": _stat((trips["dropped_off_at"] - trips["released_at"]
                             - trips["direct_seconds"]).to_numpy(dtype=float)[
                                 (trips["state"] == "completed").to_numpy()], np.mean),
    }


def _approach(tasks: pd.DataFrame) -> dict:
    reached = tasks.loc[tasks["picked_up_at"].notna()]
    assigned = tasks.loc[tasks["assigned_at"].notna() & (tasks["agent_id"] >= 0)]
    approach = (reached["picked_up_at"] - reached["assigned_at"]).to_numpy(dtype=float)
    planned = reached["cost"].to_numpy(dtype=float)
    return {
        "assignment_delay_average": _stat(
            (assigned["assigned_at"] - assigned["released_at"]).to_numpy(dtype=float), np.mean),
        "approach_time_average": _stat(approach, np.mean),
        "approach_delay_average": _stat(approach - planned, np.mean),
    }


def vehicle_stats(vehicles: pd.DataFrame, states: pd.DataFrame | None, rides: int,
                  trips_have_dropoff: bool, horizon: dict[str, float]) -> dict:
    """The vehicle columns of :func:`taxi_metrics`. ``states``: the rows of
    :func:`analysis.timeline.fleet_states` for these vehicles (None: utilization from the
    vehicles' ``busy_seconds`` and ``down_seconds`` and ``horizon``, the simulated seconds per
    run)."""
    distance = float(vehicles["distance"].sum())
    has_empty = "empty_distance" in vehicles and vehicles["empty_distance"].notna().all()
    empty = float(vehicles["empty_distance"].sum()) if has_empty else math.nan
    # MATSim DRT's totalPassengerDistanceTraveled: passenger-metres (with one-seat vehicles
    # the occupied metres, which is what results written before shared rides hold)
    pax = "passenger_distance" if "passenger_distance" in vehicles else "occupied_distance"
    occupied = (float(vehicles[pax].sum())
                if pax in vehicles and vehicles[pax].notna().all() else math.nan)
    if states is not None and len(states):
        secs = (states["end"] - states["start"]).groupby(states["state"]).sum()
        total = float(secs.sum())
        available = total - float(secs.get("failed", 0.0))
        busy = float(secs.get("to_pickup", 0.0) + sum(secs.get(k, 0.0) for k in
                                                       ("occupied", "occupied_2", "occupied_3+")))
    else:
        cap = vehicles["run_id"].map(horizon).to_numpy(dtype=float)
        down = (vehicles["down_seconds"].to_numpy(dtype=float) if "down_seconds" in vehicles
                else np.zeros(len(vehicles)))
        available = float(np.nansum(cap - np.nan_to_num(down)))
        busy = float(vehicles["busy_seconds"].sum())
    n = len(vehicles)
    return {
        "vehicles": n, "totalDistance": distance,
        "averageDrivenDistance": distance / n if n else math.nan,
        "totalEmptyDistance": empty, "totalPassengerDistanceTraveled": occupied,
        "occupancy": occupied / distance if distance > 0 else math.nan,
        "emptyRatio": (empty / distance if trips_have_dropoff and distance > 0 else math.nan),
        "vkm_per_ride": distance / 1000 / rides if rides else math.nan,
        "utilization": busy / available if available > 0 else math.nan,
    }


def trip_distances(events: pd.DataFrame) -> pd.DataFrame:
    """Per leg (run, agent, task) with ``move`` events: distance driven (sum of the move steps
    from the departure cell) and straight-line distance from the departure cell to the arrival
    cell, metres."""
    cols = ["run_id", "agent_id", "task_id", "driven", "direct"]
    if events.empty:
        return pd.DataFrame(columns=cols)
    e = events.loc[events["event"].isin(["depart", "move"]) & (events["task_id"] >= 0),
                   ["run_id", "t", "event", "agent_id", "task_id", "x", "y", "z"]]
    if not (e["event"] == "move").any():
        return pd.DataFrame(columns=cols)
    out = []
    for (run, agent, task), g in e.groupby(["run_id", "agent_id", "task_id"], sort=False):
        p = g[["x", "y", "z"]].to_numpy(dtype=float)
        if len(p) < 2:
            continue
        driven = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        direct = float(np.linalg.norm(p[-1] - p[0]))
        out.append((run, agent, task, driven, direct))
    return pd.DataFrame(out, columns=cols)


def _stat(values: np.ndarray, fn) -> float:
    values = values[np.isfinite(values)]
    return float(fn(values)) if len(values) else math.nan


def _states(summary, events, vehicles):
    from analysis.timeline import fleet_states

    if events is None or events.empty:
        return None
    out = []
    ends = summary.set_index("run_id")["sim_time"].to_dict()
    for run, v in vehicles.groupby("run_id", sort=False):
        e = events.loc[events["run_id"] == run] if events["run_id"].nunique() > 1 else events
        out.append(fleet_states(e, v, end=float(ends.get(run, e["t"].max() if len(e) else 0))))
    return pd.concat(out, ignore_index=True) if out else None


def _taxi(summary, tasks, vehicles, events, keys, direct=None) -> pd.DataFrame:
    trips = trip_table(tasks, events, direct)
    states = _states(summary, events, vehicles)
    stretch = trip_distances(events) if events is not None else None
    horizon = summary.set_index("run_id")["sim_time"].to_dict()
    run_keys = summary[list(dict.fromkeys(["run_id", *keys]))].drop_duplicates("run_id")

    def groups(df):
        if df is None or df.empty:
            return {}
        missing = [k for k in keys if k not in df.columns]
        if missing:
            df = df.merge(run_keys[["run_id", *missing]], on="run_id", how="left")
        df = _defaults(df)
        return {k if isinstance(k, tuple) else (k,): g
                for k, g in df.groupby(keys, sort=False)}

    t_groups, tr_groups, v_groups = groups(tasks), groups(trips), groups(vehicles)
    s_groups, st_groups = groups(states), groups(stretch)
    e_groups = groups(energy_events(events))
    rows = []
    for key, s in summary.groupby(keys, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(keys, key))
        row["runs"] = len(s)
        tr = tr_groups.get(key, trips.iloc[:0])
        ts = t_groups.get(key, tasks.iloc[:0])
        row.update(customer_stats(tr))
        row.update(_approach(ts))
        dropoff = "dropoff_x" in ts and bool(ts["dropoff_x"].notna().any())
        row.update(vehicle_stats(v_groups.get(key, vehicles.iloc[:0]),
                                 s_groups.get(key) if states is not None else None,
                                 row["rides"], dropoff, horizon))
        st = st_groups.get(key)
        ok = st.loc[st["direct"] > 0] if st is not None else None
        row["path_stretch_mean"] = (float((ok["driven"] / ok["direct"]).mean())
                                    if ok is not None and len(ok) else math.nan)
        row.update(energy_stats(v_groups.get(key, vehicles.iloc[:0]),
                                None if events is None else e_groups.get(key)))
        rows.append(row)
    return sort_groups(pd.DataFrame(rows))


def taxi_metrics(summary: pd.DataFrame, tasks: pd.DataFrame, vehicles: pd.DataFrame,
                 events: pd.DataFrame | None = None,
                 direct: pd.Series | np.ndarray | None = None) -> pd.DataFrame:
    """Taxi-style metrics per series (scenario, planner, allocator, N and, where the summary
    names it, repositioner), tasks pooled over the series' runs (see the module docstring).
    ``events`` gives in-vehicle times, the fleet states (utilization) and path stretch;
    ``direct`` (per row of ``tasks``) the trips' free-flow times where the tasks table lacks
    ``direct_seconds``."""
    summary = with_series(summary, summary)
    keys = series_keys(summary)
    out = _taxi(summary, tasks, vehicles, events, keys, direct)
    ci = seed_intervals(summary, keys)
    return out.merge(ci, on=keys, how="left") if len(out) and len(ci) else out


#: The taxi columns with a 95 % interval over seeds (``<column>_ci95``), and how one run's value
#: is computed from its summary row.
RUN_VALUES = {
    "service_rate": lambda s: s["tasks_completed"] / s["n_tasks"],
    "rejectionRate": lambda s: (s["tasks_rejected"] + s["tasks_expired"]
                                + s.get("tasks_unreachable", 0)) / s["n_tasks"],
    "cutOffRate": lambda s: s["tasks_cut_off"] / s["n_tasks"],
    "wait_average": lambda s: s["wait_time_mean"],
    "emptyRatio": lambda s: s["empty_distance"] / s["distance"],
}


def seed_intervals(summary: pd.DataFrame, keys: list[str] | None = None,
                   level: float = 0.95) -> pd.DataFrame:
    """Per series (``keys``): for each column of :data:`RUN_VALUES`, the half-width of the
    ``level`` Student-t interval of the mean over the series' runs (seeds) of the run's value
    (``<column>_ci95``; NaN with one run). The taxi tables show them as ``mean ± half-width``;
    the means themselves pool the tasks of the runs, which for equal-sized runs is the same
    mean."""
    keys = keys or series_keys(summary)
    rows = []
    with np.errstate(divide="ignore", invalid="ignore"):
        values = {}
        for col, fn in RUN_VALUES.items():
            try:
                values[col] = pd.to_numeric(fn(summary), errors="coerce").astype(float)
            except KeyError:  # an older summary without that column
                continue
    for key, idx in summary.groupby(keys, sort=False).groups.items():
        row = dict(zip(keys, key if isinstance(key, tuple) else (key,)))
        for col, v in values.items():
            row[f"{col}_ci95"] = mean_ci(v.loc[idx], level)[1]
        rows.append(row)
    return pd.DataFrame(rows, columns=[*keys, *(f"{c}_ci95" for c in values)])


def run_metrics(summary: pd.DataFrame, tasks: pd.DataFrame, vehicles: pd.DataFrame,
                events: pd.DataFrame | None = None,
                direct: pd.Series | np.ndarray | None = None) -> pd.DataFrame:
    """Taxi-style metrics per run (the same columns as :func:`taxi_metrics`)."""
    summary = with_series(summary, summary)
    out = _taxi(summary, tasks, vehicles, events, [*series_keys(summary), "seed", "run_id"],
                direct)
    return out.drop(columns="runs")


def hourly_customers(trips: pd.DataFrame, keys: list[str] | None = None,
                     bin_s: float = 3600.0) -> pd.DataFrame:
    """Per group (``keys``, default the allocator groups) and hour of release (or bin of
    ``bin_s`` seconds): the customer columns of :func:`customer_stats` (``trips``: the rows of
    :func:`trip_table`); ``hour`` is the bin's index, ``t_h`` its start in hours; ``runs`` the
    number of runs pooled in the group (over all its bins, from ``run_id``; 1 without it):
    the counts (``requests``, ``rides``, ``rejections``) are sums over those runs, so
    ``requests / runs`` is the mean per run."""
    keys = [k for k in (keys or GROUP) if k in trips.columns]
    t = trips.assign(hour=np.floor(trips["released_at"].to_numpy(dtype=float) / bin_s)
                     .astype(int))
    runs = (t.groupby(keys)["run_id"].nunique() if keys and "run_id" in t.columns else None)
    rows = []
    for key, g in t.groupby([*keys, "hour"], sort=True):
        row = dict(zip([*keys, "hour"], key))
        row["t_h"] = row["hour"] * bin_s / 3600
        group = key[:-1] if len(keys) > 1 else key[0]
        row["runs"] = 1 if runs is None else int(runs.loc[group])
        row.update(customer_stats(g))
        rows.append(row)
    return pd.DataFrame(rows)


def hourly_fleet(states: pd.DataFrame, summary: pd.DataFrame,
                 keys: list[str] | None = None, bin_s: float = 3600.0) -> pd.DataFrame:
    """Per group and clock hour (or bin of ``bin_s`` seconds; ``hour`` its index, ``t_h`` its
    start in hours): the mean number of vehicles in each fleet state (its share of the bin's
    vehicle seconds times the fleet size; a bin cut short by the end of a run counts for the
    time it covers) and ``utilization`` (to_pickup + occupied over the time not failed)."""
    from analysis.timeline import FLEET_STATES, hourly_states

    keys = keys or group_keys(summary)
    h = hourly_states(states, hour=bin_s)
    if h.empty:
        return pd.DataFrame(columns=[*keys, "hour", "t_h", *FLEET_STATES, "utilization"])
    h = h.merge(summary[list(dict.fromkeys(["run_id", *keys]))], on="run_id", how="left")
    runs = h.groupby(keys)["run_id"].nunique()
    out = h.groupby([*keys, "hour"], sort=True)[list(FLEET_STATES)].sum().reset_index()
    out.insert(len(keys) + 1, "t_h", out["hour"] * bin_s / 3600)
    fleet = (states.merge(summary[list(dict.fromkeys(["run_id", *keys]))], on="run_id",
                          how="left").drop_duplicates(["run_id", "agent_id"])
             .groupby(keys).size() / runs)  # vehicles per run
    size = out.set_index(keys).index.map(fleet).to_numpy(dtype=float)
    covered = out[list(FLEET_STATES)].sum(axis=1)  # a run's last bin may be cut short
    available = covered - out["failed"]
    busy = out["to_pickup"] + out[["occupied", "occupied_2", "occupied_3+"]].sum(axis=1)
    out["utilization"] = busy / available.where(available > 0)
    for st in FLEET_STATES:
        out[st] = out[st] / covered.where(covered > 0) * size
    return out


def wait_times(tasks: pd.DataFrame) -> pd.DataFrame:
    """One row per task reached by a vehicle: the group keys, seed and ``wait`` (seconds)."""
    reached = tasks.loc[tasks["picked_up_at"].notna()]
    cols = [c for c in [*GROUP, "seed", "run_id", "task_id"] if c in reached.columns]
    return reached[cols].assign(wait=reached["picked_up_at"] - reached["released_at"])
