"""Peak memory against run length: the kernel's memory must not grow with the simulated time.

Each run is a fresh process (its peak RSS is its own): a Manhattan grid (20 x 20 intersections,
200 m blocks, 10 m/s), 100 taxis, Poisson trips at 0.5 per second (origin and destination
uniform over the intersections), fcfs, for 1, 4 and 16 simulated hours. It is run twice:

* streaming (the kernel as it is): rows flushed to Parquet chunks every 10,000;
* the reference: the same kernel holding every row until the end (``flush_rows`` larger than
  the run), which is what the recorder did before it streamed.

Printed: peak RSS, trips, event rows and wall seconds per run, and the ratio of the 16 h run's
peak RSS to the 1 h run's for both. Streaming should stay near 1.0; the reference grows with
the run. Usage: ``.venv/bin/python benchmarks/memory.py [--hours 1 4 16]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCENARIO = """
name = "memory"
seed = 0
duration = {duration}

[world]
network = "manhattan"
blocks = [20, 20]
block = 200.0
speed = 10.0

[fleet]
agents = 100

[tasks]
source = "poisson"
rate = 0.5
max_wait = 600.0

[dispatch]
allocator = "fcfs"
planner = "dijkstra"
"""

CHILD = textwrap.dedent("""
    import json, resource, sys, time
    from pathlib import Path
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario
    [spec] = load_scenario(Path(sys.argv[1])).runs()
    t0 = time.perf_counter()
    r = run_one(spec, Path(sys.argv[2]), flush_rows=int(sys.argv[3]))
    wall = time.perf_counter() - t0
    import pyarrow.parquet as pq
    events = pq.ParquetFile(r.files["events"]).metadata.num_rows
    print(json.dumps({"rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "wall": wall, "trips": r.summary["n_tasks"], "events": events}))
""")


def measure(hours: float, flush_rows: int, work: Path) -> dict:
    scenario = work / f"memory_{hours}.toml"
    scenario.write_text(SCENARIO.format(duration=hours * 3600.0), encoding="utf-8")
    out = work / f"out_{hours}_{flush_rows}"
    proc = subprocess.run([sys.executable, "-c", CHILD, str(scenario), str(out), str(flush_rows)],
                          capture_output=True, text=True, cwd=ROOT, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    from rich.console import Console
    from rich.table import Table

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, nargs="+", default=[1.0, 4.0, 16.0])
    args = p.parse_args(argv)
    modes = {"streaming": 10_000, "reference (all rows held)": 10**12}
    table = Table(title="Peak RSS against simulated hours (100 taxis, 0.5 trips/s, fcfs)")
    for col in ("mode", "hours", "trips", "event rows", "peak RSS MB", "wall s"):
        table.add_column(col, justify="left" if col == "mode" else "right")
    growth = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode, flush in modes.items():
            rss = []
            for h in args.hours:
                m = measure(h, flush, Path(tmp))
                rss.append(m["rss_mb"])
                table.add_row(mode, f"{h:g}", str(m["trips"]), str(m["events"]),
                              f"{m['rss_mb']:.0f}", f"{m['wall']:.1f}")
            growth[mode] = rss[-1] / rss[0]
    console = Console()
    console.print(table)
    for mode, g in growth.items():
        console.print(f"{mode}: peak RSS at {args.hours[-1]:g} h / at {args.hours[0]:g} h = "
                      f"{g:.2f}")


if __name__ == "__main__":
    main()
