"""Benchmark: the kernel's cost per request stays constant over a long run (issue 11).

Runs the city-day workload of :mod:`benchmarks.city_day` (Manhattan 20 x 20, 1000 taxis,
``--requests`` Poisson requests over 24 simulated hours, ``fcfs`` immediate by default) through
:class:`dispatch.run.sim.Simulation` with its Parquet recorder, and takes the wall clock (and CPU
clock) each time another 10,000 requests have been released. Prints the seconds of each block
of 10,000 and the ratio of each block to the first, measured in the same run: the issue's
target is last / first <= 1.2 (a kernel whose step scans the run's history grows instead).
The first block includes the compilation-cache loads; the last block ends at the last release
(the drain after it is printed separately).

Run: ``.venv/bin/python benchmarks/kernel_scaling.py [--requests 100000] [--allocator fcfs]
[--network manhattan|chicago]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.city_day import scenario_text  # noqa: E402

BLOCK = 10_000


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--requests", type=int, default=100_000)
    p.add_argument("--vehicles", type=int, default=1000)
    p.add_argument("--allocator", choices=("fcfs", "hungarian"), default="fcfs")
    p.add_argument("--network", choices=("manhattan", "chicago"), default="manhattan")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()

    from rich.console import Console
    from rich.table import Table

    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    console = Console(width=80)
    marks: list[tuple[float, float, float]] = []  # (wall, cpu, simulated) at each block's end
    with tempfile.TemporaryDirectory(prefix="kernel-scaling-") as tmp:
        path = Path(tmp) / "day.toml"
        path.write_text(scenario_text(args.network, args.allocator, args.requests,
                                      args.vehicles, args.seed))
        spec = load_scenario(path, ignore_limits=True).runs()[0]
        recorder = make_recorder(spec, Path(tmp) / "out")
        sim = Simulation(spec, recorder)

        def on_release(e) -> None:
            if (e.task_id + 1) % BLOCK == 0:
                marks.append((time.perf_counter(), time.process_time(), e.t))

        sim.bus.subscribe(on_release, kinds=("release",))
        start = (time.perf_counter(), time.process_time(), 0.0)
        summary = sim.run()
        recorder.finish()
        end = (time.perf_counter(), time.process_time(), summary["sim_time"])
    t = Table(title=f"wall seconds per {BLOCK:,} requests ({args.allocator}, {args.network})")
    for c in ("requests", "sim h", "wall s", "CPU s", "wall / first"):
        t.add_column(c, justify="right")
    prev, first = start, None
    for i, m in enumerate(marks):
        wall, cpu = m[0] - prev[0], m[1] - prev[1]
        first = first or wall
        t.add_row(f"{(i + 1) * BLOCK:,}", f"{m[2] / 3600:.1f}", f"{wall:.2f}", f"{cpu:.2f}",
                  f"{wall / first:.2f}")
        prev = m
    console.print(t)
    if len(marks) >= 2:
        blocks = [(b[0] - a[0], b[1] - a[1]) for a, b in zip([start, *marks], marks)]
        console.print(f"last / first block: wall {blocks[-1][0] / blocks[0][0]:.2f}, CPU "
                      f"{blocks[-1][1] / blocks[0][1]:.2f} (target <= 1.2); second / first "
                      f"wall {blocks[1][0] / blocks[0][0]:.2f}")
    console.print(f"drain after the last block (and the final files): "
                  f"{end[0] - prev[0]:.2f} s wall; total {end[0] - start[0]:.1f} s wall, "
                  f"{end[1] - start[1]:.1f} s CPU; served {summary['tasks_completed']:,}")


if __name__ == "__main__":
    main()
