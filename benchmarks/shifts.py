"""Driver shifts on the NYC Manhattan day (issue 31, target: a three-shift fleet that serves
>= 98 % of the day with >= 15 % fewer vehicle-hours than the smallest all-day fleet that does).

Each run is ``scenarios/nyc_manhattan.toml`` (19,979 requests of Sunday 2014-12-21, 18,167 within
250 m of the network; one seat, ``hungarian`` batched 30 s, requests wait at most 5 min) with
its fleet replaced by a start file. Every vehicle's node and depot is drawn (seed 0) from the
day's pickup nodes, each with its share of the requests, so the all-day fleet and the shift
fleet start from the same kind of places and only the shifts differ.

1. **All-day fleet**: ``N`` vehicles on duty all run; the smallest ``N`` (a multiple of
   ``--step``) serving >= ``--target`` is found by bisection between ``--low`` and ``--high``.
2. **Three shifts** of 8 h (00-08, 08-16, 16-24 h; ``[fleet] shift_grace`` ``--grace`` s):
   each shift in turn gets the smallest size (a multiple of ``--step``, by bisection) at which
   the requests released during it are served >= the target, the shifts not yet sized at the
   all-day size; should the day as a whole then miss the target, the shift with the lowest
   share grows by ``--step`` until it does not.

Vehicle-hours are the runs' ``vehicle_hours`` (on duty: from entering to reaching the depot,
or the run's end: 25 h for the all-day fleet). Every run is kept in ``<out>/runs.jsonl`` (a
rerun skips those already there); the table goes to ``<out>/shifts.md`` and the three-shift
start file found to ``<out>/fleet.csv`` (shipped as ``scenarios/data/nyc_manhattan_shifts.csv``).

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/shifts.py --out runs/shifts`` (one core;
about 20 s a run on the full day).
"""

from __future__ import annotations

import argparse
import csv
import functools
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SHIFTS = ((0.0, 8 * 3600.0), (8 * 3600.0, 16 * 3600.0), (16 * 3600.0, 24 * 3600.0))


def depots(n: int, seed: int = 0) -> list[int]:
    """``n`` node ids of the network drawn from the day's pickups (seeded; the first ``k``
    of ``n`` are the ``k`` drawn for a smaller fleet)."""
    return _depots(seed, max(n, 4000))[:n]


@functools.cache
def _depots(seed: int, n: int) -> list[int]:
    from dispatch.api.space import space_for
    from dispatch.scenario.load import load_scenario

    sc = load_scenario(ROOT / "scenarios" / "nyc_manhattan.toml")
    net = space_for(sc.world, 0, sc.path)
    trips = sc.tasks.trips  # latlon layout: (lat, lon)
    xy = net.lonlat_to_xy(trips.origin[:, 1], trips.origin[:, 0])
    nodes, _ = net.nearest(xy)
    pick = np.random.default_rng(seed).choice(nodes, size=n, replace=True)
    return [int(net.ids[int(k)]) for k in pick]


def write_fleet(path: Path, sizes: list[int] | None, n_all: int, nodes: list[int]) -> None:
    """A start file: ``sizes`` vehicles per shift (None: ``n_all`` all day, no shift
    columns), each at its depot node."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        if sizes is None:
            w.writerow(["vehicle_id", "node"])
            w.writerows((i, nodes[i]) for i in range(n_all))
            return
        w.writerow(["vehicle_id", "node", "shift_start", "shift_end", "depot"])
        i = 0
        for (a, b), n in zip(SHIFTS, sizes):
            for _ in range(n):
                w.writerow((i, nodes[i], int(a), int(b), nodes[i]))
                i += 1


def run(a, sizes: list[int] | None, n_all: int = 0) -> dict:
    """One full-day run with the fleet of :func:`write_fleet`."""
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    nodes = depots(sum(sizes) if sizes else n_all)
    base = (ROOT / "scenarios" / "nyc_manhattan.toml").read_text()
    head, _, rest = base.partition("[fleet]")
    _, _, rest = rest.partition("[tasks]")
    with tempfile.TemporaryDirectory(prefix="shifts-") as tmp:
        tmp = Path(tmp)
        write_fleet(tmp / "fleet.csv", sizes, n_all, nodes)
        grace = f"shift_grace = {a.grace}\n" if sizes else ""
        (tmp / "s.toml").write_text(head + f'[fleet]\nstart = "fleet.csv"\n{grace}\n[tasks]'
                                    + rest)
        [spec] = load_scenario(tmp / "s.toml").runs()
        t0 = time.perf_counter()
        result = run_one(spec)
        wall = time.perf_counter() - t0
    r = result.summary
    tasks = result.tables["tasks"].to_pandas()
    by_shift = []
    for lo, hi in SHIFTS:  # the served share of the requests released in each shift
        mine = tasks[(tasks.released_at >= lo) & (tasks.released_at < hi)]
        by_shift.append(float((mine.state == "completed").mean()) if len(mine) else 1.0)
    return {"sizes": sizes, "n_all": n_all, "grace": a.grace, "requests": r["n_tasks"],
            "served": r["tasks_completed"] / r["n_tasks"], "vehicle_hours": r["vehicle_hours"],
            "riders_per_vehicle_hour": r["riders_per_vehicle_hour"],
            "overruns": r["shift_overruns"], "wait": r["wait_time_mean"],
            "vkm": r["distance"] / 1000.0, "wall": wall, "by_shift": by_shift}


class Runs:
    def __init__(self, a) -> None:
        self.a, self.out = a, Path(a.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / "runs.jsonl"
        self.done = {}
        if self.path.exists():
            for line in self.path.read_text().splitlines():
                r = json.loads(line)
                if "by_shift" not in r:  # (a run of an earlier version of this script)
                    if r["sizes"]:
                        continue
                    r["by_shift"] = []
                self.done[self._key(r["sizes"], r["n_all"], r["grace"])] = r

    @staticmethod
    def _key(sizes, n_all, grace):
        return (tuple(sizes) if sizes else None, n_all if not sizes else 0, grace)

    def get(self, sizes=None, n_all: int = 0) -> dict:
        key = self._key(sizes, n_all, self.a.grace)
        if key not in self.done:
            r = run(self.a, list(sizes) if sizes else None, n_all)
            self.done[key] = r
            with self.path.open("a") as fh:
                fh.write(json.dumps(r) + "\n")
            what = f"shifts {list(sizes)}" if sizes else f"all-day {n_all}"
            print(f"  {what}: served {r['served']:.2%} (by shift "
                  f"{', '.join(f'{x:.2%}' for x in r['by_shift'])}), "
                  f"{r['vehicle_hours']:.0f} vehicle-h, {r['wall']:.0f} s", flush=True)
        return self.done[key]


def smallest(ok, lo: int, hi: int, step: int) -> int:
    """The smallest multiple of ``step`` from ``lo`` up for which ``ok`` holds (taken as
    monotone), by bisection; ``hi`` is doubled until it holds."""
    lo, hi = lo // step, -(-hi // step)
    while not ok(hi * step):
        lo, hi = hi + 1, hi * 2
    while lo < hi:
        mid = (lo + hi) // 2
        if ok(mid * step):
            hi = mid
        else:
            lo = mid + 1
    return hi * step


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="runs/shifts")
    p.add_argument("--target", type=float, default=0.98)
    p.add_argument("--low", type=int, default=300)
    p.add_argument("--high", type=int, default=650)
    p.add_argument("--step", type=int, default=10)
    p.add_argument("--grace", type=float, default=900.0)
    a = p.parse_args(argv)
    runs = Runs(a)
    print("all-day fleet (bisection):")
    n_all = smallest(lambda n: runs.get(n_all=n)["served"] >= a.target, a.low, a.high, a.step)
    base = runs.get(n_all=n_all)
    print("three shifts: each shift's smallest size serving >= the target of the requests "
          "released in it (the later shifts at the all-day size meanwhile)")
    best = [n_all] * len(SHIFTS)
    for k in range(len(SHIFTS)):
        def ok(n: int, k: int = k) -> bool:
            trial = list(best)
            trial[k] = n
            return runs.get(tuple(trial))["by_shift"][k] >= a.target

        best[k] = smallest(ok, a.step, n_all, a.step)
    while runs.get(tuple(best))["served"] < a.target:  # the day as a whole, to be sure
        k = int(np.argmin(runs.get(tuple(best))["by_shift"]))
        best[k] += a.step
    shift = runs.get(tuple(best))
    saving = 1.0 - shift["vehicle_hours"] / base["vehicle_hours"]
    nodes = depots(sum(best))
    write_fleet(runs.out / "fleet.csv", best, 0, nodes)
    lines = [
        "| fleet | vehicles | served | vehicle-hours | riders / vehicle-hour | overruns | "
        "mean wait s | vehicle-km |",
        "|---|---|---|---|---|---|---|---|",
        f"| all day (smallest >= {a.target:.0%}) | {n_all} | {base['served']:.2%} | "
        f"{base['vehicle_hours']:.0f} | {base['riders_per_vehicle_hour']:.2f} | - | "
        f"{base['wait']:.1f} | {base['vkm']:.0f} |",
        f"| three shifts 00-08/08-16/16-24 h | {' + '.join(map(str, best))} | "
        f"{shift['served']:.2%} | {shift['vehicle_hours']:.0f} | "
        f"{shift['riders_per_vehicle_hour']:.2f} | {shift['overruns']} | "
        f"{shift['wait']:.1f} | {shift['vkm']:.0f} |",
        "",
        f"vehicle-hours saved: {saving:.1%} (target >= 15 %: "
        f"{'met' if saving >= 0.15 and shift['served'] >= a.target else 'missed'}); "
        f"all-day fleet one step smaller "
        f"({n_all - a.step}): served {runs.get(n_all=n_all - a.step)['served']:.2%}",
    ]
    text = "\n".join(lines)
    print(text)
    (runs.out / "shifts.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
