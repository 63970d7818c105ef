"""Benchmark: shared rides on the Chicago day, capacity 1, 2 and 4 (``hungarian`` batched 30 s).

The day of ``scenarios/chicago_taxi.toml`` (40,000 trips drawn from the Chicago sample,
congestion by the hour, taxis placed on the sample's pickup nodes, ``max_wait`` 600 s) with
``--agents`` taxis of each ``--capacities`` seats, ``max_delay`` ``--max-delay`` s (drop-off by
release + direct free-flow time + that; the day's congestion spends part of it) and the
``--objective``, over ``--seeds``. Printed per
capacity: served share, mean wait, occupancy (passenger-km / vehicle-km), share of rides shared,
mean delay, vehicle-km (thousands) and wall seconds of the run (mean over the seeds; with 3 or
more seeds a 95 % t-interval of the served share and the wait).

Run: ``.venv/bin/python benchmarks/pooling_chicago.py [--agents 500] [--seeds 0 1 2]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.run.runner import run_one  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402


def interval(values: list[float]) -> str:
    """``mean ± half-width`` of a 95 % t-interval (the mean alone below 3 values)."""
    m = statistics.fmean(values)
    if len(values) < 3:
        return f"{m:.3g}"
    from scipy import stats

    h = stats.t.ppf(0.975, len(values) - 1) * statistics.stdev(values) / len(values) ** 0.5
    return f"{m:.3g} ± {h:.2g}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=500)
    p.add_argument("--capacities", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--max-delay", type=float, default=900.0,
                   help="seconds over the free-flow direct drive (0: no limit); the day is "
                        "congested, so the drive alone takes some of it")
    p.add_argument("--objective", default="pickup_time", choices=["pickup_time", "added_time"])
    p.add_argument("--hours", type=float, default=24.0)
    a = p.parse_args(argv)
    sc = load_scenario(ROOT / "scenarios" / "chicago_taxi.toml")
    rows = []
    for cap in a.capacities:
        got = []
        for seed in a.seeds:
            s = dataclasses.replace(
                sc, duration=a.hours * 3600 + 7200,
                fleet=dataclasses.replace(sc.fleet, agents=a.agents, capacity=cap),
                tasks=dataclasses.replace(sc.tasks,
                                          max_delay=a.max_delay if a.max_delay > 0 else None,
                                          trips_per_day=sc.tasks.trips_per_day * a.hours / 24),
                dispatch=dataclasses.replace(sc.dispatch, allocator="hungarian",
                                             batch_window=30.0, objective=a.objective),
                sweep=dataclasses.replace(sc.sweep, agents=(), allocator=(), batch_window=(),
                                          seed=(), reposition=()),
                name=f"chicago_pooled_c{cap}")
            [spec] = s.runs(seed=seed)
            t0 = time.perf_counter()
            r = run_one(spec).summary
            wall = time.perf_counter() - t0
            got.append((r["tasks_completed"] / r["n_tasks"], r["wait_time_mean"],
                        r["occupancy"], r["shared_rate"], r["delay_mean"],
                        r["distance"] / 1e6, wall))
            print(f"capacity {cap} seed {seed}: served {got[-1][0]:.3f}, wait "
                  f"{got[-1][1]:.1f} s, occupancy {got[-1][2]:.2f}, {wall:.0f} s", flush=True)
        rows.append((cap, got))
    print(f"\nChicago day, {a.agents} taxis, hungarian batched 30 s, max_wait 600 s, max_delay "
          f"{a.max_delay:.0f} s, objective {a.objective}, seeds {a.seeds}")
    print(f"{'seats':>5} {'served':>14} {'wait s':>14} {'occupancy':>9} {'shared':>7} "
          f"{'delay s':>8} {'k vkm':>6} {'wall s':>7}")
    for cap, got in rows:
        col = list(zip(*got))
        print(f"{cap:>5} {interval([100 * x for x in col[0]]):>14} {interval(list(col[1])):>14} "
              f"{statistics.fmean(col[2]):>9.2f} {100 * statistics.fmean(col[3]):>6.1f}% "
              f"{statistics.fmean(col[4]):>8.1f} {statistics.fmean(col[5]):>6.1f} "
              f"{statistics.fmean(col[6]):>7.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
