"""Benchmark: the CBBA auction (and MAGNNET-match, greedy) under limited communication, vs
Hungarian.

For N = M in {4, 8, 12, 20, 50, 100} and communication ranges {unlimited, 20 m, 10 m}, on the
first decision of the paper's static scenario (``scenarios/paper_static.toml``: the same world,
fleet and tasks as ``dispatch run`` builds for each seed; costs from the ``astar`` planner),
each allocator answers the same problem and we report, averaged over seeds:

* gap to Hungarian: (total cost - Hungarian's) / Hungarian's, on the pairs handed out;
* conflict-free rate: share of tasks assigned to exactly one agent without ever being in
  conflict (DESIGN.md, Metrics); "assigned" is the share of tasks assigned at all;
* rounds, messages (transmissions) and hops of the decision (see dispatch/api/comms.py);
* time: wall milliseconds of ``allocate`` (the cost matrix is shared and not counted), its
  ratio to Hungarian's time measured in the same process, and the per-agent critical path
  (the largest per-agent compute time: agents think in parallel on their own hardware);
* connected: share of instances whose communication graph is connected.

Run: ``.venv/bin/python benchmarks/auction.py [--seeds 10] [--loss 0.0] [--out DIR]``.
Prints a rich table and writes ``auction_runs.parquet`` (one row per instance and allocator) and
``auction_table.parquet`` (the table) under ``benchmarks/results/`` or ``--out``.
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
from rich.progress import Progress
from rich.table import Table

from dispatch.api import registry
from dispatch.api.comms import comm_graph, components, diameter
from dispatch.api.problem import AllocationProblem, TaskView
from dispatch.fleet.placement import place_fleet
from dispatch.plan.demand import VoxelDemand
from dispatch.scenario.load import load_scenario
from dispatch.space.world import world_for
from dispatch.streams import STREAM_ALLOCATOR, STREAM_FLEET, STREAM_TASKS, rng_for

ROOT = Path(__file__).resolve().parents[1]
SIZES = (4, 8, 12, 20, 50, 100)
RANGES = (None, 20.0, 10.0)
ALLOCATORS = ("hungarian", "auction", "magnnet", "greedy")


def load_planner():
    """The astar planner class (retries for a while: another engineer may be finishing it)."""
    last = None
    for _ in range(10):
        try:
            return registry.load("planner", "astar")
        except Exception as e:  # noqa: BLE001 - report after the retries
            last = e
            time.sleep(30)
    raise SystemExit(f"cannot load the astar planner: {last}")


def instance(scenario, n: int, seed: int, planner_cls):
    """Agents, tasks, cost matrix and agent positions (metres) of the first decision."""
    spec = scenario.runs(allocator="hungarian", agents=n, seed=seed)[0]
    world = world_for(scenario.world, seed)
    fleet = place_fleet(world, spec, rng_for(seed, STREAM_FLEET))
    demand = VoxelDemand(world.grid, scenario.tasks.ground_fraction, rng_for(seed, STREAM_TASKS))
    tasks = tuple(TaskView(i, (r := demand.draw()).kind, r.loc, 0.0)
                  for i in range(spec.n_static_tasks))
    agents = tuple(v.view() for v in fleet)
    cost = planner_cls(world).costs(agents, tasks)
    positions = np.array([world.grid.centre(a.cell) for a in agents])
    return agents, tasks, cost, positions, world.grid.cell


def evaluate(problem: AllocationProblem, allocation, elapsed: float) -> dict:
    rows = {a.id: i for i, a in enumerate(problem.agents)}
    cols = {t.id: j for j, t in enumerate(problem.tasks)}
    total = float(sum(problem.cost[rows[a], cols[t]] for a, t in allocation.pairs))
    conflicted = allocation.conflicted_tasks()
    assigned = {t for _, t in allocation.pairs}
    m = problem.n_tasks
    return dict(
        total_cost=total,
        assigned=len(assigned) / m,
        conflict_free_rate=len(assigned - conflicted) / m,
        rounds=allocation.rounds,
        messages=allocation.messages,
        hops=allocation.hops,
        seconds=elapsed,
        agent_seconds=max(allocation.agent_seconds, default=elapsed),
    )


def _instance_rows(out, scenario, planner_cls, allocs, n, seed, ranges, loss, bundle_size,
                   warm) -> None:
    """Every allocator on one instance under every range: rows appended to ``out``."""
    agents, tasks, cost, positions, cell = instance(scenario, n, seed, planner_cls)
    if warm:  # first calls pay for imports and caches: keep them out of the timings
        for name, cls in allocs.items():
            cls().allocate(AllocationProblem(
                time=0.0, agents=agents, tasks=tasks, cost=cost.copy(),
                comm=comm_graph(positions, 10.0), rng=np.random.default_rng(0),
                cell_size=cell))
    for rng_m in ranges:
        comm = comm_graph(positions, rng_m)
        n_comp = components(comm)[0]
        for name, cls in allocs.items():
            alloc = cls(bundle_size=bundle_size) if name == "auction" else cls()
            problem = AllocationProblem(
                time=0.0, agents=agents, tasks=tasks, cost=cost.copy(), comm=comm,
                rng=rng_for(seed, STREAM_ALLOCATOR), loss=loss, cell_size=cell)
            t0 = time.perf_counter()
            allocation = alloc.allocate(problem)
            elapsed = time.perf_counter() - t0
            row = dict(allocator=name, n=n, range_m=math.inf if rng_m is None else rng_m,
                       seed=seed, loss=loss, bundle_size=bundle_size,
                       components=n_comp, connected=n_comp == 1,
                       diameter=diameter(comm) if n_comp == 1 else -1)
            row.update(evaluate(problem, allocation, elapsed))
            out.append(row)


def run(sizes, ranges, seeds, loss, bundle_size, console) -> list[dict]:
    scenario = load_scenario(ROOT / "scenarios" / "paper_static.toml")
    planner_cls = load_planner()
    allocs = {name: registry.load("allocator", name) for name in ALLOCATORS}
    out = []
    warm = True
    with Progress(console=console, transient=True) as progress:
        bar = progress.add_task("instances", total=len(sizes) * len(seeds))
        for n, seed in ((n, s) for n in sizes for s in seeds):
            progress.update(bar, description=f"N = {n}, seed {seed}")
            _instance_rows(out, scenario, planner_cls, allocs, n, seed, ranges, loss,
                           bundle_size, warm)
            warm = False
            progress.advance(bar)
    ref = {(r["n"], r["range_m"], r["seed"]): r for r in out if r["allocator"] == "hungarian"}
    for r in out:
        h = ref[(r["n"], r["range_m"], r["seed"])]
        r["gap"] = (r["total_cost"] - h["total_cost"]) / h["total_cost"] if h["total_cost"] else 0.0
        r["time_ratio"] = r["seconds"] / h["seconds"] if h["seconds"] > 0 else math.nan
    return out


def aggregate(rows: list[dict]) -> list[dict]:
    keys = sorted({(r["n"], r["range_m"], r["allocator"]) for r in rows
                   if r["allocator"] != "hungarian"},
                  key=lambda k: (k[0], -k[1], ALLOCATORS.index(k[2])))
    table = []
    for n, rng_m, name in keys:
        group = [r for r in rows if (r["n"], r["range_m"], r["allocator"]) == (n, rng_m, name)]
        href = [r for r in rows
                if (r["n"], r["range_m"], r["allocator"]) == (n, rng_m, "hungarian")]

        def mean(k, g=group):
            return float(np.mean([r[k] for r in g]))

        table.append(dict(
            n=n, range_m=rng_m, allocator=name, seeds=len(group),
            connected=mean("connected"), gap=mean("gap"), assigned=mean("assigned"),
            conflict_free_rate=mean("conflict_free_rate"), rounds=mean("rounds"),
            messages=mean("messages"), hops=mean("hops"), ms=1e3 * mean("seconds"),
            hungarian_ms=1e3 * mean("seconds", href), time_ratio=mean("time_ratio"),
            agent_ms=1e3 * mean("agent_seconds"),
        ))
    return table


def render(table: list[dict], console: Console, title: str) -> None:
    t = Table(title=title)
    for col in ("N", "range", "allocator", "connected", "gap", "assigned", "conflict-free",
                "rounds", "messages", "hops", "time ms", "x hungarian", "per-agent ms"):
        t.add_column(col, justify="left" if col == "allocator" else "right")
    for r in table:
        rng_s = "unlimited" if math.isinf(r["range_m"]) else f"{r['range_m']:g} m"
        t.add_row(str(r["n"]), rng_s, r["allocator"], f"{100 * r['connected']:.0f}%",
                  f"{100 * r['gap']:+.1f}%", f"{100 * r['assigned']:.1f}%",
                  f"{100 * r['conflict_free_rate']:.1f}%", f"{r['rounds']:.1f}",
                  f"{r['messages']:.0f}", f"{r['hops']:.1f}", f"{r['ms']:.2f}",
                  f"{r['time_ratio']:.1f}", f"{r['agent_ms']:.3f}")
    console.print(t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--ranges", type=float, nargs="+", default=None,
                    help="metres; 0 or inf for unlimited (default: unlimited 20 10)")
    ap.add_argument("--seeds", type=int, default=10, help="seeds 0..K-1 (default 10)")
    ap.add_argument("--loss", type=float, default=0.0)
    ap.add_argument("--bundle-size", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = ap.parse_args(argv)
    ranges = RANGES if args.ranges is None else tuple(
        None if (r <= 0 or math.isinf(r)) else r for r in args.ranges)
    console = Console(width=max(Console().width, 150))  # the table is wide; let it be
    t0 = time.perf_counter()
    rows = run(args.sizes, ranges, range(args.seeds), args.loss, args.bundle_size, console)
    table = aggregate(rows)
    render(table, console, f"auction (CBBA, bundle_size={args.bundle_size}) and greedy vs "
                           f"Hungarian: paper_static first decision, N = M, {args.seeds} seeds, "
                           f"loss {args.loss:g}")
    args.out.mkdir(parents=True, exist_ok=True)
    suffix = "" if (args.loss == 0 and args.bundle_size == 1) else \
        f"_loss{args.loss:g}_L{args.bundle_size}"
    pq.write_table(pa.Table.from_pylist(rows), args.out / f"auction_runs{suffix}.parquet")
    pq.write_table(pa.Table.from_pylist(table), args.out / f"auction_table{suffix}.parquet")
    console.print(f"{len(rows)} allocations in {time.perf_counter() - t0:.1f} s; Parquet written "
                  f"to {args.out}/auction_runs{suffix}.parquet and auction_table{suffix}.parquet")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
