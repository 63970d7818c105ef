"""The NYC pooling study (issue 20): Manhattan with the real taxi requests of 2014-12-21, insertion
(``hungarian`` batched 30 s) against ``rtv`` (batched 30 s), seats {1, 2, 4}, fleet sizes found
by bisection, 3 seeds.

Each run is ``scenarios/nyc_manhattan.toml`` with ``max_wait`` 300 s, ``max_delay`` 600 s
(``--max-wait`` / ``--max-delay``), ``--hours`` of the day (24: all of it, run as the scenario
does, an hour past the day), the fleet size, the seats and the allocator overridden; the seed
places the fleet. For each (seats, method) the smallest fleet that serves >= ``--target``
(98 %) of the requests is searched on seed 0 by bisection over multiples of ``--step`` (50)
between ``--low`` and ``--high``; then the other seeds run at that size and at the size one
step below, and the search moves up while the mean over the seeds misses the target. Every
run's summary is kept in ``<out>/runs.jsonl`` (a rerun skips runs already there: resumable).

Printed and written to ``<out>/study.md``: per (seats, method, fleet) the served share, mean
wait, mean delay (drop-off - release - direct drive), occupancy (passenger-km / vehicle-km),
vehicle-km, seconds per batch (the decision's costs and allocator, mean) and, for ``rtv``, what
its bounds cut; means over the seeds run, with a 95 % t-interval where 3 seeds ran; then the
smallest fleet per seats and method.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/nyc_study.py --out runs/nyc_study``
(``--hours 6`` for a quick look).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

METHODS = ("hungarian", "rtv")


def interval(values: list[float], fmt: str = ".3g") -> str:
    """``mean ± half-width`` of a 95 % t-interval (the mean alone below 3 values)."""
    m = statistics.fmean(values)
    if len(values) < 3:
        return format(m, fmt)
    from scipy import stats

    h = stats.t.ppf(0.975, len(values) - 1) * statistics.stdev(values) / len(values) ** 0.5
    return f"{format(m, fmt)} ± {h:.2g}"


def run_arguments(p: argparse.ArgumentParser) -> None:
    """The options :func:`run` reads from its ``a``: ``--hours`` of the day, ``--max-wait``,
    ``--max-delay``."""
    p.add_argument("--hours", type=float, default=24.0)
    p.add_argument("--max-wait", type=float, default=300.0)
    p.add_argument("--max-delay", type=float, default=600.0)


def run(a, seats: int, method: str, fleet: int, seed: int, params: dict | None = None) -> dict:
    """One run's numbers (the simulation in this process); ``params``: allocator parameters
    over the scenario's (e.g. rtv's ``reorder``)."""
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    sc = load_scenario(ROOT / "scenarios" / "nyc_manhattan.toml")
    s = dataclasses.replace(
        sc, duration=a.hours * 3600.0 + 3600.0,
        fleet=dataclasses.replace(sc.fleet, agents=fleet, capacity=seats),
        tasks=dataclasses.replace(sc.tasks, max_wait=a.max_wait, max_delay=a.max_delay),
        dispatch=dataclasses.replace(
            sc.dispatch, allocator=method, batch_window=30.0,
            allocator_params=tuple(sorted({**dict(sc.dispatch.allocator_params),
                                           **(params or {})}.items()))),
        sweep=dataclasses.replace(sc.sweep, agents=(), allocator=(), batch_window=(), seed=(),
                                  reposition=()),
        name=f"nyc_study_{method}_c{seats}_n{fleet}")
    [spec] = s.runs(seed=seed)
    with tempfile.TemporaryDirectory(prefix="nyc-study-") as tmp:
        t0 = time.perf_counter()
        rec = make_recorder(spec, Path(tmp) / "out")
        sim = Simulation(spec, rec)
        r = sim.run()
        rec.finish()
        wall = time.perf_counter() - t0
    d = sim.tally
    released = r["n_tasks"]
    if a.hours < 24:  # requests released before the cut (the rest never were)
        released = max(1, r["n_tasks"] - r.get("tasks_cut_off", 0))
    return {"seats": seats, "method": method, "fleet": fleet, "seed": seed, "hours": a.hours,
            "max_wait": a.max_wait, "max_delay": a.max_delay, "requests": r["n_tasks"],
            "served": r["tasks_completed"] / released, "wait": r["wait_time_mean"],
            "delay": r.get("delay_mean"), "occupancy": r.get("occupancy"),
            "shared": r.get("shared_rate"), "vkm": r["distance"] / 1000.0,
            "batch_s": (d.cost_seconds + d.decide_seconds) / max(1, r["decisions"]),
            "decisions": r["decisions"], "wall": wall,
            "rtv": dict(getattr(sim.allocator, "stats", {}) or {})}


class Study:
    def __init__(self, a) -> None:
        self.a = a
        self.out = Path(a.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / "runs.jsonl"
        self.done: dict[tuple, dict] = {}
        if self.path.exists():
            for line in self.path.read_text().splitlines():
                r = json.loads(line)
                if (r["hours"], r["max_wait"], r["max_delay"]) == (a.hours, a.max_wait,
                                                                    a.max_delay):
                    self.done[(r["seats"], r["method"], r["fleet"], r["seed"])] = r

    def get(self, seats: int, method: str, fleet: int, seed: int) -> dict:
        key = (seats, method, fleet, seed)
        if key not in self.done:
            r = run(self.a, seats, method, fleet, seed)
            self.done[key] = r
            with self.path.open("a") as fh:
                fh.write(json.dumps(r) + "\n")
            print(f"  seats {seats} {method:9s} fleet {fleet:4d} seed {seed}: served "
                  f"{r['served']:.3f}, wait {r['wait']:.0f} s, delay {r['delay'] or 0:.0f} s, "
                  f"occupancy {r['occupancy'] or 0:.2f}, {r['batch_s'] * 1000:.0f} ms/batch, "
                  f"run {r['wall']:.0f} s", flush=True)
        return self.done[key]

    def mean_served(self, seats, method, fleet) -> float:
        return statistics.fmean(self.get(seats, method, fleet, s)["served"]
                                for s in self.a.seeds)

    def smallest(self, seats: int, method: str) -> int:
        """The smallest fleet (a multiple of the step) whose mean served share over the seeds
        reaches the target: bisection on the first seed, then checked on all."""
        a = self.a
        step, target = a.step, a.target
        lo, hi = a.low // step, a.high // step  # in steps: lo fails (or is the floor), hi holds
        first = a.seeds[0]
        if self.get(seats, method, hi * step, first)["served"] < target:
            return -1
        if self.get(seats, method, lo * step, first)["served"] >= target:
            hi = lo
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if self.get(seats, method, mid * step, first)["served"] >= target:
                hi = mid
            else:
                lo = mid
        n = hi
        while n * step <= a.high:  # all seeds: up while the mean misses
            if self.mean_served(seats, method, n * step) >= target:
                break
            n += 1
        if n > a.low // step:  # and the size below, for the table
            self.mean_served(seats, method, (n - 1) * step)
        return n * step


def table(study: Study, best: dict) -> str:
    a = study.a
    rows = {}
    for (seats, method, fleet, seed), r in study.done.items():
        rows.setdefault((seats, method, fleet), []).append(r)
    lines = [(f"Manhattan, NYC taxi requests of 2014-12-21 ({a.hours:g} h), max_wait "
              f"{a.max_wait:g} s, max_delay {a.max_delay:g} s, batches of 30 s; mean over the "
              f"seeds run (± 95 % t-interval where 3 ran)"), "",
             ("| seats | method | fleet | seeds | served % | mean wait s | mean delay s | "
              "occupancy | vehicle-km | s / batch | rtv cut (pairs / groups / orders) |"),
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for (seats, method, fleet), rs in sorted(rows.items()):
        def col(k, rs=rs):
            return [float(r[k] or 0.0) for r in rs]

        cut = ""
        if method == "rtv":
            st = [r["rtv"] for r in rs]
            cut = " / ".join(f"{statistics.fmean(s.get(k, 0) for s in st):.0f}"
                             for k in ("pairs_cut", "groups_cut", "orders_cut"))
        lines.append(f"| {seats} | {method} | {fleet} | {len(rs)} | "
                     f"{interval([100 * x for x in col('served')], '.1f')} | "
                     f"{interval(col('wait'), '.0f')} | {interval(col('delay'), '.0f')} | "
                     f"{statistics.fmean(col('occupancy')):.2f} | "
                     f"{statistics.fmean(col('vkm')):.0f} | "
                     f"{statistics.fmean(col('batch_s')):.3f} | {cut} |")
    lines += ["", (f"Smallest fleet serving ≥ {100 * a.target:g} % (mean over seeds "
                   f"{', '.join(map(str, a.seeds))}; fleets in steps of {a.step}):"), "",
              "| seats | " + " | ".join(METHODS) + " |", "|---:|" + "---:|" * len(METHODS)]
    for seats in a.seats:
        cells = []
        for method in a.methods:
            n = best.get((seats, method))
            if n is None:
                cells.append("")
                continue
            if n < 0:
                cells.append(f"> {a.high}")
                continue
            rs = [study.done[(seats, method, n, s)] for s in a.seeds]
            cells.append(f"{n} ({interval([100 * r['served'] for r in rs], '.1f')} %)")
        lines.append(f"| {seats} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def figure(study: Study, path: Path) -> Path:
    """``study.png``: served share (left) and riders' mean delay (right) against the fleet
    size, one line per seats x method (mean over the seeds that ran that size, error bars the
    95 % t-interval where three or more did), the target as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    by: dict = {}
    for (seats, method, fleet, _), r in study.done.items():
        by.setdefault((seats, method), {}).setdefault(fleet, []).append(r)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    colours = {1: "#7f7f7f", 2: "#1f77b4", 4: "#d62728"}
    for (seats, method), sizes in sorted(by.items()):
        xs = sorted(sizes)
        for ax, key, scale in ((left, "served", 100.0), (right, "delay", 1.0)):
            mean, half = [], []
            for x in xs:
                v = [scale * (r[key] or 0.0) for r in sizes[x]]
                mean.append(statistics.fmean(v))
                half.append(stats.t.ppf(0.975, len(v) - 1) * statistics.stdev(v) / len(v) ** 0.5
                            if len(v) >= 3 else 0.0)
            ax.errorbar(xs, mean, yerr=half, marker="o" if method == "rtv" else "s", ms=4,
                        capsize=2, color=colours.get(seats, "k"),
                        linestyle="-" if method == "rtv" else "--",
                        label=f"{seats} seat{'s' if seats > 1 else ''}, {method}")
    left.axhline(100 * study.a.target, color="k", lw=0.8, ls=":")
    left.set(xlabel="taxis", ylabel="served (%)", title="Served share of the day's requests")
    right.set(xlabel="taxis", ylabel="mean delay (s)",
              title="Riders' delay (drop-off - release - direct)")
    for ax in (left, right):
        ax.grid(True, alpha=0.3)
    left.legend(fontsize="small")
    fig.suptitle("Manhattan, 2014-12-21: insertion (hungarian, batched 30 s) vs rtv")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="runs/nyc_study")
    p.add_argument("--seats", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    run_arguments(p)
    p.add_argument("--target", type=float, default=0.98)
    p.add_argument("--step", type=int, default=50)
    p.add_argument("--low", type=int, default=200)
    p.add_argument("--high", type=int, default=1000)
    a = p.parse_args(argv)
    study = Study(a)
    best = {}
    t0 = time.perf_counter()
    for seats in a.seats:
        for method in a.methods:
            print(f"seats {seats}, {method}:", flush=True)
            best[(seats, method)] = study.smallest(seats, method)
            print(f"  smallest fleet: {best[(seats, method)]}", flush=True)
    text = table(study, best)
    text += f"\nStudy wall time {time.perf_counter() - t0:.0f} s (runs already done skipped).\n"
    (study.out / "study.md").write_text(text)
    print(text)
    print(f"figure: {figure(study, study.out / 'study.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
