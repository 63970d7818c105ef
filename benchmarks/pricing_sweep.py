"""Benchmark: a ``[pricing]`` sweep of riders who may decline (issue 31, offers).

``scenarios/nyc_manhattan_offers.toml`` (the pooled NYC taxi day of Sunday 2014-12-21 on the
OSMnx Manhattan network, 4 seats, ``rtv`` batched every 30 s, requests wait at most 5 min
and arrive at most 10 min later than a direct ride; riders answer each offer by the file's
``logit`` acceptor of wait, in-vehicle time and fare, and a declined request is offered once
more) cut to its first ``--hours`` (default 2) with ``--agents`` taxis (default 100: the
night's demand is a few hundred trips an hour). Each per-km fare of ``--per-km`` (the base,
per-minute fare and sharing discount are the file's) runs ``--seeds`` seeds (the fleet's start
nodes, the riders' draws); every fare runs on the same seeds.

Prints, per fare: the served share (completed / released), the declined share (closed
``declined`` / released), the mean fare of a completed ride, and the revenue per
vehicle-hour (fares of the completed rides / (taxis x simulated hours)), each the mean over
the seeds with a 95 % t-interval (``mean ± half-width``), and the offers made per request.

Run under ``nice``: ``nice -n 10 .venv/bin/python benchmarks/pricing_sweep.py [--seeds 3]
[--hours 2] [--agents 100] [--per-km 0.5 1 2 3 5 8]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from benchmarks.nyc_study import interval  # noqa: E402
from dispatch.run.runner import run_one  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402

SCENARIO = ROOT / "scenarios" / "nyc_manhattan_offers.toml"


def one(sc, per_km: float, agents: int, seed: int) -> dict:
    """The figures of one run at ``per_km``."""
    sc = replace(sc, pricing=replace(sc.pricing, per_km=per_km))
    [spec] = sc.runs(agents=agents, seed=seed)
    t0 = time.perf_counter()
    r = run_one(spec)
    wall = time.perf_counter() - t0
    s = r.summary
    tasks = r.tables["tasks"].to_pandas()
    n = s["n_tasks"]
    hours = s["sim_time"] / 3600.0
    done = tasks[tasks.state == "completed"]
    return {"served": s["tasks_completed"] / n, "declined": s["tasks_declined"] / n,
            "fare": float(done.fare.mean()), "revenue_vh": s["revenue"] / (agents * hours),
            "offers": s["offers"] / n, "wall": wall, "n": n}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--hours", type=float, default=2.0)
    p.add_argument("--agents", type=int, default=100)
    p.add_argument("--per-km", type=float, nargs="+", default=[0.5, 1.0, 2.0, 3.0, 5.0, 8.0])
    args = p.parse_args(argv)
    console = Console(width=130)
    sc = load_scenario(SCENARIO)
    sc = replace(sc, duration=args.hours * 3600.0)
    pr, logit = sc.pricing, dict(sc.acceptor.params)
    console.print(f"{SCENARIO.name}: first {args.hours:g} h, {args.agents} taxis of "
                  f"{sc.fleet.capacity} seats, {sc.dispatch.allocator} batched "
                  f"{sc.dispatch.batch_window:g} s; fare = {pr.base:g} + per_km x km + "
                  f"{pr.per_minute:g} x min, {100 * pr.sharing_discount:g} % off shared; "
                  f"acceptor {sc.acceptor.name} {logit}, retries {sc.acceptor.retries}; "
                  f"seeds 0..{args.seeds - 1}")
    rows = {}
    for per_km in args.per_km:
        runs = []
        for seed in range(args.seeds):
            r = one(sc, per_km, args.agents, seed)
            console.print(f"  per_km {per_km:g}, seed {seed}: served {100 * r['served']:.1f} %, "
                          f"declined {100 * r['declined']:.1f} %, revenue "
                          f"{r['revenue_vh']:.2f} / vehicle-hour ({r['n']} requests, "
                          f"{r['wall']:.0f} s)")
            runs.append(r)
        rows[per_km] = runs
    t = Table(title=f"pricing sweep: mean over {args.seeds} seeds ± 95 % t-interval",
              title_justify="left")
    for c in ("per km", "served %", "declined %", "offers / request", "fare / ride",
              "revenue / vehicle-hour"):
        t.add_column(c, justify="right")
    for per_km, runs in rows.items():
        def col(k, scale=1.0):
            return [scale * r[k] for r in runs]
        t.add_row(f"{per_km:g}", interval(col("served", 100), ".1f"),
                  interval(col("declined", 100), ".1f"), interval(col("offers"), ".3f"),
                  interval(col("fare"), ".2f"), interval(col("revenue_vh"), ".2f"))
    console.print(t)


if __name__ == "__main__":
    main()
