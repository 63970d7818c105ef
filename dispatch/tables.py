"""Paper-style result tables from run summaries (Tables I and III of the MAGNNET paper)."""

from __future__ import annotations

import math
from collections import defaultdict
from statistics import fmean

PREFERRED_ORDER = ("hungarian", "local_hungarian", "magnnet", "auction", "greedy", "random")


def allocator_order(names) -> list[str]:
    names = set(names)
    first = [n for n in PREFERRED_ORDER if n in names]
    return first + sorted(names - set(first))


def aggregate(summaries: list[dict], reference: str = "hungarian") -> dict[tuple[str, int], dict]:
    """Per (allocator, n_agents): mean total cost, mean paired gap to ``reference`` (same seed,
    planner and N), mean conflict-free rate, mean allocation seconds, number of runs."""
    ref = {
        (s["planner"], s["n_agents"], s["seed"]): s["total_cost"]
        for s in summaries if s["allocator"] == reference
    }
    groups: dict[tuple[str, int], list[dict]] = defaultdict(list)
    for s in summaries:
        groups[(s["allocator"], s["n_agents"])].append(s)
    out = {}
    for key, rows in groups.items():
        gaps = [
            (r["total_cost"] - ref[k]) / ref[k]
            for r in rows
            if (k := (r["planner"], r["n_agents"], r["seed"])) in ref and ref[k] > 0
        ]
        rates = [r["conflict_free_rate"] for r in rows if not math.isnan(r["conflict_free_rate"])]
        out[key] = {
            "runs": len(rows),
            "total_cost": fmean(r["total_cost"] for r in rows),
            "gap": fmean(gaps) if gaps else math.nan,
            "conflict_free_rate": fmean(rates) if rates else math.nan,
            "alloc_seconds": fmean(r["alloc_seconds"] for r in rows),
            "first_decision_seconds": fmean(r["first_decision_seconds"] for r in rows),
            "tasks_completed": fmean(r["tasks_completed"] for r in rows),
        }
    return out


def render(summaries: list[dict], console=None) -> None:
    """Print Table I (total travel cost, gap to Hungarian) and Table III (conflict-free success
    rate, allocation time) with rich."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    agg = aggregate(summaries)
    allocs = allocator_order({a for a, _ in agg})
    sizes = sorted({n for _, n in agg})
    runs = {n: max(agg[(a, n)]["runs"] for a in allocs if (a, n) in agg) for n in sizes}

    t1 = Table(title="Table I: total travel cost (s), mean over seeds [gap to Hungarian]")
    t1.add_column("N", justify="right")
    t1.add_column("runs", justify="right")
    for a in allocs:
        t1.add_column(a, justify="right")
    for n in sizes:
        cells = []
        for a in allocs:
            r = agg.get((a, n))
            if r is None:
                cells.append("-")
            elif a == "hungarian" or math.isnan(r["gap"]):
                cells.append(f"{r['total_cost']:.1f}")
            else:
                # + 0.0 turns a rounding-level -0.0 (equal totals summed in another order) into 0
                cells.append(f"{r['total_cost']:.1f} [{round(100 * r['gap'], 1) + 0.0:+.1f}%]")
        t1.add_row(str(n), str(runs[n]), *cells)
    console.print(t1)

    t3 = Table(title="Table III: conflict-free success rate (%) / allocation time (s)")
    t3.add_column("N", justify="right")
    for a in allocs:
        t3.add_column(a, justify="right")
    for n in sizes:
        cells = []
        for a in allocs:
            r = agg.get((a, n))
            cells.append("-" if r is None else
                         f"{100 * r['conflict_free_rate']:.1f} / {r['first_decision_seconds']:.3f}")
        t3.add_row(str(n), *cells)
    console.print(t3)
    console.print("allocation time: wall seconds of the first decision (cost matrix + allocator), "
                  "mean over seeds")


def render_trips(summaries: list[dict], console=None) -> None:
    """Print the trip table of road-network runs: per allocator and fleet size, the mean over
    seeds of trips released, the share served, rejected and expired, the mean wait (release to
    pickup), the fleet's empty and occupied kilometres and the wall seconds spent deciding."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    groups: dict[tuple[str, int], list[dict]] = defaultdict(list)
    for s in summaries:
        groups[(s["allocator"], s["n_agents"])].append(s)
    runs = max((len(g) for g in groups.values()), default=0)
    t = Table(title=f"Trips, mean over {runs} seed(s): served, rejected, expired, wait "
                    f"(release to pickup), empty and occupied km, deciding seconds")
    for col in ("allocator", "N", "trips", "served", "rej.", "exp.", "wait s", "empty km",
                "occ. km", "dec. s"):
        t.add_column(col, justify="left" if col == "allocator" else "right")
    for alloc in allocator_order({a for a, _ in groups}):
        for n in sorted(k for a, k in groups if a == alloc):
            rows = groups[(alloc, n)]

            def mean(key, rows=rows):
                vals = [r[key] for r in rows if not math.isnan(r[key])]
                return fmean(vals) if vals else math.nan

            served = fmean(r["tasks_completed"] / r["n_tasks"] if r["n_tasks"] else math.nan
                           for r in rows)
            t.add_row(alloc, str(n), f"{mean('n_tasks'):.0f}",
                      "-" if math.isnan(served) else f"{100 * served:.1f}%",
                      f"{mean('tasks_rejected'):.0f}", f"{mean('tasks_expired'):.0f}",
                      f"{mean('wait_time_mean'):.1f}", f"{mean('empty_distance') / 1000:.0f}",
                      f"{mean('occupied_distance') / 1000:.0f}", f"{mean('alloc_seconds'):.2f}")
    console.print(t)
