"""A report of one or more results folders: paper-style tables, taxi-style metrics, plots.

``write_report(paths, out)`` writes into ``out``:

* ``report.md`` (or ``report.html``): the tables and the figures below, with definitions;
* ``allocators.csv`` (Tables I and III per allocator and N, see
  :func:`analysis.metrics.allocator_metrics`) and the service metrics per allocator and N
  (:func:`analysis.metrics.taxi_metrics`): ``taxi.csv`` where the folder holds road runs,
  ``service.csv`` where it holds only voxel runs (robots, not taxis); ``runs.csv`` (the same
  metrics per run);
* voxel runs of static scenarios: ``cost_vs_n.png``, ``success_vs_n.png``,
  ``alloc_time_vs_n.png``, ``wait_times.png``, ``timeline.png`` (vehicle Gantt of one run) and
  ``paths_3d.png`` (that run in 3D);
* voxel runs of dynamic scenarios (tasks released over time): Tables I and III per task
  (:func:`analysis.metrics.dynamic_metrics`, ``dynamic.csv``) and ``served_vs_n.png``,
  ``wait_vs_n.png``, ``cost_per_task_vs_n.png`` instead of ``cost_vs_n.png``;
* road (taxi) runs: ``hourly_customers.csv`` / ``hourly_fleet.csv`` (per-hour series),
  ``map.png`` (streets, pickup density, fleet start; whole region and zoomed on the demand),
  ``hourly.png`` (demand, served, rejected, wait percentiles over time), ``fleet_state.png``
  (stacked fleet states over time), ``wait_by_allocator.png`` (wait distributions); each per
  series: allocator, N and, where the runs differ in them, batch window (a swept
  ``[sweep] batch_window``), scenario, planner and repositioner
  (:func:`analysis.taxi_plots.series`).
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path

import pandas as pd

from analysis import metrics as M
from analysis import plots
from analysis.io import Results, open_results
from paired.compare import allocator_order, window_label

FIGURES = ("cost_vs_n.png", "success_vs_n.png", "alloc_time_vs_n.png", "wait_times.png",
           "timeline.png", "paths_3d.png")

DYNAMIC_FIGURES = ("served_vs_n.png", "wait_vs_n.png", "cost_per_task_vs_n.png",
                   "success_vs_n.png", "alloc_time_vs_n.png", "wait_times.png", "timeline.png",
                   "paths_3d.png")
ROAD_FIGURES = ("map.png", "hourly.png", "fleet_state.png", "wait_by_allocator.png")

#: The taxi columns the report shows (taxi.csv has them all).
TAXI_COLUMNS = ["runs", "requests", "rides", "rejections", "cut_off", "failed", "service_rate",
                "rejectionRate", "cutOffRate", "wait_average", "wait_median", "wait_p90",
                "wait_p95", "wait_max", "inVehicleTravelTime_mean", "detour_ratio_mean",
                "utilization", "emptyRatio", "vkm_per_ride"]
#: ... and of shared rides, where some ride was shared (occupancy: passenger-km / vehicle-km)
SHARED_COLUMNS = ["occupancy", "shared_rate", "delay_mean"]


#: The shares the report prints as percentages with one decimal (taxi.csv keeps 0-1).
PERCENT_COLUMNS = {"service_rate", "rejectionRate", "cutOffRate", "utilization", "emptyRatio",
                   "shared_rate", "soc_min", "soc_end_mean"}


def _pooled(taxi: pd.DataFrame) -> bool:
    return bool("shared_rate" in taxi and (taxi["shared_rate"].fillna(0) > 0).any())


#: ... for voxel runs (point tasks: no ride, no empty ratio)
VOXEL_TAXI_COLUMNS = ["runs", "requests", "rides", "rejectionRate", "wait_average",
                      "wait_median", "wait_p90", "wait_max", "assignment_delay_average",
                      "approach_delay_average", "path_stretch_mean", "utilization",
                      "totalDistance"]


def default_run(summary: pd.DataFrame, reference: str = "hungarian") -> str:
    """The run a report shows in detail: the reference allocator's (else the first
    allocator's) largest fleet, smallest seed."""
    allocs = allocator_order(summary["allocator"].unique())
    alloc = reference if reference in allocs else allocs[0]
    s = summary.loc[summary["allocator"] == alloc].sort_values(["n_agents", "seed"],
                                                               ascending=[False, True])
    return str(s.iloc[0]["run_id"])


def _fmt(v, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}" if abs(v) < 1e5 else f"{v:.3g}"
    return str(v)


def _pm(m: float, h: float, digits: int = 1, scale: float = 1.0) -> str:
    if not math.isfinite(m):
        return "–"
    s = f"{m * scale:.{digits}f}"
    return s + (f" ± {h * scale:.{digits}f}" if math.isfinite(h) else "")


def table_i(am: pd.DataFrame, reference: str = "hungarian") -> pd.DataFrame:
    """Paper Table I: per N (rows) and allocator (columns) the mean total cost ± 95 % CI and
    the mean paired gap to the reference."""
    return _pivot(am, lambda r: _pm(r.total_cost_mean, r.total_cost_ci95) + (
        "" if r.allocator == reference or not math.isfinite(r.gap_mean)
        else f" [{round(100 * r.gap_mean, 1) + 0.0:+.1f} %]"))


def table_iii(am: pd.DataFrame) -> pd.DataFrame:
    """Paper Table III: conflict-free success rate (%) and allocation time (ms)."""
    return _pivot(am, lambda r: f"{_pm(r.conflict_free_rate_mean, math.nan, 1, 100)} % / "
                                f"{_fmt(1000 * r.alloc_seconds_mean, 1)} ms")


def _pivot(am: pd.DataFrame, cell) -> pd.DataFrame:
    am = am.copy()
    multi = [k for k in ("scenario", "planner") if am[k].nunique() > 1]
    am["column"] = am["allocator"]
    for k in multi:
        am["column"] = am["column"] + " (" + am[k].astype(str) + ")"
    am["cell"] = [cell(r) for r in am.itertuples(index=False)]
    cols = list(dict.fromkeys(am["column"]))
    out = am.pivot_table(index="n_agents", columns="column", values="cell", aggfunc="first")
    out = out.reindex(columns=cols).fillna("–")
    out.insert(0, "runs", am.groupby("n_agents")["runs"].max())
    out.index.name = "N"
    return out.reset_index()


def markdown_table(df: pd.DataFrame, digits: int = 2) -> str:
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(v, digits).replace("|", "\\|") for v in row) + " |")
    return "\n".join(lines)


def _taxi_view(taxi: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    keys = ["allocator", "n_agents"] + [k for k in M.series_keys(taxi)
                                         if k not in ("allocator", "n_agents")
                                         and taxi[k].nunique() > 1]
    cols = [c for c in columns if c in taxi.columns]
    view = taxi[keys + cols].rename(columns={"n_agents": "N"})
    if "batch_window" in keys:  # imm / 30s, as the CLI's tables and the figures' legends
        view["batch_window"] = view["batch_window"].map(window_label)
    for c in cols:  # mean ± half-width of the 95 % interval over seeds, where there is one
        ci = f"{c}_ci95"
        h = (taxi[ci] if ci in taxi.columns and taxi[ci].notna().any()
             else pd.Series(math.nan, index=taxi.index))
        if c in PERCENT_COLUMNS:  # 99.3 % and 99.5 % told apart, not both 0.99
            view[c] = [_percent(float(m), float(w)) for m, w in zip(taxi[c], h)]
        elif h.notna().any():
            digits = 1 if c == "wait_average" else 3
            view[c] = [_pm(float(m), float(w), digits) for m, w in zip(taxi[c], h)]
    return view


def _percent(m: float, h: float = math.nan) -> str:
    """A share (0-1) as a percentage with one decimal, ``± half-width`` where there is one:
    ``99.3 %``, ``97.2 ± 0.4 %``; ``–`` for a missing value."""
    s = _pm(m, h, 1, 100)
    return s if s == "–" else s + " %"


def table_dynamic(dm: pd.DataFrame) -> pd.DataFrame:
    """Tables I and III of dynamic runs, one row per allocator and N (mean ± 95 % CI)."""
    rows = []
    for r in dm.itertuples(index=False):
        rows.append({"allocator": r.allocator, "N": r.n_agents, "runs": r.runs,
                     "tasks": _fmt(r.tasks_mean, 0),
                     "served %": _pm(r.served_share_mean, r.served_share_ci95, 1, 100),
                     "wait s": _pm(r.wait_mean_mean, r.wait_mean_ci95, 1),
                     "cost s / assignment": _pm(r.cost_per_assignment_mean,
                                                r.cost_per_assignment_ci95, 2),
                     "conflict-free %": _pm(r.conflict_free_rate_mean, math.nan, 1, 100),
                     "ms / decision": _pm(r.decision_ms_mean, math.nan, 2)})
    return pd.DataFrame(rows)


def task_sources(res: Results, summary: pd.DataFrame) -> dict[str, str]:
    """Per scenario: its task source (``static``, ``periodic``, ``poisson``, ``trace``), read
    from the scenario text in one of its runs' files (``static`` where it cannot be read)."""
    import tomllib

    out = {}
    for scen, g in summary.groupby("scenario"):
        source = "static"
        try:
            text = res.metadata(str(g["run_id"].iloc[0]), "summary").get("dispatch.scenario", "")
            source = tomllib.loads(text).get("tasks", {}).get("source", "static")
        except (KeyError, ValueError):
            pass
        out[str(scen)] = str(source)
    return out


def write_report(source: Results | str | os.PathLike | list, out: str | os.PathLike, *,
                 fmt: str = "md", run_id: str | None = None,
                 reference: str = "hungarian", series=None) -> list[Path]:
    """Write the report of ``source`` (a :class:`Results` or one or more folders) into
    ``out``; returns the files written (the report first). ``series``: glob patterns of the
    series the taxi figures draw (``"hungarian*"``, ``"* 30s*"``; see
    :func:`analysis.taxi_plots.select`; all when None); the tables keep every series."""
    if fmt not in ("md", "html"):
        raise ValueError(f"report format must be 'md' or 'html', got {fmt!r}")
    res = source if isinstance(source, Results) else open_results(
        *(source if isinstance(source, (list, tuple)) else [source]))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = res.summary
    if summary.empty:
        raise ValueError(f"{res}: no runs in the summary table")
    if run_id is not None and run_id not in set(summary["run_id"]):
        raise KeyError(f"no run {run_id!r}; there are {len(summary)} runs, e.g. "
                       f"{', '.join(summary['run_id'].head(3))}")
    space = (summary["space"].fillna("voxel") if "space" in summary
             else pd.Series("voxel", index=summary.index))
    road = summary.loc[space == "road"]
    voxel = summary.loc[space != "road"]
    tasks, vehicles = res.table("tasks"), res.table("vehicles")
    events = res.table("events", columns=["run_id", "t", "event", "agent_id", "task_id",
                                          "x", "y", "z"])
    direct = _direct_times(res, road, tasks) if len(road) else None
    # the service metrics' file: robots are not taxis
    service = "taxi.csv" if len(road) else "service.csv"
    written: list[Path] = []
    sections = _head(res, summary)
    if len(voxel):
        sections += _voxel_part(res, voxel, tasks, vehicles, events, out, written,
                                run_id if run_id in set(voxel["run_id"]) else None, reference,
                                service=service)
    if len(road):
        sections += _road_part(res, road, tasks, vehicles, events, direct, out, written, series,
                               run_id if run_id in set(road["run_id"]) else None)
    taxi = M.taxi_metrics(summary, tasks, vehicles, events, direct)
    per_run = M.run_metrics(summary, tasks, vehicles, events, direct)
    for name, df in ((service, taxi), ("runs.csv", per_run)):
        df.to_csv(out / name, index=False)
    at = 1 if written and written[0].name in ("allocators.csv", "dynamic.csv") else 0
    written[at:at] = [out / service, out / "runs.csv"]
    errors = res.errors()
    if len(errors):
        cols = [c for c in ("run_id", "error_type", "message") if c in errors.columns]
        sections += [("h2", "Failed runs"), ("table", errors[cols])]
    sections += [("p", "Files: " + ", ".join(f.name for f in written if f.suffix == ".csv")
                  + " (every column; runs.csv per run).")]
    report = out / f"report.{fmt}"
    text = _markdown(sections) if fmt == "md" else _html(sections)
    tmp = report.with_name(f".{report.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(report)
    return [report, *written]


def _direct_times(res: Results, road: pd.DataFrame, tasks: pd.DataFrame):
    """Per row of ``tasks``: the trip's free-flow direct seconds, from the network of its
    scenario rebuilt by :mod:`analysis.network` (NaN where it cannot be)."""
    import numpy as np

    from analysis.network import direct_seconds, road_network

    out = np.full(len(tasks), np.nan)
    if "direct_seconds" in tasks and tasks["direct_seconds"].notna().any():
        return None  # recorded by the kernel
    for scen, g in road.groupby("scenario"):
        try:
            meta = res.metadata(str(g["run_id"].iloc[0]), "tasks")
        except KeyError:
            continue
        net = road_network(meta, [s.path for s in res.sources])
        rows = (tasks["scenario"] == scen).to_numpy()
        if net is not None and rows.any():
            out[rows] = direct_seconds(tasks.loc[rows], net)
    return out


def _head(res, summary) -> list:
    scen = ", ".join(sorted(summary["scenario"].unique()))
    allocs = ", ".join(allocator_order(summary["allocator"].unique()))
    ns = ", ".join(map(str, sorted(summary["n_agents"].unique())))
    seeds = summary["seed"].nunique()
    errors = res.errors()
    return [("h1", f"Report: {scen}"),
            ("p", (f"{len(summary)} runs from {', '.join(str(x.path) for x in res.sources)}: "
                   f"allocators {allocs}; N = {ns}; {seeds} seed(s).")
             + (f" **{len(errors)} run(s) failed** (see the end)." if len(errors) else "")
             + (f" {duplicates_note(res)}." if res.duplicates else ""))]


def duplicates_note(res: Results) -> str:
    """One line on the runs found in more than one folder (counted once), e.g. for the CLI."""
    d = res.duplicates
    more = f" and {len(d) - 1} more" if len(d) > 1 else ""
    return (f"{len(d)} run(s) found in more than one folder, counted once (read from the first "
            f"folder that holds them): {d[0].run_id} in {d[0].kept} and {d[0].dropped}{more}")


def _voxel_part(res, summary, tasks, vehicles, events, out, written, run_id, reference, *,
                service: str = "service.csv") -> list:
    """Tables I and III (static: summed cost and gap; dynamic: per task), their plots, the
    service metrics, one run in detail."""
    sources = task_sources(res, summary)
    dynamic = summary["scenario"].map(sources).fillna("static") != "static"
    s: list = []
    static_runs, dynamic_runs = summary.loc[~dynamic], summary.loc[dynamic]
    if len(static_runs):
        am = M.allocator_metrics(static_runs, reference)
        am.to_csv(out / "allocators.csv", index=False)
        written.append(out / "allocators.csv")
        plots.cost_vs_n(am, out / "cost_vs_n.png")
        plots.success_vs_n(am, out / "success_vs_n.png")
        plots.alloc_time_vs_n(am, out / "alloc_time_vs_n.png")
        s += [("h2", "Table I: total travel cost"),
              ("p", ("Sum of the planned travel times c_ij (s) of the assignments made; mean "
                     "over seeds ± half-width of the 95 % Student-t interval; in brackets the "
                     f"mean gap to {reference} on the same instance (same seed, N, planner).")),
              ("table", table_i(am, reference)),
              ("img", "cost_vs_n.png")]
        s += [("h2", "Table III: conflict-free success rate and allocation time"),
              ("p", ("Share of offered tasks assigned without ever being requested by two "
                     "agents in one round; wall time of the first decision (cost matrix + "
                     "allocator), mean over seeds.")),
              ("table", table_iii(am)),
              ("img", "success_vs_n.png"), ("img", "alloc_time_vs_n.png")]
        figures = list(FIGURES)
    if len(dynamic_runs):
        dm = M.dynamic_metrics(dynamic_runs)
        dm.to_csv(out / "dynamic.csv", index=False)
        written.append(out / "dynamic.csv")
        plots.metric_vs_n(dm, "served_share_mean", out / "served_vs_n.png",
                          ci="served_share_ci95", scale=100, ylabel="tasks served (%)",
                          title="Served share vs N (completed / released; mean, 95 % CI)")
        plots.metric_vs_n(dm, "wait_mean_mean", out / "wait_vs_n.png", ci="wait_mean_ci95",
                          ylabel="mean wait, release → pickup (s)",
                          title="Mean wait vs N (mean over seeds, 95 % CI)")
        plots.metric_vs_n(dm, "cost_per_assignment_mean", out / "cost_per_task_vs_n.png",
                          ci="cost_per_assignment_ci95",
                          ylabel="planned cost per assignment (s)",
                          title="Planned travel time to the task per assignment vs N")
        plots.metric_vs_n(dm, "conflict_free_rate_mean", out / "success_vs_n.png",
                          ci="conflict_free_rate_ci95", scale=100, ylim=(-2, 105),
                          ylabel="conflict-free success rate (%)",
                          title="Conflict-free success rate vs N (mean, 95 % CI)")
        plots.metric_vs_n(dm, "decision_ms_mean", out / "alloc_time_vs_n.png",
                          ci="decision_ms_ci95", log=True,
                          ylabel="wall time per decision (ms, log scale)",
                          title="Allocation time per decision vs N")
        s += [("h2", "Tables I and III (dynamic): per task"),
              ("p", ("Tasks are released over time, so each allocator drives its own "
                     "trajectory through the run: summed planned costs are not comparable. "
                     "Per task instead, mean over seeds ± 95 % half-width: served = completed "
                     "/ released; wait = release → pickup over the tasks picked up; cost = "
                     "planned seconds from the vehicle to the task per assignment; "
                     "conflict-free = share of the offered tasks assigned without a conflict; "
                     "wall milliseconds per decision (cost matrix + allocator).")),
              ("table", table_dynamic(dm)),
              ("img", "served_vs_n.png"), ("img", "wait_vs_n.png"),
              ("img", "cost_per_task_vs_n.png"), ("img", "success_vs_n.png"),
              ("img", "alloc_time_vs_n.png")]
        figures = list(DYNAMIC_FIGURES) if not len(static_runs) else list(FIGURES) + [
            "served_vs_n.png", "wait_vs_n.png", "cost_per_task_vs_n.png"]
    ids = set(summary["run_id"])
    t = tasks.loc[tasks["run_id"].isin(ids)]
    plots.wait_distribution(M.wait_times(t), out / "wait_times.png")
    taxi = M.taxi_metrics(summary, t, vehicles.loc[vehicles["run_id"].isin(ids)],
                          events.loc[events["run_id"].isin(ids)])
    s += [("h2", "Service metrics"),
          ("p", ("Wait = release → pickup (s), pooled over the seeds; rejectionRate = "
                 "(rejected + expired + unreachable) / requests; approach_delay = realized "
                 "approach time − planned cost (reservation waits, replans); path_stretch = "
                 "metres driven / straight line per leg; utilization = time driving to a task "
                 f"or serving it / time not broken down. All columns: {service}.")),
          ("table", _taxi_view(taxi, VOXEL_TAXI_COLUMNS)),
          ("img", "wait_times.png")]
    run_id = run_id or default_run(summary, reference)
    run = res.run(run_id)
    try:
        world = res.world(run_id)[0]
    except KeyError:
        world = None
    r = run["summary"].iloc[0]
    label = f"{r['allocator']}, N = {r['n_agents']}, seed {r['seed']}"
    plots.gantt(run["events"], run["vehicles"], out / "timeline.png",
                title=f"Vehicle timeline: {label}", end=float(r["sim_time"]))
    plots.paths_3d(run["events"], run["vehicles"], run["obstacles"], run["tasks"],
                   out / "paths_3d.png", world=world, title=f"Paths and obstacles: {label}")
    s += [("h2", f"One run in detail: {run_id}"),
          ("p", ("Vehicle timeline (busy = travelling to or serving a task; waiting = holding "
                 "a cell or assigned but not yet moving; idle) and the vehicles' paths among "
                 "the obstacles.")),
          ("img", "timeline.png"), ("img", "paths_3d.png")]
    written += [out / f for f in figures]
    return s


def _road_part(res, summary, tasks, vehicles, events, direct, out, written, only,
               run_id) -> list:
    """The taxi study: metrics, per-hour series, map, hourly plots, fleet states, waits."""
    import numpy as np

    from analysis import taxi_plots as TP
    from analysis.network import road_network
    from analysis.timeline import fleet_states

    ids = set(summary["run_id"])
    pick = tasks["run_id"].isin(ids).to_numpy()
    t = tasks.loc[pick]
    d = None if direct is None else np.asarray(direct)[pick]
    v = vehicles.loc[vehicles["run_id"].isin(ids)]
    e = events.loc[events["run_id"].isin(ids)]
    taxi = M.taxi_metrics(summary, t, v, e, d)
    bin_s = TP.time_bin(float(summary["sim_time"].max()))
    summary = M.with_series(summary, summary)
    keys = M.series_keys(summary)
    trips = M.with_series(M.trip_table(t, e, d), summary)
    hc = M.hourly_customers(trips, keys)
    hc_bins = hc if bin_s == 3600 else M.hourly_customers(trips, keys, bin_s=bin_s)
    states = []
    ends = summary.set_index("run_id")["sim_time"].to_dict()
    for rid, vg in v.groupby("run_id", sort=False):
        mine = t.loc[t["run_id"] == rid]
        riders = (mine.set_index("task_id")["passengers"] if "passengers" in mine else None)
        states.append(fleet_states(e.loc[e["run_id"] == rid], vg, end=float(ends[rid]),
                                   passengers=riders))
    states = pd.concat(states, ignore_index=True) if states else pd.DataFrame(
        columns=["run_id", "agent_id", "state", "start", "end", "onboard"])
    hf = M.hourly_fleet(states, summary, keys)
    hf_bins = hf if bin_s == 3600 else M.hourly_fleet(states, summary, keys, bin_s=bin_s)
    hc.to_csv(out / "hourly_customers.csv", index=False)
    hf.to_csv(out / "hourly_fleet.csv", index=False)
    written += [out / "hourly_customers.csv", out / "hourly_fleet.csv"]

    # the map and the stations: one run of each scenario (the chosen run for its own)
    run_ids, nets, panels = {}, {}, []
    for scen_name, g in summary.groupby("scenario", sort=True):
        rid = run_id if run_id in set(g["run_id"]) else default_run(g)
        r = g.loc[g["run_id"] == rid].iloc[0]
        rt, rv = t.loc[t["run_id"] == rid], v.loc[v["run_id"] == rid]
        try:
            net = road_network(res.metadata(rid, "tasks"), [s.path for s in res.sources])
        except KeyError:
            net = None
        run_ids[str(scen_name)], nets[str(scen_name)] = rid, net
        panels.append(TP.MapPanel(
            f"{scen_name}\nseed {r['seed']}: {len(rt)} requests, N = {r['n_agents']}",
            rt[["x", "y"]].to_numpy(dtype=float),
            rv[["x0", "y0"]].to_numpy(dtype=float),
            None if net is None else net.xy, None if net is None else net.edges))
    scen = TP.scenario_title(summary["scenario"].unique())
    TP.network_map(out / "map.png", panels,
                   title="Streets, demand and where the fleet starts" + (
                       ", one scenario a row" if len(panels) > 1 else ""))
    cols = TP.series_columns(summary)
    runs = {k if isinstance(k, tuple) else (k,): n
            for k, n in summary.groupby(cols)["run_id"].nunique().items()}
    TP.hourly(hc_bins, out / "hourly.png", bin_s=bin_s, runs=runs, only=only,
              title=f"{scen}: demand, service and waiting (by time of release)")
    TP.fleet_state(hf_bins, out / "fleet_state.png", bin_s=bin_s, only=only,
                   title=f"{scen}: fleet state over time (mean vehicles per state)")
    TP.wait_by_group(trips.loc[trips["wait"].notna()], out / "wait_by_allocator.png", only=only,
                     title=f"{scen}: wait from release to pickup, seeds pooled")
    written += [out / f for f in ROAD_FIGURES]
    from analysis.energy_metrics import ENERGY_COLUMNS
    from analysis.energy_plots import energy_section

    files, energy = energy_section(res, summary, out, nets, run_ids, keys)
    written += files
    from analysis.transit_plots import transit_section

    files, transit = transit_section(res, summary, out)
    written += files
    if energy:  # the energy columns of taxi.csv, after the section's heading and text
        energy[2:2] = [("p", ENERGY_NOTE),
                       ("table", _taxi_view(taxi.loc[taxi["kwh_drawn_per_vehicle"].notna()],
                                            ["runs", *ENERGY_COLUMNS]))]
    unit = "one hour" if bin_s == 3600 else f"{bin_s / 60:g} minutes"
    return [
        ("h2", "Taxi study: customers and fleet"),
        ("p", ("Per series (allocator, fleet size N and, where they differ, batch window, "
               "scenario and repositioner), requests pooled over the seeds; a ± gives the "
               "half-width of the 95 % Student-t interval of the mean over seeds (the runs' "
               "own values; none with one seed). The columns are defined below the table.")),
        ("table", _taxi_view(taxi, TAXI_COLUMNS + (SHARED_COLUMNS if _pooled(taxi) else []))),
        ("p", "Columns (named as MATSim DRT's customer and vehicle stats print them):"),
        ("list", TAXI_GLOSSARY),
        ("p", "All columns: taxi.csv; per hour (customers by hour of release, fleet by clock "
              "hour): hourly_customers.csv, hourly_fleet.csv."),
        ("img", "map.png"),
        ("p", f"Over time, in bins of {unit} (the CSV files are per hour):"),
        ("img", "hourly.png"), ("img", "fleet_state.png"), ("img", "wait_by_allocator.png"),
        *energy, *transit,
    ]


#: What the taxi table's columns mean: one short line each, below the table (a paragraph
#: above it hid the table under 250 words)
TAXI_GLOSSARY = (
    "rides: served trips",
    "rejections: rejected at once + expired waiting + unreachable",
    "cut_off: still waiting or aboard when the run ended (the run's end cut them off; a count "
    "of their own, not a rejection)",
    "failed: aboard a vehicle that broke down (rides + rejections + cut_off + failed = "
    "requests)",
    "service_rate, rejectionRate, cutOffRate: rides, rejections, cut_off / requests (%, one "
    "decimal, as utilization, emptyRatio and shared_rate; taxi.csv holds 0-1)",
    "wait: release → pickup (s; median, p90 by linear interpolation)",
    "inVehicleTravelTime: pickup → drop-off (s)",
    "detour_ratio: in-vehicle time / the trip's direct free-flow time (1: driven straight at "
    "free flow)",
    "utilization: share of the vehicles' available time (not broken down) driving to a "
    "pickup or with a passenger (FleetPy's '% fleet utilization')",
    "emptyRatio: km without a passenger / all km (FleetPy's '% empty vkm')",
    "vkm_per_ride: vehicle km per served trip",
    "with shared rides: occupancy = passenger-km / vehicle-km (MATSim DRT's), shared_rate = "
    "share of the rides during which another request was on board, delay_mean = drop-off - "
    "release - direct free-flow time (s)",
)

#: What the energy table says (taxi.csv's energy columns, :mod:`analysis.energy_metrics`).
ENERGY_NOTE = ("Per series: kWh drawn (driving and auxiliary load) and charged, mean per "
               "vehicle; charges started (plug-ins) and strandings (a battery run empty) "
               "summed over the seeds; soc_min = the lowest state of charge any vehicle "
               "reached, soc_end_mean = the vehicles' mean at the end (%); seconds queued "
               "for a plug, mean per vehicle. Columns of taxi.csv (runs.csv per run).")


def _markdown(sections) -> str:
    parts = []
    for kind, body in sections:
        if kind == "h1":
            parts.append(f"# {body}")
        elif kind == "h2":
            parts.append(f"## {body}")
        elif kind == "p":
            parts.append(body)
        elif kind == "list":
            parts.append("\n".join(f"- {item}" for item in body))
        elif kind == "table":
            parts.append(markdown_table(body))
        elif kind == "img":
            parts.append(f"![{Path(body).stem}]({body})")
    return "\n\n".join(parts) + "\n"


def _html(sections) -> str:
    style = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
             "table{border-collapse:collapse;font-size:90%}td,th{border:1px solid #ccc;"
             "padding:3px 6px;text-align:right}img{max-width:100%}")
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>dispatch report</title>",
             f"<style>{style}</style></head><body>"]
    for kind, body in sections:
        if kind in ("h1", "h2"):
            parts.append(f"<{kind}>{html.escape(body)}</{kind}>")
        elif kind == "p":
            parts.append(f"<p>{html.escape(body).replace('**', '')}</p>")
        elif kind == "list":
            parts.append("<ul>" + "".join(f"<li>{html.escape(item)}</li>" for item in body)
                         + "</ul>")
        elif kind == "table":
            view = body.map(_fmt) if hasattr(body, "map") else body.applymap(_fmt)
            parts.append(view.to_html(index=False, escape=True))
        elif kind == "img":
            parts.append(f"<p><img src='{html.escape(body)}' alt='{html.escape(body)}'></p>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
