"""Benchmark: a city day (issue 11) through the public API, with where the time goes.

Workload (the issue's): a Manhattan grid of 20 x 20 intersections, 200 m blocks, 10 m/s,
bidirectional; ``--requests`` (100,000) Poisson requests over 24 simulated hours, origin and
destination uniform over the intersections (destination != origin); ``--vehicles`` (1000) taxis
at random intersections, capacity 1; every draw seeded. ``--network chicago``: the same on the
shipped Chicago Regional network (requests wait at most 10 min: a request no taxi can reach in
time is rejected; uniform demand over 11,180 nodes is far above what 1000 taxis can serve).

Runs ``fcfs`` (immediate: a decision per request) and ``hungarian`` batched every 30 s
(``[dispatch] batch_window = 30``), each ``--reps`` times, each in its own child process (so
peak RSS is the run's: ``resource.getrusage`` of the child), writing the Parquet tables as
``dispatch run`` does. Prints requests per wall second, wall seconds (min / median), peak RSS,
and where the time goes: the cost matrices (planner ``costs``), the allocator, routing
(planner ``plan``: the legs driven), recording (the recorder's rows, chunk files and final
files) and the rest (SimPy and the kernel), next to the issue's targets.

A reference measured in the same run: a fixed Python + numpy calibration loop timed before
each run (its seconds are printed; on this 2-core machine shared with other jobs the load
changes from minute to minute, so read the wall times next to it).

``--trace``: the same Manhattan workload written first as files a user brings (``trips.csv``,
one row per request with a trip id; ``fleet.csv``, the taxis' start nodes) and read from them
(demand from a trace streams: rows become requests as the clock reaches them).

Run: ``.venv/bin/python benchmarks/city_day.py [--network chicago] [--reps 3]
[--requests 100000] [--vehicles 1000] [--only fcfs|hungarian] [--trace]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DAY = 86_400.0
#: (network, allocator) -> (wall seconds, peak RSS MB): issue 11's targets
TARGETS = {("manhattan", "fcfs"): (30.0, 1024.0), ("manhattan", "hungarian"): (60.0, 1024.0),
           ("chicago", "hungarian"): (180.0, 2048.0), ("chicago", "fcfs"): (None, 2048.0)}


def write_trace(folder: Path, requests: int, vehicles: int, seed: int, nodes: int = 400) -> None:
    """The Manhattan workload as files a user brings: ``trips.csv`` (release time, origin and
    destination node, a trip id: one row per request, Poisson over 24 h, uniform over the
    ``nodes`` intersections) and ``fleet.csv`` (each taxi's start node), seeded."""
    import numpy as np

    rng = np.random.default_rng([seed, 28])
    t = np.cumsum(rng.exponential(DAY / requests, requests))
    o = rng.integers(0, nodes, requests)
    d = rng.integers(0, nodes - 1, requests)
    d += d >= o
    with (folder / "trips.csv").open("w") as fh:
        fh.write("t,origin_node,dest_node,trip_id\n")
        for k in range(0, requests, 100_000):
            fh.write("".join(f"{t[i]:.3f},{o[i]},{d[i]},trip-{i:07d}\n"
                             for i in range(k, min(requests, k + 100_000))))
    start = rng.integers(0, nodes, vehicles)
    (folder / "fleet.csv").write_text("vehicle_id,node\n" + "".join(
        f"{i},{n}\n" for i, n in enumerate(start.tolist())))


def scenario_text(network: str, allocator: str, requests: int, vehicles: int, seed: int,
                  trace: Path | None = None) -> str:
    """The workload as a scenario file (``trace``: the folder of :func:`write_trace`'s files,
    the requests and starts read from them)."""
    if network == "manhattan":
        world = ('network = "manhattan"\nblocks = [20, 20]\nblock = 200.0\nspeed = 10.0\n')
        wait = ""
    else:
        world = 'network = "chicago"\n'
        wait = "max_wait = 600.0\n"
    batch = "batch_window = 30.0\n" if allocator == "hungarian" else ""
    if trace is None:
        fleet = f"agents = {vehicles}\n"
        tasks = f'source = "poisson"\nrate = {requests / DAY!r}\ncount = {requests}\n'
    else:
        fleet = f'start = "{trace / "fleet.csv"}"\n'
        tasks = f'source = "trace"\ntrace = "{trace / "trips.csv"}"\n'
    return (f'name = "city_day_{network}"\nseed = {seed}\nduration = {DAY + 7200.0}\n'
            f"[world]\n{world}[fleet]\n{fleet}"
            f'[tasks]\n{tasks}{wait}'
            f'[dispatch]\nallocator = "{allocator}"\nplanner = "dijkstra"\n{batch}')


def calibrate() -> float:
    """Seconds of a fixed Python + numpy workload (the machine-speed reference)."""
    import numpy as np

    t = time.perf_counter()
    rng = np.random.default_rng(0)
    acc = 0.0
    for i in range(200_000):
        acc += (i * 7919) % 13
    a = rng.random((300, 300))
    for _ in range(20):
        a = np.sort(a, axis=1) @ a.T / 300.0
    return time.perf_counter() - t


def child(args) -> None:
    """One run in this process; prints one JSON line."""
    import resource

    from dispatch.output.parquet import Recorder
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    timers = {"record": 0.0, "plan": 0.0}

    def timed(cls_or_obj, name, key):
        fn = getattr(cls_or_obj, name)

        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers[key] += time.perf_counter() - t
        setattr(cls_or_obj, name, wrapper)

    for name in ("add", "flush", "finish"):
        timed(Recorder, name, "record")
    calib = calibrate()
    with tempfile.TemporaryDirectory(prefix="city-day-") as tmp:
        path = Path(tmp) / "city_day.toml"
        path.write_text(scenario_text(args.network, args.allocator, args.requests,
                                      args.vehicles, args.seed,
                                      Path(args.trace_dir) if args.trace_dir else None))
        sc = load_scenario(path, ignore_limits=True)
        spec = sc.runs()[0]
        t0, c0 = time.perf_counter(), time.process_time()
        recorder = make_recorder(spec, Path(tmp) / "out")
        sim = Simulation(spec, recorder)
        timed(sim.planner, "plan", "plan")
        setup = time.perf_counter() - t0
        summary = sim.run()
        recorder.finish()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    d = sim.tally
    print(json.dumps({
        "wall": wall, "cpu": cpu, "setup": setup, "calib": calib,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "cost": d.cost_seconds, "allocator": d.decide_seconds, "plan": timers["plan"],
        "record": timers["record"], "requests": summary["n_tasks"],
        "served": summary["tasks_completed"], "rejected": summary["tasks_rejected"],
        "expired": summary["tasks_expired"], "wait_mean": summary["wait_time_mean"],
        "decisions": summary["decisions"], "sim_time": summary["sim_time"],
    }))


def run_child(network, allocator, args) -> dict:
    cmd = [sys.executable, __file__, "--child", "--network", network, "--allocator", allocator,
           "--requests", str(args.requests), "--vehicles", str(args.vehicles),
           "--seed", str(args.seed)] + (["--trace-dir", args.trace_dir] if args.trace_dir else [])
    return child_result(cmd)


def child_result(cmd: list[str]) -> dict:
    """Run a benchmark's child process (this project on its path; peak RSS is the child's) and
    return the JSON object of its last output line; exit with its stderr if it fails."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode:
        sys.exit(f"child failed ({' '.join(cmd)}):\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--network", choices=("manhattan", "chicago"), default="manhattan")
    p.add_argument("--requests", type=int, default=100_000)
    p.add_argument("--vehicles", type=int, default=1000)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", choices=("fcfs", "hungarian"))
    p.add_argument("--trace", action="store_true",
                   help="read the requests and the taxis' starts from files (manhattan only)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--allocator", help=argparse.SUPPRESS)
    p.add_argument("--trace-dir", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args)
        return
    if args.trace:
        if args.network != "manhattan":
            p.error("--trace: the Manhattan grid only")
        with tempfile.TemporaryDirectory(prefix="city-day-trace-") as folder:
            write_trace(Path(folder), args.requests, args.vehicles, args.seed)
            size = (Path(folder) / "trips.csv").stat().st_size / 1e6
            print(f"trace: {args.requests:,} rows, {size:.0f} MB")
            args.trace_dir = folder
            report(args)
        return
    report(args)


def report(args) -> None:
    """Run the children and print the tables."""
    from rich.console import Console
    from rich.table import Table

    console = Console(width=80)
    allocators = [args.only] if args.only else ["fcfs", "hungarian"]
    console.print(f"city day on {args.network}: {args.requests:,} requests, {args.vehicles:,} "
                  f"vehicles, 24 h; {args.reps} run(s) each; load average "
                  f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    rows = {}
    for alloc in allocators:
        runs = []
        for r in range(args.reps):
            res = run_child(args.network, alloc, args)
            runs.append(res)
            console.print(f"  {alloc} run {r + 1}: {res['wall']:.1f} s wall "
                          f"({res['cpu']:.1f} s CPU), "
                          f"{res['rss_mb']:.0f} MB, calibration {res['calib']:.2f} s, "
                          f"served {res['served']:,}, wait {res['wait_mean']:.1f} s")
        rows[alloc] = runs
    t = Table(title=f"city day, {args.network} (min / median of {args.reps})")
    for c in ("", "wall s", "req/s", "RSS MB", "target"):
        t.add_column(c, justify="right" if c else "left")
    for alloc, runs in rows.items():
        walls = [r["wall"] for r in runs]
        target, mem = TARGETS[(args.network, alloc)]
        goal = (f"<={target:.0f} s" if target and args.requests == 100_000 else "-") \
            + f", <={mem:.0f} MB"
        t.add_row(alloc + (" 30 s" if alloc == "hungarian" else " imm."),
                  f"{min(walls):.1f} / {statistics.median(walls):.1f}",
                  f"{runs[0]['requests'] / statistics.median(walls):,.0f}",
                  f"{max(r['rss_mb'] for r in runs):.0f}", goal)
    console.print(t)
    w = Table(title="where the time goes (median run, seconds)")
    for c in ("", "cost", "alloc", "routes", "record", "setup", "rest"):
        w.add_column(c, justify="right" if c else "left")
    for alloc, runs in rows.items():
        r = sorted(runs, key=lambda x: x["wall"])[len(runs) // 2]
        rest = r["wall"] - r["cost"] - r["allocator"] - r["plan"] - r["record"] - r["setup"]
        w.add_row(alloc, *(f"{r[k]:.1f}" for k in ("cost", "allocator", "plan", "record",
                                                    "setup")), f"{rest:.1f}")
    console.print(w)
    console.print("cost: planner costs(); alloc: the allocator; routes: planner plan() (legs); "
                  "record: Parquet rows and files; setup: network, planner (hierarchy), fleet; "
                  "rest: SimPy and the kernel (events, dispatcher, vehicles).", soft_wrap=True)


if __name__ == "__main__":
    main()
