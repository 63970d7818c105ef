"""Benchmark: this project's ``fcfs`` against RidePy and SUMO's taxi device on one workload.

The workload (``benchmarks/peers_workload.py``): a Manhattan grid of 20 x 20 intersections,
200 m blocks, 10 m/s, two-way streets; ``--requests`` Poisson requests over ``--hours`` (origins
and destinations uniform over the intersections, destination != origin); ``--vehicles`` taxis
of capacity 1 on uniformly drawn intersections; all seeded (``--seed``). Written once as a trace
and a start file, so every simulator gets the same requests and starts; each run stops
``--drain`` seconds after the last release.

* **ours** (``benchmarks/peers_ours.py``): ``[world] network = "manhattan"``, allocator
  ``fcfs``, planner ``dijkstra``, no ``max_wait`` (the peers' requests wait without limit).
* **RidePy** (``benchmarks/peers_ridepy.py``): Cython core, brute-force total-travel-time
  insertion dispatcher, seat capacity 1, Manhattan space in blocks.
* **SUMO** (``benchmarks/peers_sumo.py``): ``netgenerate --grid`` net with unregulated
  junctions and no internal links, persons with taxi rides, ``greedy`` dispatch every 1 s;
  ``--only ... sumo-instant`` adds the same run with taxis that accelerate and brake within one
  step, which splits the wait difference to ``fcfs`` into kinematics and time steps.

Each simulator runs in its own process (its peak RSS is its own), ``--repeats`` times,
interleaved (ours, RidePy, SUMO, ours, ...) so that the load of a shared machine falls on all
alike. Printed: requests per wall second (from the median wall), wall seconds (min / median),
CPU seconds (median), peak RSS, and the service metrics side by side (served, wait mean / p90
over the requests picked up, vehicle km); then the ratios ours / each peer.

The peers are slow at the full size (SUMO's greedy routes every idle taxi to every waiting
request each second). ``--peer-requests K`` runs the peers, and ours beside them, on the first
K requests of the full workload with the full fleet: the same rate per vehicle, a shorter day;
ours then also runs the full workload, and its rate there is compared with the peers' rates on
the prefix. The output says so plainly.

The peers live in their own environment, never this project's: ``python benchmarks/peers.py
--setup`` creates ``benchmarks/.peers-venv`` (Python 3.11; RidePy, eclipse-sumo, sumolib at the
pinned versions below). RidePy builds a C++ extension that needs the Boost Graph headers
(Debian: ``apt-get install -y libboost-graph-dev``).

Run: ``.venv/bin/python benchmarks/peers.py [--requests 100000 --vehicles 1000 --hours 24]
[--peer-requests 2000] [--repeats 3] [--only ours ridepy sumo]``.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from peers_workload import compare_pickups, generate, prefix, write

VENV = HERE / ".peers-venv"
#: The peers, pinned (RidePy builds from source against Boost; SUMO ships wheels).
PINS = ("ridepy==2.10.1", "eclipse-sumo==1.28.0", "sumolib==1.28.0", "numpy==2.4.6")
BOOST_HEADER = Path("/usr/include/boost/graph/adjacency_list.hpp")
SIMULATORS = ("ours", "ridepy", "sumo", "sumo-instant")
LABEL = {"ours": "ours fcfs", "ridepy": "RidePy", "sumo": "SUMO", "sumo-instant": "SUMO inst"}


def peer_python() -> Path:
    return VENV / "bin" / "python"


def setup() -> None:
    """Create ``benchmarks/.peers-venv`` (Python 3.11) and install the pinned peers into it."""
    if not BOOST_HEADER.exists():
        sys.exit(f"peers --setup: RidePy needs the Boost Graph headers ({BOOST_HEADER} is "
                 "missing): apt-get install -y libboost-graph-dev")
    py = shutil.which("python3.11") or (sys.executable if sys.version_info[:2] == (3, 11)
                                        else None)
    if py is None:
        sys.exit("peers --setup: needs a python3.11 on PATH")
    if not peer_python().exists():
        subprocess.run([py, "-m", "venv", str(VENV)], check=True)
    subprocess.run([str(peer_python()), "-m", "pip", "install", "-q", *PINS], check=True)
    print(f"peers environment ready: {VENV}\n  {', '.join(PINS)}")


def command(sim: str, folder: Path, out: Path,
            ours: dict[str, tuple[str, ...]] | None = None) -> list[str]:
    """The command line of one run of ``sim``. ``ours``: the runs of the project's runner by
    name, each with its arguments after the two paths (allocator, objective, batch window;
    default ``{"ours": ()}``: ``fcfs`` at once); ``ridepy-grid``: RidePy on its graph space."""
    ours = {"ours": ()} if ours is None else ours
    if sim in ours:
        return [sys.executable, str(HERE / "peers_ours.py"), str(folder), str(out), *ours[sim]]
    if sim == "sumo-instant":
        return [str(peer_python()), str(HERE / "peers_sumo.py"), str(folder), str(out), "instant"]
    if sim == "ridepy-grid":
        return [str(peer_python()), str(HERE / "peers_ridepy.py"), str(folder), str(out), "grid"]
    return [str(peer_python()), str(HERE / f"peers_{sim}.py"), str(folder), str(out)]


def run_once(sim: str, folder: Path, ours: dict[str, tuple[str, ...]] | None = None) -> dict:
    """One run of ``sim`` on the workload in ``folder``, in a fresh process; its JSON row."""
    out = folder / f"{sim}.json"
    out.unlink(missing_ok=True)
    proc = subprocess.run(command(sim, folder, out, ours), check=False, cwd=ROOT,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["(no output)"]
        raise RuntimeError(f"{sim} failed (exit {proc.returncode}): {tail[0]}")
    return json.loads(out.read_text())


def run_all(sims: list[str], folder: Path, repeats: int, log,
            ours: dict[str, tuple[str, ...]] | None = None,
            label: dict[str, str] | None = None) -> dict[str, dict]:
    """``repeats`` interleaved runs of each simulator: the first run's metrics (they are
    deterministic; a change between runs is reported) with every run's wall and CPU seconds.
    ``ours``: as :func:`command`'s (several named runs of the project's runner may be among
    ``sims``)."""
    label = label or LABEL
    rows: dict[str, dict] = {}
    width = max([11, *(len(label[sim]) for sim in sims)])
    for k in range(repeats):
        for sim in sims:
            r = run_once(sim, folder, ours)
            log(f"  {label[sim]:<{width}} run {k + 1}/{repeats}: {r['wall_s']:7.1f} s wall, "
                f"{r['cpu_s']:7.1f} s CPU")
            if sim not in rows:
                rows[sim] = dict(r, walls=[], cpus=[], rss=[])
            elif any(r[m] != rows[sim][m] for m in ("served", "picked", "wait_mean")):
                log(f"  note: {label[sim]} metrics changed between runs")
            rows[sim]["walls"].append(r["wall_s"])
            rows[sim]["cpus"].append(r["cpu_s"])
            rows[sim]["rss"].append(r["rss_mb"])
    return rows


def _f(x: float, nd: int = 1) -> str:
    return "-" if math.isnan(x) else f"{x:,.{nd}f}"


def print_tables(console, title: str, rows: dict[str, dict]) -> None:
    """The side-by-side table and the ratios ours / each peer (80 columns)."""
    from rich.table import Table

    table = Table(title=title, title_justify="left", pad_edge=False, box=None)
    for name, just in (("", "left"), ("req/s", "right"), ("wall min/med", "right"),
                       ("CPU s", "right"), ("RSS MB", "right"), ("served", "right"),
                       ("wait mean/p90", "right"), ("veh km", "right")):
        table.add_column(name, justify=just, no_wrap=True)
    for sim, r in rows.items():
        med = statistics.median(r["walls"])
        table.add_row(LABEL[sim], _f(r["requests"] / med, 0),
                      f"{min(r['walls']):.1f}/{med:.1f}", _f(statistics.median(r["cpus"])),
                      _f(max(r["rss"]), 0), f"{r['served']:,}",
                      f"{_f(r['wait_mean'])}/{_f(r['wait_p90'])}", _f(r["vehicle_km"], 0))
    console.print(table)
    if "ours" not in rows or len(rows) < 2:
        return
    ours = rows["ours"]
    console.print("ratios ours / peer (req/s, req/CPU s: > 1 means ours is faster)")
    ratio = Table(pad_edge=False, box=None)
    for name in ("peer", "req/s", "req/CPU s", "served", "wait mean", "wait p90", "veh km"):
        ratio.add_column(name, justify="left" if name == "peer" else "right", no_wrap=True)
    for sim, r in rows.items():
        if sim == "ours":
            continue
        speed = statistics.median(r["walls"]) / statistics.median(ours["walls"])
        cpu = statistics.median(r["cpus"]) / statistics.median(ours["cpus"])
        ratio.add_row(LABEL[sim], f"{speed:.2f}x", f"{cpu:.2f}x",
                      f"{ours['served'] / max(r['served'], 1):.3f}",
                      f"{ours['wait_mean'] / r['wait_mean']:.3f}",
                      f"{ours['wait_p90'] / r['wait_p90']:.3f}",
                      f"{ours['vehicle_km'] / r['vehicle_km']:.3f}")
    console.print(ratio)


def explain_sumo(console, rows: dict[str, dict], t, folder: Path) -> None:
    """What separates SUMO's greedy waits from ours (same rule, same requests): the parts this
    run can measure, and the ones it can only bound."""
    import numpy as np

    gap = rows["sumo"]["wait_mean"] - rows["ours"]["wait_mean"]
    late = float(np.mean(np.ceil(t) - t))
    c = compare_pickups(folder / "ours.npz", folder / "sumo.npz")
    same, part = f"{c['same']:.0%}", f"{c['first_parted']:,}"
    med, mean = f"{c['diff_median']:.1f}", f"{c['diff_mean']:.1f}"
    leave, board = rows["sumo"]["lag_leave"], rows["sumo"]["lag_board"]
    lines = [
        f"SUMO - ours, mean wait: {gap:+.1f} s. Same rule (first come first served, nearest",
        f"idle taxi by travel time, ties to the lower id). The same taxi picks up {same}",
        f"of the requests in both (all before request {part}); on those SUMO waits {med} s",
        f"longer (median; mean {mean} s): a fixed cost per pick-up. SUMO adds to each wait:",
        f"  release -> the taxi leaves its stop: +{leave:.1f} s (measured; {late:.2f} s of it",
        "    the release seen at the next whole second, the rest dispatch and leave steps);",
        f"  arrival -> on board (boarding at the next step): +{board:.1f} s (measured);",
        "  the pick-up 5 m into the edge: +0.5 s; reaching it at a whole step: ~+0.5 s;",
    ]
    if "sumo-instant" in rows:
        inst = compare_pickups(folder / "ours.npz", folder / "sumo-instant.npz")["diff_median"]
        lines.append(f"  accelerating and braking: {c['diff_median'] - inst:+.1f} s (measured: "
                     f"with SUMO inst it is {inst:.1f} s).")
    else:
        lines.append("  accelerating to 10 m/s at 2.6 m/s^2 and braking at 4.5: about +3 s.")
    lines.append("Past that, timing shifts which taxi is idle first, and assignments part.")
    for line in lines:
        console.print(line)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--setup", action="store_true", help="create benchmarks/.peers-venv")
    ap.add_argument("--requests", type=int, default=100_000)
    ap.add_argument("--vehicles", type=int, default=1000)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--peer-requests", type=int, default=None,
                    help="run the peers (and ours beside them) on this prefix of the requests")
    ap.add_argument("--drain", type=float, default=1800.0,
                    help="seconds simulated after the last release")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="+", choices=SIMULATORS, default=list(SIMULATORS[:3]),
                    help="simulators to run (sumo-instant: SUMO with taxis that accelerate "
                    "and brake within a step, to measure what acceleration costs)")
    ap.add_argument("--work", type=Path, default=None, help="keep the files here")
    ap.add_argument("--no-full", action="store_true",
                    help="with --peer-requests: skip our run of the full workload")
    args = ap.parse_args(argv)
    if args.setup:
        setup()
        return
    from rich.console import Console

    console = Console(width=80, highlight=False)

    def log(line: str) -> None:  # progress shows up in a log file too (stdout is buffered there)
        console.print(line)
        sys.stdout.flush()

    peers = [s for s in args.only if s != "ours"]
    if peers and not peer_python().exists():
        sys.exit("peers: no peers environment: run `python benchmarks/peers.py --setup` first "
                 "(or --only ours)")
    if (args.requests < 1 or args.vehicles < 1 or args.repeats < 1 or not args.hours > 0
            or (args.peer_requests is not None and args.peer_requests < 1)
            or not args.drain >= 0):
        ap.error("--requests, --vehicles, --repeats, --peer-requests must be >= 1, --hours > 0 "
                 "and --drain >= 0")
    work = args.work or Path(tempfile.mkdtemp(prefix="peers-"))
    w, t, o, d, s = generate(args.requests, args.vehicles, args.hours, args.seed,
                             drain=args.drain)
    write(work / "full", w, t, o, d, s)
    k = args.peer_requests if args.peer_requests else args.requests
    scaled = peers and k < args.requests
    rate = w.requests / w.horizon
    console.print(f"workload: {w.columns} x {w.rows} grid, {w.block:g} m blocks, {w.speed:g} m/s; "
                  f"{w.vehicles:,} taxis (capacity 1);\n{w.requests:,} requests over "
                  f"{w.horizon / 3600:g} h ({rate:.3f}/s, {rate * 3600 / w.vehicles:.2f} per "
                  f"vehicle-hour); drain {args.drain:g} s;\nseed {args.seed}; "
                  f"{args.repeats} run(s) of each simulator, interleaved")
    if scaled:
        wp, tp, op, dp = prefix(w, t, o, d, k, args.drain)
        write(work / "prefix", wp, tp, op, dp, s)
        console.print(f"PEERS RUN A PREFIX: the first {wp.requests:,} requests "
                      f"({wp.horizon / 3600:.2f} h) with the same {wp.vehicles:,} taxis:\nthe "
                      "same rate per vehicle, a shorter day. Ours runs both.")
        console.print(f"[prefix: {wp.requests:,} requests, {wp.vehicles:,} taxis]")
        rows = run_all(args.only, work / "prefix", args.repeats, log)
        print_tables(console, f"prefix: {wp.requests:,} requests, {wp.vehicles:,} taxis, "
                     f"{wp.horizon / 3600:.2f} h", rows)
        if "ours" in args.only and not args.no_full:
            console.print(f"[full: {w.requests:,} requests, ours only]")
            full = run_all(["ours"], work / "full", args.repeats, log)
            print_tables(console, f"full: {w.requests:,} requests, {w.vehicles:,} taxis, "
                         f"{w.horizon / 3600:g} h (ours only)", full)
            f_rate = w.requests / statistics.median(full["ours"]["walls"])
            for sim in peers:
                p_rate = wp.requests / statistics.median(rows[sim]["walls"])
                console.print(f"ours on the FULL workload {f_rate:,.0f} req/s vs "
                              f"{LABEL[sim]} on the PREFIX {p_rate:,.1f} req/s: "
                              f"{f_rate / p_rate:.1f}x")
    else:
        rows = run_all(args.only, work / "full", args.repeats, log)
        print_tables(console, f"{w.requests:,} requests, {w.vehicles:,} taxis, "
                     f"{w.horizon / 3600:g} h", rows)
    if "ridepy" in rows:
        console.print("RidePy's rule differs: each request is queued at once on the taxi "
                      "whose route\ngrows least (busy taxis included): it drives less, riders "
                      "wait longer.")
    if "sumo" in rows and "ours" in rows:
        explain_sumo(console, rows, tp if scaled else t, work / ("prefix" if scaled else "full"))
    console.print(f"files: {work}")


if __name__ == "__main__":
    main()
