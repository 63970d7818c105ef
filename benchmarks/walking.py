"""Benchmark: meeting points on the Manhattan NYC day (issue 31's walking target).

Workload: ``scenarios/nyc_manhattan_pooled.toml`` (the NYC taxi requests of Sunday 2014-12-21
on the OSMnx street network, 4-seat taxis, ``max_wait`` 300 s, ``max_delay`` 600 s), allocated
by ``hungarian`` batched every 30 s (insertion costs, ``added_time`` objective: what the pooled
hungarian runs use) and ``rtv`` batched every 30 s, with ``max_walk`` 0 / 150 / 300 / 500 m
(``walk_speed`` 1.4 m/s, ``meeting_points`` 8). ``--start`` / ``--hours`` cut a window of the
day (the trace's rows departing in it; the run goes on an hour past the window so the last
trips finish); ``--agents`` sets the fleet; ``--seeds`` repeats each run with other vehicle
placements (the trace is the day's, fixed).

Per run: served share, vehicle-km per served rider, mean metres walked per ride, mean wait,
wall seconds. Per (allocator, max_walk): the mean over seeds with its 95 % Student-t
half-width, and the change of vehicle-km per served rider against ``max_walk`` 0 of the same
seeds. Each run in its own child process; ``--json FILE`` keeps every run's figures.

Run: ``nice -n 10 .venv/bin/python benchmarks/walking.py [--hours 2 --start 08:00]
[--walks 0 300] [--allocators hungarian rtv] [--seeds 0 1 2] [--agents 400]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from city_day import child_result  # noqa: E402  (the same child runner)

TRACE = ROOT / "dispatch" / "data" / "nyc_manhattan" / "nyc_taxi_2014-12-21_20k.csv"
DAY = "2014-12-21"


def scenario_text(allocator: str, walk: float, agents: int, seed: int, trace: Path,
                  start: str, duration: float, k: int) -> str:
    objective = 'objective = "added_time"\n' if allocator == "hungarian" else ""
    return (f'name = "walking"\nseed = {seed}\nduration = {duration!r}\n'
            f'[world]\nnetwork = "manhattan_osm"\n'
            f"[fleet]\nagents = {agents}\ncapacity = 4\n"
            f'[tasks]\nsource = "trace"\ntrace = "{trace}"\nstart = "{DAY}T{start}"\n'
            f"max_snap = 250.0\nmax_wait = 300.0\nmax_delay = 600.0\n"
            f"max_walk = {walk!r}\nwalk_speed = 1.4\nmeeting_points = {k}\n"
            f'[dispatch]\nallocator = "{allocator}"\nplanner = "dijkstra"\n'
            f"batch_window = 30.0\n{objective}")


def child(args) -> None:
    import pandas as pd

    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    with tempfile.TemporaryDirectory(prefix="walking-") as tmp:
        trips = pd.read_csv(TRACE)
        t = pd.to_datetime(trips.departure_time)
        t0 = pd.Timestamp(f"{DAY} {args.start}")
        keep = (t >= t0) & (t < t0 + pd.Timedelta(hours=args.hours))
        trace = Path(tmp) / "trips.csv"
        trips[keep].to_csv(trace, index=False)
        path = Path(tmp) / "walking.toml"
        path.write_text(scenario_text(args.allocator, args.walk, args.agents, args.seed, trace,
                                      args.start, args.hours * 3600.0 + 3600.0,
                                      args.meeting_points))
        spec = load_scenario(path, ignore_limits=True).runs()[0]
        w0 = time.perf_counter()
        recorder = make_recorder(spec, Path(tmp) / "out")
        summary = Simulation(spec, recorder).run()
        recorder.finish()
        wall = time.perf_counter() - w0
    served = summary["tasks_completed"]
    print(json.dumps({
        "allocator": args.allocator, "walk": args.walk, "seed": args.seed,
        "agents": args.agents, "requests": summary["n_tasks"], "served": served,
        "served_share": served / summary["n_tasks"],
        "km_per_rider": summary["distance"] / 1000.0 / served if served else float("nan"),
        "distance_km": summary["distance"] / 1000.0, "walk_mean": summary["walk_mean"],
        "wait_mean": summary["wait_time_mean"], "occupancy": summary["occupancy"],
        "meeting_points": summary["meeting_points"], "meeting_cut": summary["meeting_cut"],
        "wall": wall}))


def run_child(allocator: str, walk: float, seed: int, args) -> dict:
    cmd = [sys.executable, __file__, "--child", "--allocator", allocator, "--walk", str(walk),
           "--seed", str(seed), "--agents", str(args.agents), "--start", args.start,
           "--hours", str(args.hours), "--meeting-points", str(args.meeting_points)]
    return child_result(cmd)


def _ci(values: list[float]) -> tuple[float, float]:
    from paired.stats import mean_ci

    mean, half, _ = mean_ci(values)
    return mean, half


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--allocators", nargs="+", default=["hungarian", "rtv"],
                   choices=("hungarian", "rtv"))
    p.add_argument("--walks", nargs="+", type=float, default=[0.0, 150.0, 300.0, 500.0])
    p.add_argument("--seeds", nargs="+", type=int, default=[0])
    p.add_argument("--agents", type=int, default=400)
    p.add_argument("--start", default="00:00", help="window start, HH:MM of the day")
    p.add_argument("--hours", type=float, default=24.0, help="window length")
    p.add_argument("--meeting-points", type=int, default=8)
    p.add_argument("--json", help="append every run's figures to this file (JSON lines)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--allocator", help=argparse.SUPPRESS)
    p.add_argument("--walk", type=float, help=argparse.SUPPRESS)
    p.add_argument("--seed", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(args)
        return
    print(f"NYC day {args.start} + {args.hours:g} h, {args.agents} taxis of 4 seats, seeds "
          f"{args.seeds}", flush=True)
    for allocator in args.allocators:
        base: dict[int, dict] = {}
        for walk in args.walks:
            runs = []
            for seed in args.seeds:
                r = run_child(allocator, walk, seed, args)
                runs.append(r)
                if args.json:
                    with open(args.json, "a") as fh:
                        fh.write(json.dumps(r) + "\n")
                print(f"  {allocator} max_walk {walk:g} seed {seed}: served "
                      f"{r['served_share']:.4f} of {r['requests']}, {r['km_per_rider']:.3f} "
                      f"veh-km/rider, walk {r['walk_mean']:.0f} m, wait {r['wait_mean']:.0f} s, "
                      f"wall {r['wall']:.0f} s", flush=True)
                if walk == args.walks[0]:
                    base[seed] = r
            km, km_h = _ci([r["km_per_rider"] for r in runs])
            sv, sv_h = _ci([r["served_share"] for r in runs])
            wk, _ = _ci([r["walk_mean"] for r in runs])
            change, ch_h = _ci([r["km_per_rider"] / base[r["seed"]]["km_per_rider"] - 1.0
                                for r in runs])
            print(f"{allocator:9s} max_walk {walk:5.0f} m: veh-km/rider {km:.3f} ± {km_h:.3f}, "
                  f"served {100 * sv:.2f} ± {100 * sv_h:.2f} %, walk {wk:.0f} m; veh-km/rider "
                  f"vs max_walk {args.walks[0]:g}: {100 * change:+.1f} ± {100 * ch_h:.1f} %",
                  flush=True)


if __name__ == "__main__":
    main()
