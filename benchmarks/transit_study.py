"""Shared rides with and without the subway: the smallest fleet of 4-seat taxis serving at least
98 % of the riders, its vehicle-km per served rider, door-to-door times and mode shares.

Workload: ``scenarios/nyc_manhattan_transit.toml`` (NYC taxi requests of Sunday 2014-12-21 on
Manhattan's OSMnx streets, the shipped subway timetable of Wednesday 2026-09-23 with the
trace's clock laid on the feed's service day) cut to a window: the requests departing in
``--hours`` hours from ``--start`` (time of day), and half an hour more to finish their trips.
Each configuration is one run per fleet size, found by bisection:

* ``door to door``: the scenario without ``[transit]``: every request a taxi ride;
* ``subway, <choice>``: ``[transit]`` with the mode choice (``cheapest``: least generalized
  cost; ``logit``: a seeded multinomial logit, scale 0.1 per minute; ``train_first:S``: the
  cheapest option with a train where it costs at most S generalized seconds more than the
  cheapest, an operator steering riders to the train) at each ``--penalties`` transfer
  penalty (seconds per change of train).

A rider is served when every leg of their trip is made (``riders_served``; door to door: a
completed request). For each configuration the script prints the smallest fleet serving at
least ``--target`` of its riders and, at that fleet, vehicle-km per served rider (the whole
fleet's kilometres), door-to-door seconds (request to arrival at the goal: mean, median, 90th
percentile), the shares of riders by mode and the missed connections; ``--csv`` writes every
run's row. Runs are single-process and sequential (``nice -n 15`` on a shared machine).

    python benchmarks/transit_study.py --start 17:00 --hours 1 --csv transit_study.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENARIO = ROOT / "scenarios" / "nyc_manhattan_transit.toml"
MODES = ("fleet", "fleet_train", "train_fleet", "train")


def scenario_text(agents: int, start: str, hours: float, choice: str | None,
                  penalty: float) -> str:
    """The scenario's text for one run: ``agents`` taxis, the window, and ``[transit]`` with
    the mode choice ``choice`` and the transfer penalty (None: no ``[transit]``)."""
    out = []
    for line in SCENARIO.read_text().splitlines():
        key = line.split("=")[0].strip()
        if line.startswith("[transit]") and choice is None:
            break
        if key == "agents":
            line = f"agents = {agents}"
        elif key == "start":
            line = f'start = "2014-12-21T{start}"'
        elif key == "duration":
            line = f"duration = {hours * 3600.0 + 1800.0}"
        elif key == "transfer_penalty":
            line = f"transfer_penalty = {penalty}"
        elif key == "mode_choice" and choice is not None:
            name, _, slack = choice.partition(":")
            line = f'mode_choice = "{name}"' + (f"\n[transit.{name}]\nslack = {slack}"
                                                if slack else "")
        out.append(line)
    return "\n".join(out) + "\n"


def one(agents: int, start: str, hours: float, choice: str | None, penalty: float) -> dict:
    """One run's figures."""
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    with tempfile.TemporaryDirectory(prefix="transit-") as tmp:
        path = Path(tmp) / "nyc_manhattan_transit.toml"
        text = scenario_text(agents, start, hours, choice, penalty)
        path.write_text(text)
        trips = load_scenario(path, ignore_limits=True).tasks.trips
        n = int((trips.t < hours * 3600.0).sum())  # the window's requests
        path.write_text(text.replace("[tasks]\n", f"[tasks]\ncount = {n}\n"))
        [spec] = load_scenario(path, ignore_limits=True).runs()
        t0 = time.perf_counter()
        r = run_one(spec)
        wall = time.perf_counter() - t0
        s = r.summary
        row = dict(config=label(choice, penalty), agents=agents, requests=n, wall=round(wall, 1))
        if choice is None:
            t = r.tables["tasks"].to_pandas()
            done = t[t.state == "completed"]
            d2d = (done.completed_at - done.released_at).to_numpy()
            served = len(done)
            row.update(served=served / n, vkm_per_rider=s["distance"] / 1000.0 / max(served, 1),
                       d2d_mean=float(np.mean(d2d)), d2d_median=float(np.median(d2d)),
                       d2d_p90=float(np.percentile(d2d, 90)), missed=0,
                       **{f"share_{m}": float(m == "fleet") for m in MODES})
        else:
            row.update(served=s["riders_served"] / max(s["riders"], 1),
                       vkm_per_rider=s["vehicle_km_per_rider"], d2d_mean=s["door_to_door_mean"],
                       d2d_median=s["door_to_door_median"], d2d_p90=s["door_to_door_p90"],
                       missed=s["missed_connections"],
                       **{f"share_{m}": s[f"mode_share_{m}"] for m in MODES})
            legs = r.tables["legs"].to_pandas()
            row["train_legs"] = int((legs["mode"] == "train").sum())
    return row


def label(choice: str | None, penalty: float) -> str:
    return "door to door" if choice is None else f"subway, {choice}, penalty {penalty:g} s"


def smallest(start: str, hours: float, choice: str | None, penalty: float, target: float,
             lo: int, hi: int, step: int, rows: list) -> dict | None:
    """The smallest fleet (to ``step`` vehicles) serving ``target`` of the riders: ``hi``
    doubled until it does, then bisection; every run's row appended to ``rows``."""
    runs: dict[int, dict] = {}

    def at(k: int) -> dict:
        if k not in runs:
            runs[k] = one(k, start, hours, choice, penalty)
            rows.append(runs[k])
            r = runs[k]
            print(f"  {r['config']}: {k} taxis, served {r['served']:.4f}, "
                  f"{r['vkm_per_rider']:.2f} vkm/rider, d2d median {r['d2d_median']:.0f} s "
                  f"({r['wall']:.0f} s wall)", flush=True)
        return runs[k]

    while at(hi)["served"] < target:
        lo, hi = hi, hi * 2
        if hi > 4000:
            return None
    while hi - lo > step:
        mid = (lo + hi) // 2
        if at(mid)["served"] >= target:
            hi = mid
        else:
            lo = mid
    return runs[hi]


def plot(csvs: list[Path], out: Path, target: float = 0.98) -> Path:
    """Two panels from the rows of ``csvs`` (this script's ``--csv`` files): the share of
    riders served against the fleet size, one line per configuration; and vehicle-km per
    served rider against the median door-to-door time at each configuration's smallest fleet
    serving ``target`` (labelled with that fleet)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    rows = pd.concat([pd.read_csv(p) for p in csvs], ignore_index=True)
    rows = rows.drop_duplicates(["config", "agents"])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
    for config, g in rows.groupby("config", sort=False):
        g = g.sort_values("agents")
        ax.plot(g["agents"], g["served"] * 100, marker="o", ms=3, label=config)
        ok = g.loc[g["served"] >= target]
        if len(ok):
            b = ok.iloc[0]
            bx.scatter(b["d2d_median"] / 60, b["vkm_per_rider"])
            bx.annotate(f"{config} ({int(b['agents'])} taxis)",
                        (b["d2d_median"] / 60, b["vkm_per_rider"]), xytext=(4, 2),
                        textcoords="offset points", fontsize="x-small")
    ax.axhline(target * 100, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("taxis (4 seats)")
    ax.set_ylabel("riders served (%)")
    ax.set_ylim(90, 100.2)
    ax.legend(fontsize="x-small")
    lo, hi = bx.get_xlim()
    bx.set_xlim(lo, hi + (hi - lo) * 0.5)  # (room for the labels)
    bx.set_xlabel("median door-to-door time (min)")
    bx.set_ylabel("vehicle-km per served rider")
    bx.set_title(f"at the smallest fleet serving >= {target:.0%}", fontsize="small")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--start", default="17:00", help="time of day the window starts (HH:MM)")
    p.add_argument("--hours", type=float, default=1.0)
    p.add_argument("--target", type=float, default=0.98)
    p.add_argument("--choices", nargs="+", default=["cheapest", "logit", "train_first:600"])
    p.add_argument("--no-baseline", action="store_true", help="leave door to door out")
    p.add_argument("--penalties", type=float, nargs="+", default=[300.0])
    p.add_argument("--lo", type=int, default=20)
    p.add_argument("--hi", type=int, default=200)
    p.add_argument("--step", type=int, default=5, help="bisection stops within this many taxis")
    p.add_argument("--csv", type=Path)
    p.add_argument("--plot", type=Path, nargs="+", metavar="CSV",
                   help="draw tradeoff.png from these --csv files (no run) into --out-dir")
    p.add_argument("--out-dir", type=Path, default=ROOT / "docs" / "transit_study")
    a = p.parse_args(argv)
    if a.plot:
        print(plot(a.plot, a.out_dir / "tradeoff.png", a.target))
        return
    rows: list[dict] = []
    best = []
    configs = [] if a.no_baseline else [(None, 300.0)]
    configs += [(c, x) for c in a.choices for x in a.penalties]
    for choice, penalty in configs:
        print(label(choice, penalty), flush=True)
        b = smallest(a.start, a.hours, choice, penalty, a.target, a.lo, a.hi, a.step, rows)
        if b is not None:
            best.append(b)
        if a.csv:
            keys = sorted({k for r in rows for k in r})
            with a.csv.open("w", newline="") as f:
                w = csv.DictWriter(f, keys)
                w.writeheader()
                w.writerows(rows)
    print(f"\nsmallest fleet serving >= {a.target:.0%}, window {a.start} + {a.hours:g} h:")
    base = best[0] if best and best[0]["config"] == "door to door" else None
    for b in best:
        rel = "" if base is None or b is base else (
            f"  fleet {b['agents'] / base['agents'] - 1:+.0%}, vkm/rider "
            f"{b['vkm_per_rider'] / base['vkm_per_rider'] - 1:+.0%}, median d2d "
            f"{(b['d2d_median'] - base['d2d_median']) / 60:+.1f} min")
        shares = " ".join(f"{m} {b[f'share_{m}']:.1%}" for m in MODES)
        print(f"{b['config']:34s} {b['agents']:5d} taxis  served {b['served']:.3f}  "
              f"{b['vkm_per_rider']:.2f} vkm/rider  d2d mean/median/p90 {b['d2d_mean']:.0f}/"
              f"{b['d2d_median']:.0f}/{b['d2d_p90']:.0f} s  missed {b['missed']}  {shares}{rel}")


if __name__ == "__main__":
    main()
