"""A report of one or more results folders: paper-style tables, taxi-style metrics, plots.

``write_report(paths, out)`` writes into ``out``:

* ``report.md`` (or ``report.html``): the tables and the figures below, with definitions;
* ``allocators.csv`` (Tables I and III per allocator and N, see
  :func:`analysis.metrics.allocator_metrics`) and ``taxi.csv`` (taxi-style metrics,
  :func:`analysis.metrics.taxi_metrics`), ``runs.csv`` (taxi-style metrics per run);
* ``cost_vs_n.png``, ``success_vs_n.png``, ``alloc_time_vs_n.png``, ``wait_times.png``,
  ``timeline.png`` (vehicle Gantt of one run) and ``paths_3d.png`` (that run in 3D).
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

FIGURES = ("cost_vs_n.png", "success_vs_n.png", "alloc_time_vs_n.png", "wait_times.png",
           "timeline.png", "paths_3d.png")

TAXI_COLUMNS = ["runs", "requests", "rides", "service_rate", "wait_average", "wait_median",
                "wait_p90", "wait_max", "assignment_delay_average", "detour_time_average",
                "detourDistanceRatio_mean", "utilization", "totalDistance",
                "totalEmptyDistance", "emptyRatio"]


def default_run(summary: pd.DataFrame, reference: str = "hungarian") -> str:
    """The run a report shows in detail: the reference allocator's (else the first
    allocator's) largest fleet, smallest seed."""
    allocs = M.allocator_order(summary["allocator"].unique())
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


def _taxi_view(taxi: pd.DataFrame) -> pd.DataFrame:
    keys = ["allocator", "n_agents"] + [k for k in ("scenario", "planner")
                                         if taxi[k].nunique() > 1]
    cols = [c for c in TAXI_COLUMNS if c in taxi.columns]
    return taxi[keys + cols].rename(columns={"n_agents": "N"})


def write_report(source: Results | str | os.PathLike | list, out: str | os.PathLike, *,
                 fmt: str = "md", run_id: str | None = None,
                 reference: str = "hungarian") -> list[Path]:
    """Write the report of ``source`` (a :class:`Results` or one or more folders) into
    ``out``; returns the files written (the report first)."""
    if fmt not in ("md", "html"):
        raise ValueError(f"report format must be 'md' or 'html', got {fmt!r}")
    res = source if isinstance(source, Results) else open_results(
        *(source if isinstance(source, (list, tuple)) else [source]))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = res.summary
    if summary.empty:
        raise ValueError(f"{res}: no runs in the summary table")
    tasks, vehicles = res.table("tasks"), res.table("vehicles")
    events = res.table("events", columns=["run_id", "t", "event", "agent_id", "task_id",
                                          "x", "y", "z"])
    am = M.allocator_metrics(summary, reference)
    taxi = M.taxi_metrics(summary, tasks, vehicles, events)
    per_run = M.run_metrics(summary, tasks, vehicles, events)
    written: list[Path] = []
    for name, df in (("allocators.csv", am), ("taxi.csv", taxi), ("runs.csv", per_run)):
        df.to_csv(out / name, index=False)
        written.append(out / name)

    plots.cost_vs_n(am, out / "cost_vs_n.png")
    plots.success_vs_n(am, out / "success_vs_n.png")
    plots.alloc_time_vs_n(am, out / "alloc_time_vs_n.png")
    plots.wait_distribution(M.wait_times(tasks), out / "wait_times.png")
    run_id = run_id or default_run(summary, reference)
    run = res.run(run_id)
    try:
        world = res.world(run_id)[0]
    except KeyError:
        world = None
    s = run["summary"].iloc[0]
    label = f"{s['allocator']}, N = {s['n_agents']}, seed {s['seed']}"
    plots.gantt(run["events"], run["vehicles"], out / "timeline.png",
                title=f"Vehicle timeline: {label}", end=float(s["sim_time"]))
    plots.paths_3d(run["events"], run["vehicles"], run["obstacles"], run["tasks"],
                   out / "paths_3d.png", world=world, title=f"Paths and obstacles: {label}")
    written += [out / f for f in FIGURES]

    errors = res.errors()
    sections = _sections(res, summary, am, taxi, run_id, errors, reference)
    report = out / f"report.{fmt}"
    text = _markdown(sections) if fmt == "md" else _html(sections)
    tmp = report.with_name(f".{report.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(report)
    return [report, *written]


def _sections(res, summary, am, taxi, run_id, errors, reference) -> list:
    """The report as a list of ("h", text) / ("p", text) / ("table", df) / ("img", file)."""
    scen = ", ".join(sorted(summary["scenario"].unique()))
    allocs = ", ".join(M.allocator_order(summary["allocator"].unique()))
    ns = ", ".join(map(str, sorted(summary["n_agents"].unique())))
    seeds = summary["seed"].nunique()
    s = []
    s += [("h1", f"Report: {scen}"),
          ("p", (f"{len(summary)} runs from {', '.join(str(x.path) for x in res.sources)}: "
                 f"allocators {allocs}; N = {ns}; {seeds} seed(s).")
                + (f" **{len(errors)} run(s) failed** (see the end)." if len(errors) else ""))]
    s += [("h2", "Table I: total travel cost"),
          ("p", ("Sum of the planned travel times c_ij (s) of the assignments made; mean over "
                 "seeds ± half-width of the 95 % Student-t interval; in brackets the mean gap "
                 f"to {reference} on the same instance (same seed, N, planner).")),
          ("table", table_i(am, reference)),
          ("img", "cost_vs_n.png")]
    s += [("h2", "Table III: conflict-free success rate and allocation time"),
          ("p", ("Share of offered tasks assigned without ever being requested by two agents "
                 "in one round; wall time of the first decision (cost matrix + allocator), mean "
                 "over seeds.")),
          ("table", table_iii(am)),
          ("img", "success_vs_n.png"), ("img", "alloc_time_vs_n.png")]
    s += [("h2", "Taxi-style metrics"),
          ("p", ("Names as in MATSim DRT's customer / vehicle stats (FleetPy: service_rate = "
                 "'served users', wait_* = 'waiting time', utilization = '% fleet "
                 "utilization'). Wait = release → arrival of the vehicle (s), pooled over the "
                 "seeds; detourDistanceRatio = distance driven / straight line; utilization = "
                 "busy seconds / (vehicles × simulated time); every metre is driven to reach a "
                 "task with nothing on board, so empty distance = distance. All columns: "
                 "taxi.csv.")),
          ("table", _taxi_view(taxi)),
          ("img", "wait_times.png")]
    s += [("h2", f"One run in detail: {run_id}"),
          ("p", ("Vehicle timeline (busy = travelling to or serving a task; waiting = holding "
                 "a cell or assigned but not yet moving; idle) and the vehicles' paths among "
                 "the obstacles.")),
          ("img", "timeline.png"), ("img", "paths_3d.png")]
    if len(errors):
        cols = [c for c in ("run_id", "error_type", "message") if c in errors.columns]
        s += [("h2", "Failed runs"), ("table", errors[cols])]
    s += [("p", "Files: allocators.csv (Tables I/III, all columns), taxi.csv, runs.csv (per run).")]
    return s


def _markdown(sections) -> str:
    parts = []
    for kind, body in sections:
        if kind == "h1":
            parts.append(f"# {body}")
        elif kind == "h2":
            parts.append(f"## {body}")
        elif kind == "p":
            parts.append(body)
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
        elif kind == "table":
            view = body.map(_fmt) if hasattr(body, "map") else body.applymap(_fmt)
            parts.append(view.to_html(index=False, escape=True))
        elif kind == "img":
            parts.append(f"<p><img src='{html.escape(body)}' alt='{html.escape(body)}'></p>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
