"""Benchmark: prebooking on the NYC Manhattan taxi day (issue 31's target).

Runs ``scenarios/nyc_manhattan_prebook.toml`` (Sunday 2014-12-21, one-seat taxis, ``hungarian``
batched 30 s, ``max_wait`` 300 s from the requested departure) with 0 / 30 / 60 % of the
requests booked one hour ahead: 0 % is the shipped trace without bookings (``nyc_manhattan``
itself: today's dispatch), 30 % and 60 % the shipped traces
``scenarios/data/nyc_manhattan_prebook{30,60}.csv`` (booking times synthesised by
``scenarios/data/make_nyc_manhattan_prebook.py`` from a fixed seed). ``--agents`` (650: the
smallest of 600 / 650 / 700 that serves 98 % without prebooking) taxis; each share over
``--seeds`` run seeds (the fleet's start positions and the allocator's stream; the bookings are
the file's). ``--shares -1`` runs the day without bookings but dispatched as prebooking
dispatches (every request booked at its departure: insertion into the taxis' plans, one seat or
not), which separates what the bookings do from what the insertion does. ``--start HH:MM`` and
``--hours`` cut the day to a window (requests departing before the start are left out; a
booking before it enters at the start), with an hour more to finish.

Prints per run and, per share, the mean with a 95 % t interval over the seeds: the served
share of all requests, of the booked ones, and of the immediate ones; promises made and
broken; the mean wait (pickup - requested departure); wall seconds. The target: booked riders
served >= 99.5 % at this fleet, and the whole served share not lower than at 0 %.

``--allocator`` / ``--capacity`` run another allocator and seat count (e.g. ``rtv`` with 4
seats: its own routes, each booked pickup waiting for its requested departure).

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/prebook.py [--seeds 0 1 2] [--shares 0 30 60]
[--agents 650] [--start 00:00] [--hours 24] [--mode at_booking|lead] [--lead 900]
[--allocator hungarian] [--capacity 1] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENARIO = ROOT / "scenarios" / "nyc_manhattan_prebook.toml"
DATA = ROOT / "scenarios" / "data"


def scenario_text(share: int, agents: int, seed: int, start: str, hours: float, mode: str,
                  lead: float | None, allocator: str = "hungarian", capacity: int = 1) -> str:
    """The prebooking scenario's text for one run: its trace (0 %: the shipped one without
    bookings), fleet, seed, window, entry mode, allocator and seats."""
    out = []
    for line in SCENARIO.read_text().splitlines():
        key = line.split("=")[0].strip()
        if key == "trace":
            line = ('trace = "nyc_taxi_2014-12-21"' if share <= 0
                    else f'trace = "{DATA / f"nyc_manhattan_prebook{share}.csv"}"')
        elif key == "agents":
            line = f"agents = {agents}" + (f"\ncapacity = {capacity}" if capacity != 1 else "")
        elif key == "allocator":
            line = f'allocator = "{allocator}"'
        elif key == "seed":
            line = f"seed = {seed}"
        elif key == "start":
            line = f'start = "2014-12-21T{start}"'
        elif key == "duration":
            line = f"duration = {hours * 3600.0 + 3600.0}"
        elif key == "prebook":
            line = "" if share <= 0 else f'prebook = "{mode}"' + (
                f"\nprebook_lead = {lead}" if lead is not None else "")
        elif key == "max_wait" and share < 0:  # every request booked at its departure
            line += "\nprebook_share = 1.0\nprebook_lead = 0.0"
        out.append(line)
    return "\n".join(out) + "\n"


def one(share: int, agents: int, seed: int, start: str, hours: float, mode: str,
        lead: float | None, allocator: str = "hungarian", capacity: int = 1) -> dict:
    """One run's figures."""
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    with tempfile.TemporaryDirectory(prefix="prebook-") as tmp:
        path = Path(tmp) / "nyc_manhattan_prebook.toml"
        text = scenario_text(share, agents, seed, start, hours, mode, lead, allocator, capacity)
        path.write_text(text)
        trips = load_scenario(path, ignore_limits=True).tasks.trips
        # the window's requests only: those departing before its end (the hour after it
        # finishes their rides)
        n = int((trips.t < hours * 3600.0).sum())
        path.write_text(text.replace("[tasks]\n", f"[tasks]\ncount = {n}\n"))
        [spec] = load_scenario(path, ignore_limits=True).runs()
        t0 = time.perf_counter()
        r = run_one(spec)
        wall = time.perf_counter() - t0
    t = r.tables["tasks"].to_pandas()
    s = r.summary
    booked = t.booked_at.notna() & (t.released_at > t.booked_at)  # (share -1: none ahead)
    done = t.state == "completed"
    picked = t.picked_up_at.notna()
    return dict(share=share, seed=seed, requests=len(t), booked=int(booked.sum()),
                served=float(done.mean()),
                served_booked=float(done[booked].mean()) if booked.any() else math.nan,
                served_immediate=float(done[~booked].mean()),
                promises=int(s["promises"]), promises_broken=int(s["promises_broken"]),
                wait=float((t.picked_up_at - t.released_at)[picked].mean()),
                cut_off=int((t.state == "cut_off").sum()), wall=wall)


def interval(values: list[float], scale: float = 1.0, fmt: str = ".2f") -> str:
    """``mean ± half-width`` of a 95 % t interval (the mean alone for one value)."""
    v = [x * scale for x in values if x == x]
    if not v:
        return "-"
    m = statistics.fmean(v)
    if len(v) < 2:
        return f"{m:{fmt}}"
    from scipy import stats

    h = stats.t.ppf(0.975, len(v) - 1) * statistics.stdev(v) / len(v) ** 0.5
    return f"{m:{fmt}} ± {h:{fmt}}"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--shares", type=int, nargs="+", default=[0, 30, 60], choices=(-1, 0, 30, 60),
                   help="-1: no booking, every request dispatched as one booked at its "
                        "departure (the insertion into plans that prebooking turns on)")
    p.add_argument("--agents", type=int, default=650)
    p.add_argument("--start", default="00:00", help="HH:MM: the window's start")
    p.add_argument("--hours", type=float, default=24.0, help="the window's hours")
    p.add_argument("--mode", default="at_booking", choices=("at_booking", "lead"))
    p.add_argument("--lead", type=float, default=None,
                   help="[dispatch] prebook_lead (seconds; --mode lead)")
    p.add_argument("--allocator", default="hungarian")
    p.add_argument("--capacity", type=int, default=1, help="seats per vehicle")
    p.add_argument("--json", type=Path, help="write every run's figures here")
    a = p.parse_args(argv)
    rows = []
    for share in a.shares:
        for seed in a.seeds:
            r = one(share, a.agents, seed, a.start, a.hours, a.mode, a.lead, a.allocator,
                    a.capacity)
            rows.append(r)
            print(f"share {share:2d} % seed {seed}: {r['requests']} requests, {r['booked']} "
                  f"booked; served {100 * r['served']:.2f} % (booked "
                  f"{100 * r['served_booked']:.2f} %, immediate "
                  f"{100 * r['served_immediate']:.2f} %); promises {r['promises']}, broken "
                  f"{r['promises_broken']}; wait {r['wait']:.1f} s; cut off by the end "
                  f"{r['cut_off']}; {r['wall']:.0f} s wall", flush=True)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))
    print(f"\n{a.agents} taxis of {a.capacity} seat(s), {a.allocator}, window {a.start} + "
          f"{a.hours:g} h, mode {a.mode}, seeds {a.seeds} (mean ± 95 % t interval)")
    print("| booked | served % | booked served % | immediate served % | promises broken "
          "| wait s |")
    print("|---|---|---|---|---|---|")
    for share in a.shares:
        rs = [r for r in rows if r["share"] == share]
        print(f"| {share} % | {interval([r['served'] for r in rs], 100)} "
              f"| {interval([r['served_booked'] for r in rs], 100)} "
              f"| {interval([r['served_immediate'] for r in rs], 100)} "
              f"| {interval([r['promises_broken'] for r in rs], 1, '.1f')} "
              f"| {interval([r['wait'] for r in rs], 1, '.1f')} |")


if __name__ == "__main__":
    main()
