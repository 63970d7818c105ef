"""Voxel-world dispatch at scale: wall time per task, peak RSS, and the fields against scipy.

Two worlds, each run in a fresh process (its peak RSS is its own), ``--repeat`` times:

* **paper**: the world of ``scenarios/paper_dynamic.toml`` (50 x 50 x 30 m, 1 m cells, 10 boxes
  of 3-10 m footprint and 5-30 m height), 200 vehicles (half UAVs at 5 m/s, half UGVs at
  3 m/s), Poisson tasks at 5 per second (half on the ground, ttl 120 s), ``hungarian`` batched
  every 1 s, planner ``astar``, no PyBullet mirror, 2 simulated hours (about 36,000 tasks).
* **big**: the same fleet and demand in a 200 x 200 x 30 m world with 160 boxes (the paper
  world's obstacle density), for ``--big-minutes`` simulated minutes (default 10).

Printed per run: tasks, wall seconds, wall and CPU ms per task (whole run, imports and world
building included; CPU counts every thread, and is the steadier figure on a shared machine),
peak RSS (and, in the JSON line of each run, wall seconds and seconds inside
``planner.costs``). Then, in the same child process, the reference:
**scipy.sparse.csgraph.dijkstra** computes the UAV fields of the run's first ``--sample`` task
cells (a tenth as many in the big world) on the same graph, and so do our kernels (one thread,
cache cold); the fields must be equal (bit for bit: both compute the unique fixed point of the
float64 relaxations), and the ratio scipy / ours is printed with the per-field times.

With ``--lazy`` each world also runs with ``[dispatch] lazy_costs = true`` on the same seed
(:mod:`dispatch.decide.lazy`: decisions on lower bounds, exact costs by A* only for the pairs the
optimal answer needs), and a second table puts the two side by side: wall and CPU ms per task,
UAV distance fields and A* searches per task, certificate rounds (allocator calls) per decision,
peak RSS, tasks completed and expired, mean wait. ``--verify`` adds one more lazy run (not
timed) that checks every decision against ``hungarian`` on the exact matrix (fields on a copy of
the grid): how many decisions chose other pairs (ties) and the worst relative gap of the total.

Usage: ``.venv/bin/python benchmarks/voxel.py [--repeat 3] [--hours 2] [--only paper|big]
[--field-cache-mb 256] [--lazy [--verify]]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCENARIO = """
name = "voxel_{world}"
seed = {seed}
duration = {duration}

[world]
size = [{side}, {side}, 30]
cell = 1.0
physics = false

[world.obstacles]
count = {boxes}
min_size = [3, 3, 5]
max_size = [10, 10, 30]

[fleet]
agents = 200
uav_fraction = 0.5
uav_speed = 5.0
ugv_speed = 3.0

[tasks]
source = "poisson"
rate = 5.0
ground_fraction = 0.5
ttl = 120.0

[dispatch]
allocator = "hungarian"
planner = "astar"
batch_window = 1.0
lazy_costs = {lazy}
{params}
"""

CHILD = textwrap.dedent("""
    import json, resource, sys, time
    t_start = time.perf_counter()
    from pathlib import Path
    import numpy as np
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario
    import planners.astar as A
    from planners import graph as G

    sample, verify = int(sys.argv[2]), sys.argv[3] == "verify"
    cells, cost_s = [], [0.0]
    real = A.AStarPlanner.costs
    # the counters: the dispatcher (certificate rounds, exact pairs) and UAV fields computed
    import dispatch.decide.dispatcher as D
    from dispatch.decide.answers import finders
    kept, uav_fields, check = {}, [0], {"decisions": 0, "differ": 0, "worst": 0.0}
    real_values = A.field_values

    def field_values(grid, goals, flies, at, bounded=False):
        out, computed = real_values(grid, goals, flies, at, bounded)
        uav_fields[0] += computed if flies else 0
        return out, computed

    A.field_values = field_values
    real_init = D.Dispatcher.__init__

    def init(self, *args, **kw):
        real_init(self, *args, **kw)
        kept["d"] = self
        if verify:  # each decision against hungarian on the exact matrix (fields, own grid)
            from allocators.hungarian import optimal_pairs
            from dispatch.space.world import Grid, World
            w = self.pipeline.problems.space
            ref = A.AStarPlanner(World(size=w.size, grid=Grid(np.array(w.grid.occupied),
                                                                w.grid.cell), boxes=()))
            record = self.on_decision

            def on_decision(index, problem, allocation, total, *a, **k):
                c = real(ref, problem.agents, problem.tasks)
                dl = np.array([t.deadline for t in problem.tasks])
                c = np.where(problem.time + c <= dl + 1e-9, c, np.inf)
                want = optimal_pairs(c)
                rows, cols = finders(problem)
                got = [(rows(a), cols(t)) for a, t in allocation.pairs]
                lazy_total = float(sum(c[i, j] for i, j in got))
                best = float(sum(c[i, j] for i, j in want))
                check["decisions"] += 1
                check["differ"] += sorted(got) != sorted(want)
                if len(got) != len(want):
                    check["worst"] = float("inf")
                elif best > 0:
                    check["worst"] = max(check["worst"], abs(lazy_total - best) / best)
                return record(index, problem, allocation, total, *a, **k)

            self.on_decision = on_decision

    D.Dispatcher.__init__ = init

    def costs(self, agents, tasks):
        t0 = time.perf_counter()
        out = real(self, agents, tasks)
        cost_s[0] += time.perf_counter() - t0
        for t in tasks:
            if len(cells) < sample and t.cell not in cells:
                cells.append(t.cell)
        return out

    A.AStarPlanner.costs = costs
    real_bounds = A.AStarPlanner.bounds

    def bounds(self, agents, tasks):
        for t in tasks:
            if len(cells) < sample and t.cell not in cells:
                cells.append(t.cell)
        return real_bounds(self, agents, tasks)

    A.AStarPlanner.bounds = bounds
    [spec] = load_scenario(Path(sys.argv[1])).runs()
    r = run_one(spec)
    wall = time.perf_counter() - t_start
    ru = resource.getrusage(resource.RUSAGE_SELF)
    rss, cpu = ru.ru_maxrss / 1024, ru.ru_utime + ru.ru_stime
    s = r.summary

    # the reference: scipy's Dijkstra and ours on the same UAV graph, cold cache, one thread
    from scipy.sparse.csgraph import dijkstra
    from dispatch.space.world import world_for
    grid = world_for(load_scenario(Path(sys.argv[1])).world, spec.seed).grid
    g = G.graph(grid, True)
    nodes = [g.node(c) for c in cells if grid.is_free(c)]
    csr = g.csr
    t_ours = t_ref = 0.0
    equal = True
    for n in nodes:  # one pair of fields at a time: a 200 x 200 x 30 field is 9.6 MB
        t0 = time.perf_counter()
        ours = G._field(g, n)
        t1 = time.perf_counter()
        ref = dijkstra(csr, indices=n)
        t_ref += time.perf_counter() - t1
        t_ours += t1 - t0
        equal = equal and np.array_equal(ours, ref)
    d = kept["d"]
    extra = d.pipeline.planner.stats.extra
    print(json.dumps({"tasks": int(s["n_tasks"]), "completed": int(s["tasks_completed"]),
                      "expired": int(s["tasks_expired"]), "decisions": int(s["decisions"]),
                      "wait": float(s["wait_time_mean"]), "lazy": d.pipeline.lazy,
                      "uav_fields": uav_fields[0], "fields": int(extra["fields_computed"]),
                      "astar": int(extra.get("astar_pairs", 0)), "rounds": d.tally.lazy_rounds,
                      "lazy_decisions": d.tally.decisions if d.pipeline.lazy else 0, "check": check,
                      "wall": wall, "cpu": cpu, "cost_s": d.tally.cost_seconds, "rss_mb": rss,
                      "ref_fields": len(nodes), "ours_ms": 1000 * t_ours / max(1, len(nodes)),
                      "scipy_ms": 1000 * t_ref / max(1, len(nodes)), "equal": equal}))
""")

WORLDS = {"paper": {"side": 50, "boxes": 10}, "big": {"side": 200, "boxes": 160}}


def measure(world: str, duration: float, seed: int, sample: int, params: str,
            work: Path, lazy: bool = False, verify: bool = False) -> dict:
    scenario = work / f"voxel_{world}.toml"
    scenario.write_text(SCENARIO.format(world=world, seed=seed, duration=duration,
                                        params=params, lazy="true" if lazy else "false",
                                        **WORLDS[world]), encoding="utf-8")
    proc = subprocess.run([sys.executable, "-c", CHILD, str(scenario), str(sample),
                           "verify" if verify else "-"],
                          capture_output=True, text=True, cwd=ROOT, check=False,
                          env={"PYTHONPATH": str(ROOT), **_env()})
    if proc.returncode != 0:
        raise SystemExit(f"the {world} run failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _env() -> dict:
    import os

    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def main(argv: list[str] | None = None) -> None:
    from rich.console import Console
    from rich.table import Table

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--hours", type=float, default=2.0, help="simulated hours, paper world")
    p.add_argument("--big-minutes", type=float, default=10.0,
                   help="simulated minutes, 200 x 200 x 30 world")
    p.add_argument("--only", choices=sorted(WORLDS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sample", type=int, default=100,
                   help="fields timed against scipy (a tenth of them in the big world)")
    p.add_argument("--field-cache-mb", type=float, default=None,
                   help="the astar planner's field_cache_mb (default: the planner's)")
    p.add_argument("--lazy", action="store_true",
                   help="also run each world with [dispatch] lazy_costs = true (same seed)")
    p.add_argument("--verify", action="store_true",
                   help="with --lazy: one more lazy run that checks every decision against "
                        "hungarian on the exact matrix (not timed)")
    args = p.parse_args(argv)
    params = ("" if args.field_cache_mb is None else
              f"\n[dispatch.planner_params]\nfield_cache_mb = {args.field_cache_mb}\n")
    worlds = [args.only] if args.only else list(WORLDS)
    durations = {"paper": args.hours * 3600.0, "big": args.big_minutes * 60.0}
    modes = [False, True] if args.lazy else [False]
    console = Console()
    table = Table(title="Voxel dispatch: 200 vehicles, 5 tasks/s, hungarian, astar")
    for col in ("world", "tasks", "wall ms/task", "cpu ms/task", "peak MB", "field ms",
                "scipy ms", "ratio"):
        table.add_column(col, justify="left" if col == "world" else "right")
    lazy_table = Table(title="Exact vs lazy costs, same seed: ms, UAV fields and A* searches "
                             "per task, rounds per decision, peak MB, tasks completed and expired, mean wait s")
    for col in ("run", "wall", "cpu", "fields", "A*", "rounds", "MB", "done", "exp",
                "wait"):
        lazy_table.add_column(col, justify="left" if col == "run" else "right")
    summary = []
    with tempfile.TemporaryDirectory() as tmp:
        for world in worlds:
            runs: dict[bool, list] = {False: [], True: []}
            sample = args.sample if world == "paper" else max(1, args.sample // 10)
            for _ in range(args.repeat):
                for lazy in modes:
                    m = measure(world, durations[world], args.seed, sample, params, Path(tmp),
                                lazy)
                    if not m["equal"]:
                        raise SystemExit(f"{world}: our fields differ from scipy's")
                    runs[lazy].append(m)
                    name = " lazy" if lazy else world
                    table.add_row(name, str(m["tasks"]),
                                  f"{1000 * m['wall'] / m['tasks']:.2f}",
                                  f"{1000 * m['cpu'] / m['tasks']:.2f}",
                                  f"{m['rss_mb']:.0f}", f"{m['ours_ms']:.2f}",
                                  f"{m['scipy_ms']:.1f}",
                                  f"{m['scipy_ms'] / m['ours_ms']:.1f}")
                    n = m["tasks"]
                    lazy_table.add_row(name, f"{1000 * m['wall'] / n:.2f}",
                                       f"{1000 * m['cpu'] / n:.2f}", f"{m['uav_fields'] / n:.3f}",
                                       f"{m['astar'] / n:.2f}",
                                       f"{m['rounds'] / max(1, m['lazy_decisions']):.2f}",
                                       f"{m['rss_mb']:.0f}", str(m["completed"]),
                                       str(m["expired"]), f"{m['wait']:.3f}")
                    console.print(json.dumps({"world": world, **m}))
            for lazy in modes:
                got = runs[lazy]
                per_task = [1000 * m["wall"] / m["tasks"] for m in got]
                cpu = [1000 * m["cpu"] / m["tasks"] for m in got]
                rss = [m["rss_mb"] for m in got]
                summary.append(f"{world}{' lazy' if lazy else ''}: wall ms/task min "
                               f"{min(per_task):.2f} median {statistics.median(per_task):.2f}; "
                               f"cpu ms/task min {min(cpu):.2f} median "
                               f"{statistics.median(cpu):.2f}; peak RSS MB min {min(rss):.0f} "
                               f"median {statistics.median(rss):.0f}")
            if args.lazy:
                ratio = [e["cpu"] / lz["cpu"] for e, lz in zip(runs[False], runs[True])]
                summary.append(f"{world}: exact / lazy cpu per run, min {min(ratio):.2f} "
                               f"median {statistics.median(ratio):.2f}")
            if args.lazy and args.verify:
                m = measure(world, durations[world], args.seed, 1, params, Path(tmp), True,
                            verify=True)
                c = m["check"]
                summary.append(f"{world} lazy, checked against hungarian on the exact matrix: "
                               f"{c['decisions']} decisions, {c['differ']} with other pairs "
                               f"(ties), worst relative total gap {c['worst']:.2e}")
    console.print(table)
    if args.lazy:
        console.print(lazy_table)
    for line in summary:
        console.print(line)


if __name__ == "__main__":
    main()
