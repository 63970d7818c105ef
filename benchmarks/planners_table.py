"""Benchmark: the paper's Table II (mean path length per N) for A*, RRT* and R*.

Every run is a real simulation (:func:`dispatch.run.runner.run_one`) of the paper's static scenario
``scenarios/paper_static.toml`` (50 x 50 x 30 m world, 10 obstacles, N = M, half UAVs at 5 m/s,
half UGVs at 3 m/s, every task on the ground), Hungarian allocating, with the planner
overridden: the same worlds, fleets and tasks for every planner (instances are paired by seed).
Vehicles drive the planner's own paths, so a run's path length per assignment is the vehicles'
distance driven over the tasks completed (``vehicles.distance / tasks_completed``).

Reported per planner and N (over seeds):

* mean path length (m) per assignment, pooled over all assignments of all seeds (Table II);
* ratio of that length to A*'s on the same instances (A* is exact: ratios are >= 1 up to
  the allocator choosing other pairs with other costs);
* time per query: wall milliseconds of the planner's cost matrices divided by the N x M pairs
  they answer (``summary.cost_seconds``), each run from cold caches (as a sweep runs them), so
  one-off work (grid graphs, components, PyBullet clients) is included;
* share of tasks completed.

Run: ``.venv/bin/python benchmarks/planners_table.py [--seeds 10] [--sizes 4 8 12 20]
[--planners astar rrt_star rstar] [--out benchmarks/results/planners_table.parquet]``.
Prints rich tables and writes the table to ``--out`` and one row per run next to it
(``<out stem>_runs.parquet``).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from rich.console import Console
from rich.table import Table

from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.world import world_for

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "paper_static.toml"
SIZES = (4, 8, 12, 20)
PLANNERS = ("astar", "rrt_star", "rstar")
#: The paper's Table II: mean path length (m) of two planners inside MAGNNET.
PAPER = {"astar": {4: 5.75, 8: 13.63, 12: 20.83, 20: 38.40},
         "rrt_star": {4: 8.86, 8: 13.87, 12: 19.86, 20: 40.95}}
LABEL = {"astar": "A*", "rrt_star": "RRT*", "rstar": "R*"}


def one_run(scenario, planner: str, n: int, seed: int) -> dict:
    world_for.cache_clear()  # cold caches: the run pays for what it builds, as in a sweep
    spec = scenario.runs(allocator="hungarian", planner=planner, agents=n, seed=seed)[0]
    t0 = time.perf_counter()
    result = run_one(spec)
    wall = time.perf_counter() - t0
    s = result.summary
    veh = result.tables["vehicles"].to_pydict()
    distance = float(sum(veh["distance"]))
    done = int(sum(veh["tasks_completed"]))
    dec = result.tables["decisions"].to_pydict()
    pairs = int(sum(a * t for a, t in zip(dec["n_idle"], dec["n_tasks"])))
    return {"planner": planner, "n_agents": n, "seed": seed, "distance_m": distance,
            "tasks_completed": done, "n_tasks": int(s["n_tasks"]),
            "path_m": distance / done if done else math.nan,
            "total_cost_s": float(s["total_cost"]), "cost_seconds": float(s["cost_seconds"]),
            "cost_pairs": pairs, "run_seconds": wall}


def summarize(rows: list[dict], planners, sizes) -> list[dict]:
    by = {(r["planner"], r["n_agents"], r["seed"]): r for r in rows}
    seeds = sorted({r["seed"] for r in rows})
    table = []
    for pl in planners:
        for n in sizes:
            rs = [by[(pl, n, s)] for s in seeds if (pl, n, s) in by]
            dist = sum(r["distance_m"] for r in rs)
            done = sum(r["tasks_completed"] for r in rs)
            ref = [by[("astar", n, r["seed"])] for r in rs if ("astar", n, r["seed"]) in by]
            ref_len = (sum(r["distance_m"] for r in ref) / sum(r["tasks_completed"] for r in ref)
                       if ref and sum(r["tasks_completed"] for r in ref) else math.nan)
            per_run = [r["path_m"] for r in rs]
            pairs = sum(r["cost_pairs"] for r in rs)
            table.append({
                "planner": pl, "n_agents": n, "seeds": len(rs),
                "mean_path_m": dist / done if done else math.nan,
                "std_path_m_over_seeds": float(np.std(per_run)) if per_run else math.nan,
                "ratio_to_astar": (dist / done) / ref_len if done and ref_len else math.nan,
                "ms_per_query": 1e3 * sum(r["cost_seconds"] for r in rs) / pairs
                if pairs else math.nan,
                "cost_seconds_per_run": float(np.mean([r["cost_seconds"] for r in rs])),
                "completed_share": done / sum(r["n_tasks"] for r in rs) if rs else math.nan,
                "paper_mean_path_m": PAPER.get(pl, {}).get(n, math.nan),
            })
    return table


def show(table: list[dict], planners, sizes, seeds: int, console: Console) -> None:
    cell = {(r["planner"], r["n_agents"]): r for r in table}

    def grid(title: str) -> Table:
        t = Table(title=title)
        t.add_column("planner")
        for n in sizes:
            t.add_column(f"N={n}", justify="right")
        return t

    t = grid(f"Table II: mean path length (m), Hungarian, {seeds} seeds")
    for pl in planners:
        t.add_row(LABEL.get(pl, pl), *(f"{cell[(pl, n)]['mean_path_m']:.2f}" for n in sizes))
    for pl, vals in PAPER.items():
        t.add_row(f"paper {LABEL[pl]}", *(f"{vals[n]:.2f}" if n in vals else "" for n in sizes),
                  style="dim")
    console.print(t)

    t = grid("path length / A*'s")
    for pl in planners:
        t.add_row(LABEL.get(pl, pl), *(f"{cell[(pl, n)]['ratio_to_astar']:.3f}" for n in sizes))
    console.print(t)

    t = grid("time per query (ms per agent-task pair)")
    for pl in planners:
        t.add_row(LABEL.get(pl, pl), *(f"{cell[(pl, n)]['ms_per_query']:.2f}" for n in sizes))
    console.print(t)

    t = grid("cost-matrix s per run | completed")
    for pl in planners:
        t.add_row(LABEL.get(pl, pl), *(
            f"{cell[(pl, n)]['cost_seconds_per_run']:.2f} s | "
            f"{100 * cell[(pl, n)]['completed_share']:.0f}%" for n in sizes))
    console.print(t)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=10, help="seeds 0 .. SEEDS-1 (default 10)")
    p.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    p.add_argument("--planners", nargs="+", default=list(PLANNERS))
    p.add_argument("--scenario", type=Path, default=SCENARIO)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" /
                   "planners_table.parquet")
    args = p.parse_args(argv)
    planners = list(dict.fromkeys(["astar", *args.planners]))  # A* is the reference
    scenario = load_scenario(args.scenario)
    console = Console(width=max(Console().width, 100))
    rows = []
    started = time.perf_counter()
    for n in args.sizes:
        for seed in range(args.seeds):
            for pl in planners:
                rows.append(one_run(scenario, pl, n, seed))
        console.log(f"N={n}: {args.seeds} seeds x {len(planners)} planners done "
                    f"({time.perf_counter() - started:.0f} s)")
    table = summarize(rows, planners, args.sizes)
    show(table, planners, args.sizes, args.seeds, console)
    console.print(
        "[dim]Mean path length: metres driven per completed assignment, pooled over seeds; the "
        "paths are the planners' own, driven in the simulation; A* is exact. Time per query: "
        "cost-matrix wall time over the N x M pairs it answers, each run from cold caches. "
        "The paper does not say how its mean is taken (its values grow with N).[/dim]")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    meta = {b"dispatch.benchmark": b"planners_table", b"dispatch.scenario": scenario.text.encode()}
    pq.write_table(pa.Table.from_pylist(table).replace_schema_metadata(meta), args.out)
    runs_out = args.out.with_name(f"{args.out.stem}_runs.parquet")
    pq.write_table(pa.Table.from_pylist(rows).replace_schema_metadata(meta), runs_out)
    console.print(f"wrote {args.out} and {runs_out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
