"""The view model on held-out taxi decisions (issue 22): gap to the optimal assignment under a
radio range, shipped ``view.pt`` against the taxi-trained ``view_taxi.pt``.

Decisions are recorded from runs of ``scenarios/chicago_taxi.toml`` (batched 30 s) driven by
the optimal assignment, under ``--range`` metres (default 2000), every ``--every``-th decision
of the night (0.5-4 h) and of the morning (7-10 h) windows, for each ``--agents`` N and
``--seeds`` S (held out: the trainer's days are 100 on, its validation day 110). Each series
decides every recorded decision:

* ``magnnet view.pt``: ``magnnet`` with ``view_weights = "view"`` (the shipped view model on
  every partial view, what ``magnnet`` ran before ``view_taxi.pt``);
* ``magnnet view_taxi``: ``magnnet`` as it ships (``view_weights = "auto"``: ``view_taxi.pt``
  on taxi-scale views; ``--taxi-checkpoint`` replaces it);
* ``auction``, ``local_hungarian``: the other decentralized allocators.

Per decision: its cost and the optimum's, the gap ``(cost - optimal) / optimal`` where the
allocator assigned as many pairs as the optimum and the optimum is not 0 s (else none), its
pairs and its rounds. Written to ``DIR/view_taxi.csv`` (``--append``: added to the rows there);
printed per series, N and window over the decisions every series completed: the excess cost
(their summed cost over the optimum's, less 1) and the mean gap; then the share of decisions
it completed, its pairs against the optimum's and its mean rounds.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/view_taxi.py --seeds 0 1 2 --agents 500 1000
--out runs/view_taxi`` (a few minutes on the 2 cores). ``docs/view_taxi/`` holds its output.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SERIES = ("magnnet view.pt", "magnnet view_taxi", "auction", "local_hungarian")
FIELDS = ["series", "n_agents", "seed", "window", "decision", "n_idle", "n_requests", "gap",
          "cost", "optimal_cost", "pairs", "optimal_pairs", "rounds"]


def allocator(series: str, taxi_checkpoint: str | None):
    from allocators.auction import AuctionAllocator
    from allocators.local_hungarian import LocalHungarianAllocator
    from allocators.magnnet.allocator import MagnnetAllocator

    if series == "magnnet view.pt":
        return MagnnetAllocator(view_weights="view")
    if series == "magnnet view_taxi":
        return MagnnetAllocator(taxi_view_checkpoint=taxi_checkpoint)
    return {"auction": AuctionAllocator, "local_hungarian": LocalHungarianAllocator}[series]()


def main(argv=None) -> int:
    from allocators.magnnet.view_taxi import DAY, NIGHT, decision_gaps

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--agents", type=int, nargs="+", default=[500, 1000])
    p.add_argument("--series", nargs="+", default=list(SERIES), choices=SERIES)
    p.add_argument("--every", type=int, default=30)
    p.add_argument("--range", type=float, default=2000.0)
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--taxi-checkpoint", default=None)
    p.add_argument("--out", type=Path, default=Path("runs") / "view_taxi")
    p.add_argument("--append", action="store_true",
                   help="add to DIR/view_taxi.csv (other series) instead of replacing it")
    p.add_argument("--cache", type=Path, default=None,
                   help="keep the recorded decisions here (pickles) and reuse them")
    a = p.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    f = a.out / "view_taxi.csv"
    if a.append and f.exists():
        with f.open() as fh:
            rows = [r for r in csv.DictReader(fh) if r["series"] not in a.series]
    allocs = {s: allocator(s, a.taxi_checkpoint) for s in a.series}
    for n in a.agents:
        for seed in a.seeds:
            for name, w in (("night", NIGHT), ("day", DAY)):
                probs = decisions(a, n, seed, name, w)
                for s in a.series:
                    r = decision_gaps(allocs[s], probs)
                    for k, (pr, g) in enumerate(zip(probs, r["gaps"])):
                        rows.append({"series": s, "n_agents": n, "seed": seed, "window": name,
                                     "decision": k, "n_idle": pr.cost.shape[0],
                                     "n_requests": pr.cost.shape[1], "gap": g,
                                     "cost": r["per_cost"][k],
                                     "optimal_cost": r["per_optimal_cost"][k],
                                     "pairs": r["per_pairs"][k],
                                     "optimal_pairs": r["per_optimal"][k],
                                     "rounds": r["per_rounds"][k]})
                print(f"N={n} seed {seed} {name}: {len(probs)} decisions", file=sys.stderr,
                      flush=True)
    with f.open("w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows(rows)
    print(table(rows))
    return 0


def decisions(a, n: int, seed: int, name: str, window) -> list:
    """The recorded decisions of one run and window (from ``--cache`` when there)."""
    import pickle

    from allocators.magnnet.view_taxi import taxi_decisions

    f = None
    if a.cache is not None:
        f = a.cache / f"n{n}_s{seed}_{name}_e{a.every}_r{a.range:g}.pkl"
        if f.exists():
            return pickle.loads(f.read_bytes())
    probs = taxi_decisions(a.scenario, n, seed, (window,), a.every, a.range)
    if f is not None:
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(pickle.dumps(probs))
    return probs


def table(rows) -> str:
    """Per N and window: per series the mean gap over the decisions every series completed,
    the share it completed, its pairs against the optimum and its mean rounds."""
    import pandas as pd

    df = pd.DataFrame(rows)
    for c in FIELDS[1:]:
        if c not in ("window",):
            df[c] = pd.to_numeric(df[c], errors="coerce")  # "nan" read back from the csv
    df["full"] = df["pairs"] == df["optimal_pairs"]
    out = ["| N | window | series | decisions | excess cost | mean gap | complete | pairs | "
           "rounds |", "|---:|---|---|---:|---:|---:|---:|---:|---:|"]
    for (n, win), g in df.groupby(["n_agents", "window"], sort=True):
        key = ["seed", "decision"]
        ok = g.groupby(key)["full"].all()
        common = set(ok[ok].index)
        for s in [x for x in SERIES if x in set(g["series"])]:
            h = g[g["series"] == s]
            both = h[[k in common for k in zip(h["seed"], h["decision"])]]
            excess = both["cost"].sum() / both["optimal_cost"].sum() - 1
            out.append(f"| {n} | {win} | {s} | {len(h)} | {100 * excess:.1f} % ({len(both)}) | "
                       f"{100 * both['gap'].mean():.1f} % | {100 * h['full'].mean():.0f} % | "
                       f"{100 * h['pairs'].sum() / max(1, h['optimal_pairs'].sum()):.1f} % | "
                       f"{h['rounds'].mean():.1f} |")
    return "\n".join(out)


if __name__ == "__main__":
    raise SystemExit(main())
