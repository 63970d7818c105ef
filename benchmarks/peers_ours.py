"""``benchmarks/peers.py``'s runner for this project: ``fcfs`` + ``dijkstra`` on the workload.

Run by the project's interpreter in a fresh process (its peak RSS is its own):
``python benchmarks/peers_ours.py WORKLOAD_DIR OUT.json [ALLOCATOR [OBJECTIVE [BATCH_WINDOW]]]``
(default ``fcfs``, ``pickup_time``, 0: a decision at each release; S > 0 sets ``[dispatch]
batch_window = S``: a decision every S seconds over what was released since). The workload's
trips become the scenario's trace and its starts the fleet's start file, so this run and the
peers' see the same requests and starts; requests wait without limit (no ``max_wait``), as the
peers' do, unless the workload gives limits. A workload of shared rides
(``benchmarks/pooling.py``) sets ``[fleet] capacity``, ``[tasks] max_wait`` and ``max_delay``
from the workload, and the row gets the shared-ride metrics (``peers_workload.metrics``): the
direct times are the workload's (checked against the run's ``direct_time`` column), shared
from the tasks' ``shared`` column, passenger-metres from the summary. The wall
time is :func:`dispatch.run.runner.run_one`'s: the network built, the day simulated, every table
written to Parquet (module imports excluded, as the peers' are; compiled code loaded from
numba's cache or compiled on first use is inside the clock).
"""

from __future__ import annotations

import importlib
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
{network}
[fleet]
start = "fleet.csv"
capacity = {capacity}

[tasks]
source = "trace"
trace = "trips.csv"
{limits}
[dispatch]
allocator = "{allocator}"
planner = "dijkstra"
objective = "{objective}"
{batch}"""


def scenario_text(w, allocator: str, objective: str, batch_window: float) -> str:
    """The scenario of this run on workload ``w`` (``peers_workload.Workload``): its grid or
    jittered streets, fleet start file and trace, the workload's seats and limits, and
    ``batch_window`` only when it is > 0 (0: the default, a decision at each release)."""
    limits = "".join(f"{key} = {value}\n" for key, value in
                     (("max_wait", w.max_wait), ("max_delay", w.max_delay)) if value is not None)
    network = ('network = "grid.graphml"\n' if w.jitter else
               f'network = "manhattan"\nblocks = [{w.columns}, {w.rows}]\nblock = {w.block}\n'
               f'speed = {w.speed}\n')
    batch = f"batch_window = {float(batch_window)!r}\n" if batch_window > 0 else ""
    return SCENARIO.format(seed=w.seed, end=w.end, network=network, allocator=allocator,
                           capacity=w.capacity, limits=limits, objective=objective, batch=batch)


def main(folder: Path, out: Path, allocator: str = "fcfs", objective: str = "pickup_time",
         batch_window: float = 0.0) -> None:
    # imported before the clock starts (run_one imports the simulation lazily, and pyarrow
    # imports pandas on the recorder's first table): the peers' imports are not timed either
    import pandas  # noqa: F401
    import pyarrow.compute as pc

    importlib.import_module(f"allocators.{allocator}")
    import dispatch.run.sim  # noqa: F401
    import planners.road  # noqa: F401
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    w, t, origin, dest, _ = read(folder)
    batch_window = float(batch_window)
    if not batch_window >= 0:
        raise SystemExit(f"peers_ours: the batch window must be >= 0 seconds, not {batch_window}")
    # a name per batch window: several of our runs share the workload's folder
    name = f"ours_{allocator}" + (f"_bw{batch_window:g}" if batch_window > 0 else "")
    scenario = folder / f"{name}.toml"
    scenario.write_text(scenario_text(w, allocator, objective, batch_window))
    [spec] = load_scenario(scenario, ignore_limits=True).runs()
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_one(spec, folder / f"{name}_out")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    tasks = result.tables["tasks"]
    done = pc.equal(tasks["state"], "completed").to_numpy(zero_copy_only=False)
    completed = tasks["completed_at"].to_numpy().copy()
    completed[~done] = float("nan")
    order = np.argsort(tasks["task_id"].to_numpy())
    rides = {}
    if w.capacity > 1 or w.max_delay is not None:
        direct = np.empty(t.size)
        direct[order] = w.direct(origin, dest)  # task ids are the trace's row order
        run_direct = tasks["direct_time"].to_numpy()
        offered = np.isfinite(run_direct)
        if not np.allclose(run_direct[offered], direct[offered], rtol=0, atol=1e-6):
            raise SystemExit("peers_ours: the run's direct times are not the workload's")
        rides = {"direct": direct, "shared": tasks["shared"].to_numpy(zero_copy_only=False),
                 "passenger_m": float(result.summary["passenger_distance"])}
    row = metrics(tasks["released_at"].to_numpy(), tasks["picked_up_at"].to_numpy(), completed,
                  float(result.summary["distance"]), **rides)
    row.update(wall_s=wall, cpu_s=cpu,
               rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               rejected=int(result.summary["tasks_rejected"]),
               expired=int(result.summary["tasks_expired"]))
    save_pickups(out.with_suffix(".npz"), tasks["released_at"].to_numpy()[order],
                 tasks["picked_up_at"].to_numpy()[order], tasks["agent_id"].to_numpy()[order])
    out.write_text(json.dumps(row))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), *sys.argv[3:])
