"""Benchmark: shared rides, this project's insertion dispatch against RidePy's, same requests.

The workload is ``benchmarks/peers.py``'s (``benchmarks/peers_workload.py``: a seeded 20 x 20
Manhattan grid, 200 m blocks, 10 m/s, Poisson requests uniform over the intersections), with
``--capacity`` seats per vehicle and each request's limits: pickup by release + ``--max-wait``,
drop-off by release + direct free-flow time + ``--max-delay``. For each ``--vehicles`` size the
requests are ``--rate`` per vehicle-hour over ``--hours`` (the same load per vehicle), and the
run ends ``--drain`` seconds after the last release (default: enough for every accepted ride).

* **ours** (``benchmarks/peers_ours.py``): ``[fleet] capacity``, ``[tasks] max_wait`` and
  ``max_delay``, ``[dispatch] allocator = "hungarian"``, ``objective = "added_time"`` (a pair's
  cost is how much longer the vehicle's whole plan gets), no batch window (a decision at each
  release), planner ``dijkstra``. A request no vehicle can take within its limits is rejected
  at once. ``--batch-window S`` (S > 0) sets ``[dispatch] batch_window = S`` instead: a release
  opens a window of S seconds, then one decision assigns every request released meanwhile
  (``ours (batched S s)``); ``--batch-window 0 30`` runs both series on the same requests,
  interleaved with RidePy's, each compared with RidePy.
* **RidePy** (``benchmarks/peers_ridepy.py``): ``BruteForceTotalTravelTimeMinimizingDispatcher``
  (the request goes to the vehicle whose stoplist grows least in drive time), seat capacity
  ``--capacity``, ``pickup_timewindow_max`` and ``delivery_timewindow_max`` as above; it rejects
  a request no vehicle can insert. ``ridepy``: its continuous ``Manhattan2D`` space (a vehicle
  re-routed between stops turns where the straight line between them has got to, inside a
  block); ``ridepy-grid``: its ``Graph`` space on the same grid (a re-routed vehicle first
  reaches the next intersection, as ours does).

Without a batch window the rules are the same: one request at a time, cheapest feasible
insertion of its pickup and drop-off by added drive time, ties to the first vehicle and then the
first positions (ours: ``hungarian`` on a one-column matrix takes the first minimal row; between
positions of one vehicle the earlier pickup, which is the first position on a grid). With one
(``--batch-window S``, S > 0) they differ: ours waits up to S seconds and then assigns the whole
batch at once (at most one new request per vehicle and decision, by the assignment that serves
the most requests, then at the least total added time; a request no vehicle can take at its
first decision is rejected, one left over waits for the next decision and expires at its pickup
limit), whereas RidePy decides each request at its release. The service metrics of a batched
series are then those of another dispatch rule, not expected to match RidePy's decision for
decision, and its same-vehicle share below says nothing about agreement.

Each simulator runs in its own process, ``--repeats`` times, interleaved. Printed per size,
side by side: requests per wall and per CPU second, the service metrics (served share,
rejected, expired (batched series only: left over past the pickup limit), mean and p90 wait,
mean detour = in-vehicle time / direct time, mean delay = drop-off - release - direct time,
vehicle km actually driven, occupancy = passenger-km / vehicle-km, share of served rides
shared) and the ratios of each series of ours / each RidePy run; then how many requests each
pair of runs gave to the same vehicle.

Why the runs part (measured with ``--jitter 0.05``: unique shortest paths, ``ours`` against
``ridepy-grid``, four seeds, capacity 2 to 4, tight and loose limits): every decision is the
same (vehicle, planned pickup and drop-off times) up to the first tie, and one run (capacity 2,
276 of 1,000 requests rejected) is the same throughout. The ties are exact in arithmetic and
common on a grid, where a new stop often lies on a path the vehicle drives anyway: two vehicles
of equal added time (ours computes it from clock times, the plan's end after minus before, so
equal ones come out a few ulp apart and ``hungarian`` takes the smaller, not the first vehicle;
RidePy sums drive times and takes the first vehicle unless the other is smaller in its
rounding: at 1,000 vehicles the runs part at the fifth request this way), or two positions of equal cost (ours takes the earlier pickup, comparing
pickup times without a tolerance, so a pickup 1 ulp earlier at a later position wins; RidePy
the first position unless a later one is smaller in its rounding). After a tie the runs are
different simulations of the same rule, so their means differ by chance (a few per cent at a
few thousand requests). On the plain grid the two simulators also pick different ones of the
many equally short grid paths (where a re-routed vehicle is then differs), and RidePy's
``Manhattan2D`` lets a re-routed vehicle turn inside a block. ``shared`` can differ on the
same decisions: a drop-off and a pickup at the same node and time count as shared in the order
pickup first (RidePy's choice on such a tie), not in the order drop-off first.

Run: ``.venv/bin/python benchmarks/pooling.py [--vehicles 200 1000] [--rate 30] [--hours 1]
[--capacity 4] [--max-wait 300] [--max-delay 600] [--batch-window 0 [30 ...]] [--repeats 3]
[--only ours ridepy ridepy-grid]`` (the peers' environment first: ``python benchmarks/peers.py
--setup``).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from peers import peer_python, run_all
from peers_workload import generate, write

SIMULATORS = ("ours", "ridepy", "ridepy-grid")
LABEL = {"ours": "ours", "ridepy": "RidePy", "ridepy-grid": "RidePy grid"}
#: the project's runner: allocator, objective
OURS = ("hungarian", "added_time")


def ours_series(windows: list[float]) -> dict[str, tuple[str, ...]]:
    """Our runs, one per batch window, by name (``ours`` for 0: no window, ``ours-S`` for S
    seconds), each with the runner's arguments (``peers_ours.py``: allocator, objective,
    window)."""
    series = {}
    for s in dict.fromkeys(windows):  # each window once, in the order given
        series["ours" if s == 0 else f"ours-{s:g}"] = OURS + ((f"{s!r}",) if s > 0 else ())
    return series


def label_of(sim: str) -> str:
    """The printed name of a run: ``ours (batched 30 s)`` for ``ours-30``."""
    if sim.startswith("ours-"):
        return f"ours (batched {sim[len('ours-'):]} s)"
    return LABEL[sim]


def _f(x: float, nd: int = 1) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:,.{nd}f}"


def _header(sim: str) -> str:
    return label_of(sim).replace(" (", "\n(")  # "ours\n(batched 30 s)": narrow columns


def print_table(console, title: str, rows: dict[str, dict]) -> None:
    """Metrics down, simulators across, then each of our series / each RidePy run: in the same
    table for one series of ours, in a second table for several (80 columns)."""
    from rich.table import Table

    sims = list(rows)
    ours = [s for s in sims if s == "ours" or s.startswith("ours-")]
    pairs = [(o, p) for o in ours for p in sims if p not in ours]

    def new_table(title_: str | None) -> Table:
        t = Table(title=title_, title_justify="left", pad_edge=False, box=None)
        t.add_column("", no_wrap=True)
        return t

    table = new_table(title)
    for s in sims:
        table.add_column(_header(s), justify="right", no_wrap=True)
    ratios = table if len(ours) == 1 else new_table(f"{title}: ratios ours / RidePy")
    for o, p in pairs:
        head = f"ours/{LABEL[p]}" if len(ours) == 1 else f"{_header(o)}\n/ {LABEL[p]}"
        ratios.add_column(head, justify="right", no_wrap=True)

    def med(r, key):
        return statistics.median(r[key])

    lines = [  # (name, value of a row, digits, ratio: "speed" (peer / ours), "value" or None)
        ("requests / wall s", lambda r: r["requests"] / med(r, "walls"), 0, "speed"),
        ("requests / CPU s", lambda r: r["requests"] / med(r, "cpus"), 0, "speed"),
        ("wall s min", lambda r: min(r["walls"]), 2, None),
        ("wall s median", lambda r: med(r, "walls"), 2, None),
        ("CPU s median", lambda r: med(r, "cpus"), 2, None),
        ("peak RSS MB", lambda r: max(r["rss"]), 0, None),
        ("served %", lambda r: 100 * r["served_share"], 2, "value"),
        ("rejected", lambda r: r["rejected"], 0, "value"),
        ("expired", lambda r: r.get("expired", 0), 0, "value"),
        ("wait mean s", lambda r: r["wait_mean"], 1, "value"),
        ("wait p90 s", lambda r: r["wait_p90"], 1, "value"),
        ("detour mean", lambda r: r["detour_mean"], 3, "value"),
        ("delay mean s", lambda r: r["delay_mean"], 1, "value"),
        ("vehicle km", lambda r: r["vehicle_km"], 0, "value"),
        ("occupancy", lambda r: r["occupancy"], 3, "value"),
        ("shared %", lambda r: 100 * r["shared_rate"], 1, "value"),
    ]
    for name, get, nd, ratio in lines:
        cells = [_f(float(get(rows[s])), nd) for s in sims]
        quotients = []
        for o, p in pairs:
            a, b = float(get(rows[o])), float(get(rows[p]))
            if ratio == "speed":
                quotients.append(f"{a / b:.2f}x" if b else "-")
            elif ratio == "value":
                quotients.append(f"{a / b:.3f}" if b else ("1" if a == b else "-"))
            else:
                quotients.append("")
        if ratios is table:
            table.add_row(name, *cells, *quotients)
        else:
            table.add_row(name, *cells)
            if ratio is not None:
                ratios.add_row(name, *quotients)
    console.print(table)
    if ratios is not table and pairs:
        console.print(ratios)


def print_same_vehicle(console, folder: Path, sims: list[str]) -> None:
    """For each pair of runs: the share of requests that went to the same vehicle in both
    (or were served by neither), and the first request where they part."""
    import numpy as np

    for k, a in enumerate(sims):
        for b in sims[k + 1:]:
            x, y = np.load(folder / f"{a}.npz"), np.load(folder / f"{b}.npz")
            same = x["vehicle"] == y["vehicle"]
            parted = np.flatnonzero(~same)
            first = f"request {parted[0]:,}" if parted.size else "none"
            console.print(f"same vehicle {label_of(a)} / {label_of(b)}: {same.mean():.1%} of the "
                          f"requests; first parted: {first}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, nargs="+", default=[200, 1000])
    ap.add_argument("--grid", type=int, nargs=2, default=[20, 20], metavar=("COLUMNS", "ROWS"),
                    help="intersections (a 1-row grid is a line: shortest paths are unique "
                         "there, so the runs should agree request by request)")
    ap.add_argument("--jitter", type=float, default=0.0,
                    help="each street block x (1 + jitter x uniform(-1, 1)) long: unique "
                         "shortest paths, so ours and RidePy grid should agree request by "
                         "request (RidePy's Manhattan2D is left out)")
    ap.add_argument("--rate", type=float, default=30.0, help="requests per vehicle-hour")
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--capacity", type=int, default=4)
    ap.add_argument("--max-wait", type=float, default=300.0, help="seconds")
    ap.add_argument("--max-delay", type=float, default=600.0, help="seconds")
    ap.add_argument("--drain", type=float, default=None,
                    help="seconds simulated after the last release (default: the longest "
                         "direct ride + max delay + 60)")
    ap.add_argument("--batch-window", type=float, nargs="+", default=[0.0], metavar="S",
                    help="ours decides every S seconds ([dispatch] batch_window; 0: at each "
                         "release, RidePy's rule); several values: one series of ours each")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="+", choices=SIMULATORS, default=list(SIMULATORS))
    ap.add_argument("--work", type=Path, default=None, help="keep the files here")
    args = ap.parse_args(argv)
    if (min(args.vehicles) < 1 or args.repeats < 1 or args.capacity < 1 or min(args.grid) < 1
            or max(args.grid) < 2
            or not (args.rate > 0 and args.hours > 0 and args.max_wait >= 0
                    and args.max_delay >= 0 and min(args.batch_window) >= 0
                    and math.isfinite(max(args.batch_window)))
            or (args.drain is not None and args.drain < 0)):
        ap.error("--vehicles, --repeats, --capacity must be >= 1, --rate and --hours > 0, "
                 "--max-wait, --max-delay, --batch-window and --drain >= 0")
    from rich.console import Console

    console = Console(width=80, highlight=False)

    def log(line: str) -> None:  # progress shows up in a log file too (stdout is buffered there)
        console.print(line)
        sys.stdout.flush()

    if any(s != "ours" for s in args.only) and not peer_python().exists():
        sys.exit("pooling: no peers environment: run `python benchmarks/peers.py --setup` "
                 "first (or --only ours)")
    if not 0 <= args.jitter < 1:
        ap.error("--jitter must be in [0, 1)")
    if args.jitter and "ridepy" in args.only:
        args.only.remove("ridepy")  # Manhattan2D has no street lengths
    work = args.work or Path(tempfile.mkdtemp(prefix="pooling-"))
    ours = ours_series(args.batch_window)
    # "ours" in --only: every series of ours, where "ours" stood
    sims = [x for s in args.only for x in (ours if s == "ours" else [s])]
    labels = {s: label_of(s) for s in sims}
    windows = ", ".join("no batch window" if s == "ours" else f"batch window {s[5:]} s"
                        for s in ours)
    for n in args.vehicles:
        requests = max(1, round(args.rate * n * args.hours))
        columns, rows_ = args.grid
        probe = generate(1, 1, 1.0, 0, columns=columns, rows=rows_)[0]
        longest = (probe.columns + probe.rows - 2) * probe.block * (1 + args.jitter) / probe.speed
        drain = args.drain if args.drain is not None else longest + args.max_delay + 60.0
        w, t, o, d, s = generate(requests, n, args.hours, args.seed, drain=drain,
                                 columns=columns, rows=rows_, capacity=args.capacity, max_wait=args.max_wait,
                                 max_delay=args.max_delay, jitter=args.jitter)
        folder = work / f"v{n}"
        write(folder, w, t, o, d, s)
        console.print(
            f"workload: {w.columns} x {w.rows} grid, {w.block:g} m blocks, {w.speed:g} m/s; "
            f"{n:,} vehicles of {w.capacity} seats;\n{w.requests:,} requests over "
            f"{w.horizon / 3600:g} h ({args.rate:g} per vehicle-hour); "
            f"{'streets jittered by ' + format(w.jitter, 'g') + '; ' if w.jitter else ''}max wait "
            f"{w.max_wait:g} s, max delay {w.max_delay:g} s;\ndrain {drain:g} s; seed "
            f"{args.seed}; {args.repeats} run(s) of each, interleaved; ours: "
            f"{OURS[0]}, {OURS[1]}, {windows}")
        rows = run_all(sims, folder, args.repeats, log, ours=ours, label=labels)
        print_table(console, f"{n:,} vehicles x {w.capacity} seats, {w.requests:,} requests",
                    rows)
        for sim, r in rows.items():
            left = r["requests"] - r["served"] - r["rejected"] - r.get("expired", 0)
            if left:
                console.print(f"note: {labels[sim]}: {left} request(s) neither served, rejected "
                              "nor expired by the end")
        if len(rows) > 1:
            print_same_vehicle(console, folder, list(rows))
        if "ridepy" in rows:
            console.print(f"RidePy (Manhattan2D) by its own stop-to-stop definition: "
                          f"{rows['ridepy']['stop_km']:,.0f} vehicle km (misses re-routing "
                          "turns)")
    console.print(f"files: {work}")


if __name__ == "__main__":
    main()
