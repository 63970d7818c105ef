"""Benchmark: what the ``demand`` repositioner buys against ``stay`` when demand has a hotspot.

The setup of ``scenarios/manhattan.toml`` (a 20 x 20 grid, 200 m blocks, 10 m/s; 2 h of
requests at 0.1/s; 80 taxis (``--agents``) on uniform random nodes; ``fcfs``; ``max_wait`` 600 s)
with a
demand imbalance: a share ``--hot`` of the pickups falls in a hotspot, the 5 x 5 intersections
of the lower-left corner (a 800 m square), the rest uniform; drop-offs uniform anywhere (so
taxis carry riders out of the hotspot and, staying where they drop them, leave it short of
supply). Each ``--seeds`` draws one trace and one fleet; every policy runs on the same ones.

Prints, per policy (per seed and the mean over the seeds): served share, rejected + expired,
wait mean and p90 (release to pickup, served trips), empty km (reposition km included),
reposition km and wall seconds per run; then the means side by side (with the median wait and
the drives started), the wall time as a ratio to ``stay``'s, measured in the same process.

Run: ``.venv/bin/python benchmarks/reposition.py [--seeds 3] [--hot 0.5] [--agents 80]``
(``--zone``, ``--interval``, ``--horizon``, ``--max-moves``: the demand policy's settings).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from dispatch.run.runner import run_one  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402

COLUMNS, ROWS, HOT = 20, 20, 5


def hotspot_trips(rng: np.random.Generator, hot: float, rate: float = 0.1,
                  hours: float = 2.0) -> list[tuple]:
    """Poisson requests; a share ``hot`` of pickups in the lower-left HOT x HOT corner."""
    n, rows, t = COLUMNS * ROWS, [], 0.0
    corner = np.array([r * COLUMNS + c for r in range(HOT) for c in range(HOT)])
    while True:
        t += rng.exponential(1.0 / rate)
        if t > hours * 3600:
            return rows
        o = int(rng.choice(corner)) if rng.random() < hot else int(rng.integers(n))
        d = int(rng.integers(n - 1))
        d += d >= o
        rows.append((round(t, 3), o, d))


def write_scenario(d: Path, seed: int, args, policy: str) -> Path:
    rng = np.random.default_rng(seed)
    trips = hotspot_trips(rng, args.hot)
    (d / "trips.csv").write_text("t,origin_node,dest_node\n"
                                 + "".join(f"{t},{o},{e}\n" for t, o, e in trips))
    fleet = rng.integers(COLUMNS * ROWS, size=args.agents)
    (d / "fleet.csv").write_text("vehicle_id,node\n"
                                 + "".join(f"{i},{n}\n" for i, n in enumerate(fleet)))
    path = d / f"{policy}.toml"
    # the policy's own parameters only where it takes them (`stay` takes none)
    params = (f"interval = {args.interval!r}\nhorizon = {args.horizon!r}\n[reposition.demand]\n"
              f"zone = {args.zone!r}\nmax_moves = {args.max_moves}\n"
              if policy == "demand" else "")
    path.write_text(f'''name = "hotspot_{seed}"
seed = {seed}
duration = 9000.0
[world]
network = "manhattan"
blocks = [{COLUMNS}, {ROWS}]
block = 200.0
speed = 10.0
[fleet]
start = "fleet.csv"
[tasks]
source = "trace"
trace = "trips.csv"
max_wait = 600.0
[dispatch]
allocator = "{args.allocator}"
[reposition]
policy = "{policy}"
{params}''')
    return path


def measure(path: Path) -> dict:
    [spec] = load_scenario(path).runs()
    t0 = time.perf_counter()
    r = run_one(spec)
    wall = time.perf_counter() - t0
    s = r.summary
    tasks = r.tables["tasks"].to_pandas()
    served = tasks[tasks.state == "completed"]
    wait = (served.picked_up_at - served.released_at).to_numpy()
    return {"served": len(served) / len(tasks), "lost": s["tasks_rejected"] + s["tasks_expired"],
            "wait": wait.mean(), "median": float(np.median(wait)),
            "p90": float(np.percentile(wait, 90)), "empty_km": s["empty_distance"] / 1000,
            "repo_km": s["reposition_distance"] / 1000, "moves": s["repositions"],
            "wall": wall}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--hot", type=float, default=0.5)
    p.add_argument("--agents", type=int, default=80)
    p.add_argument("--allocator", default="fcfs")
    p.add_argument("--zone", type=float, default=1000.0)
    p.add_argument("--interval", type=float, default=300.0)
    p.add_argument("--horizon", type=float, default=1800.0)
    p.add_argument("--max-moves", type=int, default=20)
    args = p.parse_args(argv)
    console = Console()
    results: dict[str, list[dict]] = {"stay": [], "demand": []}
    for seed in range(args.seeds):
        for policy, rs in results.items():
            with tempfile.TemporaryDirectory() as d:
                rs.append(measure(write_scenario(Path(d), seed, args, policy)))
    keys = ("served", "lost", "wait", "median", "p90", "empty_km", "repo_km", "moves", "wall")
    t = Table(title=f"Hotspot: {args.hot:.0%} of pickups in a 800 m corner; {args.agents} "
                    f"taxis, {args.allocator}; demand: {args.zone:g} m zones, every "
                    f"{args.interval:g} s, {args.horizon:g} s back, <= {args.max_moves} moves")
    for col in ("policy", "seed", "served", "lost", "wait s", "p90 s", "empty km", "repo km",
                "wall s"):
        t.add_column(col, justify="left" if col == "policy" else "right")

    def row(policy, label, r):
        t.add_row(policy, label, f"{100 * r['served']:.1f}%", f"{r['lost']:.0f}",
                  f"{r['wait']:.1f}", f"{r['p90']:.1f}", f"{r['empty_km']:.0f}",
                  f"{r['repo_km']:.0f}", f"{r['wall']:.2f}")

    means = {}
    for policy, rs in results.items():
        for seed, r in enumerate(rs):
            row(policy, str(seed), r)
        means[policy] = {k: float(np.mean([r[k] for r in rs])) for k in keys}
        row(policy, "mean", means[policy])
    console.print(t)
    st, de = means["stay"], means["demand"]
    console.print(f"demand vs stay (means): wait {de['wait']:.1f} s vs {st['wait']:.1f} s "
                  f"({100 * (de['wait'] / st['wait'] - 1):+.1f}%), median {de['median']:.1f} vs "
                  f"{st['median']:.1f} s, p90 {de['p90']:.1f} vs "
                  f"{st['p90']:.1f} s, served {100 * de['served']:.1f}% vs "
                  f"{100 * st['served']:.1f}%, empty km {de['empty_km']:.0f} vs "
                  f"{st['empty_km']:.0f} ({de['moves']:.0f} drives, {de['repo_km']:.0f} km "
                  f"repositioning); wall per run {de['wall']:.2f} s vs {st['wall']:.2f} s "
                  f"(ratio {de['wall'] / st['wall']:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
