"""Benchmark: the pooled city day of issue 20, insertion (``hungarian``, batched 30 s and
immediate) against ``rtv`` (batched 30 s), with where the time goes.

Workload (``benchmarks/city_day.py``'s Manhattan grid, pooled): 20 x 20 intersections, 200 m
blocks, 10 m/s; ``--requests`` (100,000) Poisson requests over ``--hours`` (24) simulated hours
(the rate is the day's: ``--hours 2`` runs the day's first two hours), uniform origins and
destinations; ``--vehicles`` (1000) taxis of ``--capacity`` (4) seats; ``max_wait`` 300 s,
``max_delay`` 600 s. Each run in its own child process (peak RSS is the run's), writing the
Parquet tables as ``dispatch run`` does. Prints wall seconds, requests per wall second, peak RSS,
served share, mean wait / delay, occupancy, seconds spent in the costs (the planner and the
dispatcher's insertions), the allocator and the rest (SimPy, the kernel, recording), and for
``rtv`` its counters (groups, what the bounds cut). ``--profile FILE`` writes a cProfile of
one run (``--only`` names it).

Run: ``.venv/bin/python benchmarks/pooled_day.py [--hours 24] [--reps 1]
[--only hungarian_30|hungarian_0|rtv_30] [--profile out.prof]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from city_day import child_result  # noqa: E402  (the same child runner)

DAY = 86_400.0
METHODS = {"hungarian_30": ("hungarian", 30.0), "hungarian_0": ("hungarian", None),
           "rtv_30": ("rtv", 30.0)}


def scenario_text(allocator: str, window: float | None, requests: int, hours: float,
                  vehicles: int, capacity: int, seed: int, params: str = "") -> str:
    rate = requests / DAY
    count = round(rate * hours * 3600.0)
    batch = f"batch_window = {window}\n" if window else ""
    extra = f"\n[dispatch.allocator_params]\n{params}\n" if params else ""
    return (f'name = "pooled_day"\nseed = {seed}\nduration = {hours * 3600.0 + 3600.0}\n'
            f'[world]\nnetwork = "manhattan"\nblocks = [20, 20]\nblock = 200.0\nspeed = 10.0\n'
            f"[fleet]\nagents = {vehicles}\ncapacity = {capacity}\n"
            f'[tasks]\nsource = "poisson"\nrate = {rate!r}\ncount = {count}\n'
            f"max_wait = 300.0\nmax_delay = 600.0\n"
            f'[dispatch]\nallocator = "{allocator}"\nplanner = "dijkstra"\n{batch}{extra}')


def child(args) -> None:
    import resource

    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    allocator, window = METHODS[args.method]
    with tempfile.TemporaryDirectory(prefix="pooled-day-") as tmp:
        path = Path(tmp) / "pooled_day.toml"
        path.write_text(scenario_text(allocator, window, args.requests, args.hours,
                                      args.vehicles, args.capacity, args.seed, args.params))
        spec = load_scenario(path, ignore_limits=True).runs()[0]
        t0 = time.perf_counter()
        recorder = make_recorder(spec, Path(tmp) / "out")
        sim = Simulation(spec, recorder)
        if args.profile:
            import cProfile

            prof = cProfile.Profile()
            summary = prof.runcall(sim.run)
            prof.dump_stats(args.profile)
        else:
            summary = sim.run()
        recorder.finish()
        wall = time.perf_counter() - t0
    d = sim.tally
    stats = dict(getattr(sim.allocator, "stats", {}) or {})
    print(json.dumps({
        "wall": wall, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "cost": d.cost_seconds, "allocator": d.decide_seconds,
        "requests": summary["n_tasks"], "served": summary["tasks_completed"],
        "wait_mean": summary["wait_time_mean"], "delay_mean": summary.get("delay_mean"),
        "occupancy": summary.get("occupancy"), "shared_rate": summary.get("shared_rate"),
        "distance_km": summary.get("distance", 0.0) / 1000.0,
        "decisions": summary["decisions"], "rtv": stats,
    }))


def run_child(method: str, args) -> dict:
    cmd = [sys.executable, __file__, "--child", "--method", method, "--requests",
           str(args.requests), "--hours", str(args.hours), "--vehicles", str(args.vehicles),
           "--capacity", str(args.capacity), "--seed", str(args.seed)]
    if args.params:
        cmd += ["--params", args.params]
    if args.profile:
        cmd += ["--profile", args.profile]
    return child_result(cmd)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--requests", type=int, default=100_000, help="requests per 24 h")
    p.add_argument("--hours", type=float, default=24.0)
    p.add_argument("--vehicles", type=int, default=1000)
    p.add_argument("--capacity", type=int, default=4)
    p.add_argument("--reps", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", choices=sorted(METHODS), nargs="+")
    p.add_argument("--params", default="", help="rtv parameters, TOML lines (a = 1\\nb = 2)")
    p.add_argument("--profile", help="write a cProfile of the run here")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--method", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args)
        return
    for method in args.only or sorted(METHODS):
        runs = [run_child(method, args) for _ in range(args.reps)]
        walls = [r["wall"] for r in runs]
        r = runs[-1]
        n = r["requests"]
        print(f"{method:13s} {n} requests: wall min {min(walls):.1f} s median "
              f"{statistics.median(walls):.1f} s ({n / min(walls):.0f} requests/s), "
              f"peak RSS {max(x['rss_mb'] for x in runs):.0f} MB; costs {r['cost']:.1f} s, "
              f"allocator {r['allocator']:.1f} s, rest {r['wall'] - r['cost'] - r['allocator']:.1f}"
              f" s; served {r['served'] / n:.3f}, wait {r['wait_mean']:.0f} s, delay "
              f"{(r['delay_mean'] or 0):.0f} s, occupancy {(r['occupancy'] or 0):.2f}, "
              f"shared {(r['shared_rate'] or 0):.2f}, {r['distance_km']:.0f} vehicle-km, "
              f"{r['decisions']} decisions", flush=True)
        if r["rtv"]:
            print("   rtv:", json.dumps(r["rtv"]), flush=True)


if __name__ == "__main__":
    main()
