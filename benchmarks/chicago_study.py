"""The Chicago taxi study (issue 10, "Measure and report"): allocators x fleet sizes x batch
window x repositioning on a simulated day of Chicago taxi demand, with its table and report.

The runs: ``scenarios/chicago_taxi.toml`` with its numbers overridden (``--hours``,
``--trips-per-day``, ``--agents``, ``--seeds``) and its sweep replaced by ``--allocators``
(default ``fcfs greedy hungarian auction magnnet``; one that is not installed or fails to
construct is skipped with a message) x ``--batch-windows`` (default 0 = immediate and 30 s:
a run key: ``batch_window=0`` / ``batch_window=30`` partitions of scenario ``chicago_study``) x
``--repositioners`` (default ``stay demand``) x ``--agents`` (default 500 1000). The derived
scenario is written to ``<out>/chicago_study.toml`` and run through the normal resumable sweep
(:func:`dispatch.run.runner.sweep`) on ``--workers`` processes (default 2): rerunning skips every
run already complete in ``--out``, so an interrupted study resumes, and a rerun with other
``--allocators`` / ``--repositioners`` / ``--agents`` / ``--batch-windows`` adds only the runs
missing from the folder (a run is the same run whatever lists it was swept in:
:func:`dispatch.run.resume.run_digest`); the table and the report cover every run of the folder.
SIGTERM or Ctrl-C stops the study's worker processes with it.

``--comm-range METRES`` gives the vehicles a radio range: the derived scenario gets a ``[comms]``
table with ``range = METRES`` (see :mod:`dispatch.api.comms`: the idle vehicles of a decision within
that straight-line distance of each other hear each other). Decentralized allocators
(``auction``, ``magnnet``, ``local_hungarian``) then decide on what reaches them over that graph
and may conflict; centralized ones (``fcfs``, ``greedy``, ``hungarian``) ignore it. Omitted:
unlimited range, the scenario as it ships. A range is part of the derived scenario, so its runs
are other runs than the unlimited ones (use another ``--out``).

``--hours H`` (default 24) runs a shorter day for a quick look: the trips are still drawn for a
whole day (the sample's hour profile), the run stops at H h, so only the first H hours are
released; requests still open or aboard at the end count as cut off, not rejected. A full day
(H = 24) runs 26 h, as the scenario does, so the last trips can finish.

Then it prints (80 columns) and writes ``<out>/study.md``: per series (allocator, N, batch
window, repositioner) the share of the requests served, rejected and cut off (open or aboard
at the end: served + rejected + cut off + failed = 100 %), the wait (release to pickup) mean
and p90, each share and the mean wait with the half-width of its 95 % Student-t interval over
the seeds (``--seeds``, default 0 1 2), the fleet utilization, the empty share of the km, the
conflicts (tasks requested by two vehicles in one round at least once; ``study.md`` also the
conflict-free share of the tasks offered) and the run's wall seconds (mean over seeds, from the
sweep's completion markers), followed by a paragraph
computed from the table: who has the lowest mean wait per N and by how much, what batching
every 30 s changes, and what repositioning changes. Finally it writes the report
(``dispatch report``: ``<out>/report/``, the plots).

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/chicago_study.py --hours 3 --trips-per-day 40000
--agents 200 400 --out runs/chicago_quick`` (a quick look), or without options (the full study:
40 runs of a simulated day; see the report of the helper that wrote this for a time estimate).
Under a 2 km radio range: ``--comm-range 2000 --allocators magnnet auction local_hungarian
--repositioners stay --batch-windows 30 --out runs/chicago_range2km``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "chicago_taxi.toml"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "chicago_study")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--hours", type=float, default=24.0, help="simulated hours (24: a day)")
    p.add_argument("--trips-per-day", type=float, default=40000.0)
    p.add_argument("--agents", type=int, nargs="+", default=[500, 1000])
    p.add_argument("--allocators", nargs="+",
                   default=["fcfs", "greedy", "hungarian", "auction", "magnnet"])
    p.add_argument("--batch-windows", type=float, nargs="+", default=[0.0, 30.0])
    p.add_argument("--repositioners", nargs="+", default=["stay", "demand"])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2],
                   help="seeds (default 0 1 2: the tables give 95 %% intervals over them)")
    p.add_argument("--comm-range", type=float, default=None, metavar="METRES",
                   help="radio range of the vehicles ([comms] range; default: unlimited)")
    p.add_argument("--no-report", action="store_true", help="skip `dispatch report`")
    a = p.parse_args(argv)
    if not 0 < a.hours <= 24:
        p.error(f"--hours must be in (0, 24], got {a.hours:g}")
    if a.trips_per_day <= 0 or min(a.agents) <= 0 or a.workers <= 0:
        p.error("--trips-per-day, --agents and --workers must be positive")
    if min(a.batch_windows) < 0:
        p.error("--batch-windows must be >= 0")
    if a.comm_range is not None and not 0 <= a.comm_range < math.inf:
        p.error(f"--comm-range must be a finite number of metres >= 0, got {a.comm_range:g}")
    return a


def usable(kind: str, names: list[str]) -> list[str]:
    """The plugins of ``names`` that are installed and construct with their defaults; a
    message on stderr for each one left out."""
    from dispatch.api import registry
    ok = []
    for name in names:
        try:
            registry.load(kind, name)()
        except Exception as e:  # noqa: BLE001 - any broken plugin is skipped, not fatal
            print(f"skipping {kind} {name!r}: {type(e).__name__}: {e}", file=sys.stderr)
            continue
        ok.append(name)
    return ok


def derived_text(a: argparse.Namespace, allocators: list[str], repositioners: list[str]) -> str:
    """The text of scenarios/chicago_taxi.toml with this study's numbers and sweep (the same
    arguments give the same text, so a rerun resumes the same runs)."""
    text = SCENARIO.read_text(encoding="utf-8")
    text = text[:text.index("[sweep]")]
    duration = 93600.0 if a.hours >= 24 else a.hours * 3600.0
    subs = {r"^name = .*$": 'name = "chicago_study"',
            r"^duration = .*$": f"duration = {duration:.1f}",
            r"^agents = .*$": f"agents = {a.agents[0]}",
            r"^trips_per_day = .*$": f"trips_per_day = {a.trips_per_day:.1f}"}
    for pat, new in subs.items():
        text, n = re.subn(pat, new, text, count=1, flags=re.M)
        if n != 1:
            raise SystemExit(f"{SCENARIO}: no line matching {pat!r} to override")

    def arr(xs, fmt):
        return "[" + ", ".join(fmt(x) for x in xs) + "]"

    if getattr(a, "comm_range", None) is not None:
        if re.search(r"^\[comms\]", text, flags=re.M):
            raise SystemExit(f"{SCENARIO} has a [comms] table already; --comm-range would "
                             "need to edit it")
        text += ("[comms]  # benchmarks/chicago_study.py --comm-range\n"
                 f"range = {a.comm_range:.1f}\n\n")
    return text + (
        "[sweep]  # benchmarks/chicago_study.py\n"
        f"agents = {arr(a.agents, str)}\n"
        f"allocator = {arr(allocators, lambda s: json.dumps(s))}\n"
        f"batch_window = {arr(a.batch_windows, lambda w: f'{w:.1f}')}\n"
        f"reposition = {arr(repositioners, lambda s: json.dumps(s))}\n"
        f"seed = {arr(a.seeds, str)}\n")


def run_study(a: argparse.Namespace) -> tuple[Path, list]:
    """Write the derived scenario into ``a.out`` and sweep it there (resumable)."""
    from dispatch.run.runner import sweep
    from dispatch.scenario.load import load_scenario

    allocators = usable("allocator", a.allocators)
    repositioners = usable("repositioner", a.repositioners)
    if not allocators or not repositioners:
        raise SystemExit("no allocator or no repositioner left to run")
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "chicago_study.toml"
    text = derived_text(a, allocators, repositioners)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    specs = load_scenario(path).runs()
    print(f"{len(specs)} runs ({', '.join(allocators)}; N = {a.agents}; windows "
          f"{a.batch_windows} s; {', '.join(repositioners)}; {a.hours:g} h) into {a.out}",
          flush=True)
    started = time.perf_counter()
    done = [0]

    def on_done(o) -> None:
        done[0] += 1
        what = o.status if o.status != "failed" else f"FAILED ({o.error})"
        rid = o.run_id.replace("chicago_study-", "").replace("__dijkstra", "")
        print(f"[{done[0]:>3}/{len(specs)}] {rid[:46]:<46} {what:<8} {o.seconds:7.1f} s",
              flush=True)

    outcomes = sweep(specs, a.out, workers=a.workers, on_done=on_done)
    print(f"sweep: {time.perf_counter() - started:.1f} s wall", flush=True)
    return path, outcomes


def wall_seconds(out: Path) -> dict[str, float]:
    """Per run id: the wall seconds of its run, from the sweep's completion markers."""
    secs = {}
    for m in (out / "_runs").rglob("done.json"):
        marker = json.loads(m.read_text(encoding="utf-8"))
        secs[marker["run_id"]] = float(marker["seconds"])
    return secs


def study_table(out: Path) -> pd.DataFrame:
    """Per series: ``label``, ``N``, ``served``, ``rejected``, ``cut_off`` and
    ``failed_share`` (shares of the requests; they add up to 1), ``wait_mean`` / ``wait_p90``
    (s), ``served_ci``, ``rejected_ci``, ``cut_off_ci``, ``wait_mean_ci`` (half-widths of the
    95 % intervals over seeds, NaN with one seed), ``utilization``, ``empty`` (share of km),
    ``conflicts`` (tasks requested by two vehicles in one round at least once: only
    decentralized allocators under a limited range, and ``greedy``, have any) and
    ``conflict_free`` (share of the tasks offered that were assigned without ever being in
    conflict), means over seeds, ``wall_s`` (mean wall seconds per run), plus the keys
    ``allocator``, ``window`` (``imm`` / ``30s``) and ``reposition``; rows in the report's
    series order."""
    from analysis import metrics as M
    from analysis.io import open_results
    from analysis.taxi_plots import series
    from paired.compare import window_label

    res = open_results(out)
    summary = M.with_series(res.summary, res.summary)
    taxi = M.taxi_metrics(summary, res.table("tasks"), res.table("vehicles"))
    secs = wall_seconds(out)
    summary = summary.assign(wall_s=summary["run_id"].map(secs))
    keys = M.series_keys(summary)  # the run keys but the seed (the files say which)
    wall = summary.groupby(keys)["wall_s"].mean()
    confl = summary.groupby(keys)[["conflicts", "conflict_free_rate"]].mean()
    rows = []
    for key, label, g in series(taxi):
        r = g.iloc[0]
        rows.append({
            "label": re.sub(r" N=\d+", "", label),  # N has its own column
            "allocator": r["allocator"], "N": int(r["n_agents"]),
            "window": window_label(r["batch_window"]), "reposition": r["reposition"],
            "runs": int(r["runs"]), "served": r["service_rate"], "rejected": r["rejectionRate"],
            "cut_off": r.get("cutOffRate", math.nan), "failed_share": (
                r.get("failed", 0) / r["requests"] if r["requests"] else math.nan),
            "served_ci": r.get("service_rate_ci95", math.nan),
            "rejected_ci": r.get("rejectionRate_ci95", math.nan),
            "cut_off_ci": r.get("cutOffRate_ci95", math.nan),
            "wait_mean_ci": r.get("wait_average_ci95", math.nan),
            "wait_mean": r["wait_average"], "wait_p90": r["wait_p90"],
            "utilization": r["utilization"], "empty": r["emptyRatio"],
            "conflicts": confl["conflicts"].get(tuple(r[k] for k in keys), math.nan),
            "conflict_free": confl["conflict_free_rate"].get(tuple(r[k] for k in keys),
                                                             math.nan),
            "wall_s": wall.get(tuple(r[k] for k in keys), math.nan)})
    return pd.DataFrame(rows)


def _pct(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{100 * v:.1f}%"


def _num(v: float, digits: int = 0) -> str:
    return "-" if not math.isfinite(v) else f"{v:.{digits}f}"


def _pm(r, col: str, *, pct: bool, digits: int, md: bool) -> str:
    """``mean±half-width`` of the 95 % interval over seeds (``<col>_ci``; the mean alone with
    one seed); percentages without their sign in the terminal (the header says %)."""
    v, h = float(r.get(col, math.nan)), float(r.get(f"{col}_ci", math.nan))
    if not math.isfinite(v):
        return "-"
    scale = 100 if pct else 1
    m = f"{scale * v:.{digits}f}" + ("%" if pct and md else "")
    if not math.isfinite(h):
        return m
    return f"{m} ± {scale * h:.{digits}f}" if md else f"{m}±{scale * h:.{digits}f}"


#: (header, width in the terminal table (0: only in study.md), cell of a row (md: for
#: study.md)); served + rejected + cut off (+ failed) add up to the requests.
COLUMNS = [
    ("series", 17, lambda r, md: str(r["label"])),
    ("N", 4, lambda r, md: str(r["N"])),
    ("served%", 9, lambda r, md: _pm(r, "served", pct=True, digits=1, md=md)),
    ("rej%", 5, lambda r, md: _pm(r, "rejected", pct=True, digits=1, md=md) if md
     else _num(100 * r["rejected"], 1)),
    ("cut%", 5, lambda r, md: _pm(r, "cut_off", pct=True, digits=1, md=md) if md
     else _num(100 * r.get("cut_off", math.nan), 1)),
    ("wait s", 7, lambda r, md: _pm(r, "wait_mean", pct=False, digits=0, md=md)),
    ("p90", 0, lambda r, md: _num(r["wait_p90"])),
    ("util%", 5, lambda r, md: _pct(r["utilization"]) if md else _num(100 * r["utilization"], 1)),
    ("empty%", 0, lambda r, md: _pct(r["empty"])),
    ("emp%", 4, lambda r, md: _num(100 * r["empty"], 0)),
    ("confl.", 6, lambda r, md: _num(r.get("conflicts", math.nan))),
    ("conflict-free", 0, lambda r, md: _pct(r.get("conflict_free", math.nan))),
    ("wall s", 7, lambda r, md: _num(r["wall_s"], 1)),
]
MD_SKIP = {"emp%"}  # the terminal's short form of a study.md column


def text_table(t: pd.DataFrame) -> str:
    """The study table in at most 80 columns (a long series label is cut with '…'; the
    p90 wait, the intervals of the rejected and cut-off shares and the conflict-free share
    only in :func:`markdown_table`)."""
    def line(cells):
        out = []
        for (_, w, _), c in zip(COLUMNS, cells):
            if w == 0:
                continue
            c = c if len(c) <= w else c[:w - 1] + "…"
            out.append(c.ljust(w) if not out else c.rjust(w))
        return " ".join(out)

    head = line([c for c, _, _ in COLUMNS])
    rows = [line([f(r, False) for _, _, f in COLUMNS]) for _, r in t.iterrows()]
    return "\n".join([head, "-" * len(head), *rows])


def markdown_table(t: pd.DataFrame) -> str:
    cols = [c for c in COLUMNS if c[0] not in MD_SKIP]
    head = "| " + " | ".join(c for c, _, _ in cols) + " |"
    rule = "|" + "|".join("---" for _ in cols) + "|"
    return "\n".join([head, rule, *("| " + " | ".join(f(r, True) for _, _, f in cols) + " |"
                                    for _, r in t.iterrows())])


def _by(t: pd.DataFrame, col: str, a: str, b: str, keys: list[str]) -> pd.DataFrame:
    """Rows of ``t`` with ``col == a`` joined to their twins with ``col == b`` on ``keys``."""
    return t.loc[t[col] == a].merge(t.loc[t[col] == b], on=keys, suffixes=("_a", "_b"))


def _wait_change(j: pd.DataFrame, pairs: str) -> str:
    """How the mean wait changes from the ``_b`` to the ``_a`` rows of a :func:`_by` join."""
    dw = j["wait_mean_a"] - j["wait_mean_b"]
    return (f"mean wait lower in {int((dw < 0).sum())} of {len(j)} pairs {pairs}, change "
            f"{dw.mean():+.0f} s on average ({dw.min():+.0f} to {dw.max():+.0f})")


def findings(t: pd.DataFrame) -> str:
    """A paragraph computed from the study table: the lowest mean wait per N (and its margin
    over the next allocator), what the longest batch window changes against immediate
    dispatch, and what each repositioner changes against ``stay``."""
    out = []
    ok = t.loc[t["wait_mean"].notna()]
    for n, g in ok.groupby("N"):
        g = g.sort_values("wait_mean")
        best = g.iloc[0]
        other = g.loc[g["allocator"] != best["allocator"]]
        s = (f"N = {n}: lowest mean wait {best['label']} ({best['wait_mean']:.0f} s, "
             f"rejection {_pct(best['rejected'])})")
        if len(other):
            nxt = other.iloc[0]
            d = nxt["wait_mean"] - best["wait_mean"]
            if d < 0.5:  # e.g. immediate dispatch: one request at a time, the same choice
                s += f", tied with {nxt['label']} ({nxt['wait_mean']:.0f} s)"
            else:
                s += (f", {d:.0f} s ({100 * d / nxt['wait_mean']:.0f} %) below the best "
                      f"other allocator, {nxt['label']} ({nxt['wait_mean']:.0f} s)")
        worst = g.iloc[-1]
        s += (f"; highest {worst['label']} ({worst['wait_mean']:.0f} s)." if len(g) > 1
              else ".")
        out.append(s)
    windows = [w for w in t["window"].unique() if w != "imm"]
    if "imm" in set(t["window"]) and windows:
        w = max(windows, key=lambda v: float(v.removesuffix("s")) if v.endswith("s") else 0)
        j = _by(t, "window", w, "imm", ["allocator", "N", "reposition"])
        if len(j):
            dr = j["rejected_a"] - j["rejected_b"]
            out.append(
                f"Batching every {w} instead of immediately: "
                f"{_wait_change(j, '(allocator, N, repositioner)')}; "
                f"rejection rate lower in {int((dr < 0).sum())} of {len(j)}, "
                f"{100 * dr.mean():+.1f} points on average ({100 * dr.min():+.1f} to "
                f"{100 * dr.max():+.1f}).")
    for rep in [r for r in t["reposition"].unique() if r != "stay"]:
        j = _by(t, "reposition", rep, "stay", ["allocator", "N", "window"])
        if len(j):
            dr = j["rejected_a"] - j["rejected_b"]
            de = j["empty_a"] - j["empty_b"]
            out.append(
                f"Repositioning with {rep!r} instead of 'stay': "
                f"{_wait_change(j, '(allocator, N, window)')}; "
                f"rejection rate {100 * dr.mean():+.1f} points on average; empty share of "
                f"the km {100 * de.mean():+.1f} points.")
    return " ".join(out) if out else "No series to compare."


def main(argv=None) -> int:
    a = parse_args(argv)
    a.out = a.out.resolve()
    path, outcomes = run_study(a)
    failed = [o for o in outcomes if o.status == "failed"]
    t = study_table(a.out)
    hours = "a simulated day" if a.hours >= 24 else f"the first {a.hours:g} simulated hours"
    radio = ("unlimited radio range" if a.comm_range is None
             else f"radio range {a.comm_range:g} m (decentralized allocators decide on what "
                  "reaches them; centralized ones ignore it)")
    intro = (f"Chicago taxi study ({path.name}): {hours}, {a.trips_per_day:g} trips per day, "
             f"{radio}, seeds {a.seeds}. Per series (allocator, N, batch window, "
             "repositioner): share "
             "of the requests served, rejected (at once or expired) and cut off (open or "
             "aboard when the run ended; with the few failed these add up to 100 %), mean and "
             "p90 wait "
             "from release to pickup (s), fleet utilization (driving to a pickup or with a "
             "passenger), empty share of the km, conflicts (tasks requested by two vehicles in one "
             "round at least once) and the conflict-free share of the tasks offered, wall "
             "seconds per run (mean over seeds; the first run of each worker process also "
             "pays for loading the road network). A ± is the half-width of the 95 % "
             "Student-t interval of the mean over the seeds.")
    para = findings(t)
    print()
    print(text_table(t))
    print()
    import textwrap

    print(textwrap.fill(para, 80))
    md = a.out / "study.md"
    md.write_text(f"# Chicago taxi study\n\n{intro}\n\n{markdown_table(t)}\n\n{para}\n"
                  + (f"\n{len(failed)} run(s) failed: "
                     + "; ".join(f"{o.run_id}: {o.error}" for o in failed) + "\n"
                     if failed else ""), encoding="utf-8")
    t.to_csv(a.out / "study.csv", index=False)
    print(f"\nwritten: {md}, {a.out / 'study.csv'}")
    if failed:
        print(f"{len(failed)} run(s) failed (see {md})", file=sys.stderr)
    if not a.no_report:
        from analysis.report import write_report

        started = time.perf_counter()
        files = write_report(a.out, a.out / "report")
        print(f"report: {files[0]} ({time.perf_counter() - started:.0f} s)")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
