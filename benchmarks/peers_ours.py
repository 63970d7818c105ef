"""``benchmarks/peers.py``'s runner for this project: ``fcfs`` + ``dijkstra`` on the workload.

Run by the project's interpreter in a fresh process (its peak RSS is its own):
``python benchmarks/peers_ours.py WORKLOAD_DIR OUT.json``. The workload's trips become the
scenario's trace and its starts the fleet's start file, so this run and the peers' see the same
requests and starts; requests wait without limit (no ``max_wait``), as the peers' do. The wall
time is :func:`dispatch.runner.run_one`'s: the network built, the day simulated, every table
written to Parquet (module imports excluded, as the peers' are; compiled code loaded from
numba's cache or compiled on first use is inside the clock).
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from peers_workload import metrics, read, save_pickups

SCENARIO = """\
name = "peers"
seed = {seed}
duration = {end}

[world]
network = "manhattan"
blocks = [{columns}, {rows}]
block = {block}
speed = {speed}

[fleet]
start = "fleet.csv"

[tasks]
source = "trace"
trace = "trips.csv"

[dispatch]
allocator = "{allocator}"
planner = "dijkstra"
"""


def main(folder: Path, out: Path, allocator: str = "fcfs") -> None:
    # imported before the clock starts (run_one imports the simulation lazily, and pyarrow
    # imports pandas on the recorder's first table): the peers' imports are not timed either
    import pandas  # noqa: F401
    import pyarrow.compute as pc

    import allocators.fcfs  # noqa: F401
    import dispatch.sim  # noqa: F401
    import planners.road  # noqa: F401
    from dispatch.runner import run_one
    from dispatch.scenario import load_scenario

    w = read(folder)[0]
    scenario = folder / f"ours_{allocator}.toml"
    scenario.write_text(SCENARIO.format(seed=w.seed, end=w.end, columns=w.columns, rows=w.rows,
                                        block=w.block, speed=w.speed, allocator=allocator))
    [spec] = load_scenario(scenario, force=True).runs()
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_one(spec, folder / f"ours_{allocator}_out")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    tasks = result.tables["tasks"]
    done = pc.equal(tasks["state"], "completed").to_numpy(zero_copy_only=False)
    completed = tasks["completed_at"].to_numpy().copy()
    completed[~done] = float("nan")
    row = metrics(tasks["released_at"].to_numpy(), tasks["picked_up_at"].to_numpy(), completed,
                  float(result.summary["distance"]))
    row.update(wall_s=wall, cpu_s=cpu,
               rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    order = np.argsort(tasks["task_id"].to_numpy())
    save_pickups(out.with_suffix(".npz"), tasks["released_at"].to_numpy()[order],
                 tasks["picked_up_at"].to_numpy()[order], tasks["agent_id"].to_numpy()[order])
    out.write_text(json.dumps(row))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), *sys.argv[3:])
