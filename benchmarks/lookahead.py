"""Look-ahead on the Chicago day (issue 22): batched ``hungarian`` against ``hungarian`` with the
learned value of where vehicles end up (:mod:`learning.value`), on seeds the training never saw.

Every series runs ``scenarios/chicago_taxi.toml`` batched every ``--batch-window`` seconds
(default 30) for each ``--agents`` N and ``--seeds`` S (the seed draws the day's requests and
places the fleet; the value's training days used seeds 100-102 by default: keep them out). Series
(``--series``, default ``hungarian`` and ``hungarian + value``):

* ``hungarian``: the myopic optimum of each batch;
* ``hungarian + demand``: the same with ``demand`` repositioning;
* ``hungarian + value``: ``hungarian`` with ``value = --value`` (a ``dispatch train value`` file);
* ``hungarian + value + demand``; ``hungarian + value(d) + demand``: with the value learned on
  days with ``demand`` repositioning (``--value-demand``, default the shipped
  ``chicago_n1000_demand.npz``);
* ``magnnet``: the shipped (imitation) model; ``magnnet + value`` (``+ value + demand``) with
  the learned value, as ``hungarian``'s;
* ``magnnet-day + value``: MAGNNET fine-tuned by PPO on the day (``--day-checkpoint``, default
  ``runs/train/magnnet_day/model.pt``, what ``dispatch train magnnet --variant day`` writes)
  with the value;
* ``magnnet @2km``, ``magnnet + value @2km``: the same under a 2 km radio range (compared with
  the same series at unlimited range when it ran).

It writes ``DIR/lookahead.csv`` (``series, n_agents, seed, served_share`` (0-1), ``wait_mean``
(s), ``rejected_share``, ``passenger_km`` (km driven with a passenger: the served trips'
length), ``empty_share`` (of the km), ``seconds``; appended run by run, so an interrupted
study keeps what it ran, and runs already in the file are skipped) and prints per series and N
the mean served share and mean wait with 95 % t-intervals over the seeds, and against
``hungarian`` (a ``+ demand`` series: against ``hungarian + demand`` when it ran) the paired
difference by seed (served points, wait in per cent) with its interval, and the mean
passenger-km.

``--demand-interval S`` and ``--demand-moves K`` change the ``demand`` repositioner of the
``+ demand`` series (how often it runs, how many vehicles it may send per call).

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/lookahead.py --seeds 0 1 2 3 4 --agents 500 1000
--series hungarian "hungarian + demand" "hungarian + value" "hungarian + value + demand" --out
runs/lookahead`` (about 20 s per day on the shared 2-core machine; ``--value`` defaults to the
shipped ``learning/data/values/chicago_n500.npz``). The table of the README and
``docs/lookahead/lookahead.csv`` come from that command.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from learning.value_train import scenario_for

SERIES = ("hungarian", "hungarian + demand", "hungarian + value", "hungarian + value + demand",
          "hungarian + value(d) + demand", "magnnet", "magnnet + value",
          "magnnet + value + demand", "magnnet + value(d) + demand", "magnnet @2km",
          "magnnet + value @2km", "magnnet-day + value")
#: series ending in ``@2km`` run under a 2 km radio range (decentralized: each agent decides
#: on what it hears; the value adjusts each agent's own costs)
RADIO_RANGE = 2000.0
#: the ``magnnet-day`` series' model: MAGNNET fine-tuned by PPO on the day, where
#: ``dispatch train magnnet --variant day`` writes it by default (no such model ships: the one
#: trained for issue 22 did not beat the imitation model, see the README)
DAY_CHECKPOINT = ROOT / "runs" / "train" / "magnnet_day" / "model.pt"
FIELDS = ["series", "n_agents", "seed", "served_share", "wait_mean", "rejected_share",
          "passenger_km", "empty_share", "seconds"]


def spec_of(series: str, sc, agents: int, seed: int, value: str | None, weight: float | None,
            value_demand: str | None = None, day_checkpoint: str | None = None):
    allocator = "magnnet" if series.startswith("magnnet") else "hungarian"
    params = {}
    if "value(d)" in series:
        value = value_demand
    if series.startswith("magnnet-day"):  # the PPO-for-the-day model (--day-checkpoint)
        params["checkpoint"] = str(DAY_CHECKPOINT if day_checkpoint is None else day_checkpoint)
    if "value" in series:
        if value is None:
            raise SystemExit(f"series {series!r} needs --value FILE (value(d): --value-demand)")
        params["value"] = str(value)
        if weight is not None:
            params["value_weight"] = weight
    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(params.items())))
    if "demand" in series:
        sc = replace(sc, reposition=replace(sc.reposition, policy="demand", declared=True))
    if series.endswith("@2km"):
        sc = replace(sc, comms=replace(sc.comms, range=RADIO_RANGE))
    return sc.runs(allocator=allocator, agents=agents, seed=seed)[0]


def run(series: str, sc, agents: int, seed: int, value, weight, value_demand=None,
        day_checkpoint=None) -> dict:
    from dispatch.run.runner import run_one

    t0 = time.perf_counter()
    s = run_one(spec_of(series, sc, agents, seed, value, weight, value_demand,
                        day_checkpoint)).summary
    n = max(1, s["n_tasks"])
    lost = s["tasks_rejected"] + s["tasks_expired"] + s.get("tasks_unreachable", 0)
    return {"series": series, "n_agents": agents, "seed": seed,
            "served_share": s["tasks_completed"] / n, "wait_mean": s["wait_time_mean"],
            "rejected_share": lost / n, "passenger_km": s["passenger_distance"] / 1000.0,
            "empty_share": s["empty_distance"] / max(s["distance"], 1e-9),
            "seconds": round(time.perf_counter() - t0, 1)}


def interval(x) -> tuple[float, float]:
    """Mean and the half-width of its 95 % t-interval (nan with one value)."""
    from scipy.stats import t

    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return float(x.mean()) if x.size else math.nan, math.nan
    return float(x.mean()), float(t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))


def table(rows: list[dict]) -> str:
    import pandas as pd

    df = pd.DataFrame(rows)
    w = max([27] + [len(x) + 1 for x in df["series"]])
    out = [(f"{'series':<{w}}{'N':>5} {'seeds':>5}  {'served %':>13}  {'wait s':>12}  "
            f"{'d served pts':>13}  {'d wait %':>11}  {'pass. km':>8}")]
    for n, g in df.groupby("n_agents"):
        for name in [s for s in SERIES if s in set(g["series"])]:
            ref = "hungarian + demand" if "demand" in name and name != "hungarian + demand" \
                and "hungarian + demand" in set(g["series"]) else "hungarian"
            if name.endswith("@2km") and name[:-5] in set(g["series"]):
                ref = name[:-5]  # under the range: against its unlimited-range self
            base = g[g["series"] == ref].set_index("seed")
            h = g[g["series"] == name].set_index("seed")
            sm, sh = interval(100 * h["served_share"])
            wm, wh = interval(h["wait_mean"])
            line = (f"{name:<{w}}{n:>5} {len(h):>5}  {sm:6.2f} ±{sh:5.2f}  {wm:5.1f} ±{wh:5.1f}")
            common = h.index.intersection(base.index)
            if name != ref and len(common):
                ds = 100 * (h.loc[common, "served_share"] - base.loc[common, "served_share"])
                dw = 100 * (h.loc[common, "wait_mean"] / base.loc[common, "wait_mean"] - 1)
                a, ah = interval(ds)
                b, bh = interval(dw)
                line += f"  {a:+6.2f} ±{ah:5.2f}  {b:+5.1f} ±{bh:4.1f}"
            else:
                line += " " * 28
            if "passenger_km" in h:
                line += f"  {h['passenger_km'].astype(float).mean():8.0f}"
            if name != ref and len(common):
                line += f"  (vs {ref})"
            out.append(line)
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--agents", type=int, nargs="+", default=[500])
    p.add_argument("--out", type=Path, default=ROOT / "runs" / "lookahead")
    p.add_argument("--series", nargs="+", default=["hungarian", "hungarian + value"],
                   choices=SERIES)
    p.add_argument("--value",
                   default=str(ROOT / "learning" / "data" / "values" / "chicago_n500.npz"),
                   help="a `dispatch train value` file (default: the shipped Chicago N = 500 one)")
    p.add_argument("--value-demand",
                   default=str(ROOT / "learning" / "data" / "values" / "chicago_n1000_demand.npz"),
                   help="the value of the value(d) series: learned on days with demand "
                        "repositioning (`dispatch train value --reposition demand`)")
    p.add_argument("--day-checkpoint", default=None,
                   help="the magnnet-day series' model (default: runs/train/magnnet_day/"
                        "model.pt, where `dispatch train magnnet --variant day` writes it)")
    p.add_argument("--value-weight", type=float, default=None,
                   help="seconds per unit of value (default: the file's)")
    p.add_argument("--batch-window", type=float, default=30.0)
    p.add_argument("--hours", type=float, default=None, help="shorter days (a quick look)")
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--demand-interval", type=float, default=None,
                   help="the + demand series: seconds between two repositioner calls "
                        "(default: the scenario's, 300 s)")
    p.add_argument("--demand-moves", type=int, default=None,
                   help="the + demand series: most vehicles sent per call (default 20); "
                        "runs with other demand settings belong in an --out of their own")
    a = p.parse_args(argv)
    sc = scenario_for(a.scenario, a.batch_window, a.hours)
    if a.demand_interval is not None:
        sc = replace(sc, reposition=replace(sc.reposition, interval=a.demand_interval))
    if a.demand_moves is not None:
        params = dict(sc.reposition.params)
        params["demand"] = tuple({**dict(params.get("demand", ())),
                                  "max_moves": a.demand_moves}.items())
        sc = replace(sc, reposition=replace(sc.reposition, params=tuple(params.items())))
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "lookahead.csv"
    rows: list[dict] = []
    if path.exists():
        with path.open() as f:
            rows = [{k: (v if k == "series" else float(v)) for k, v in r.items()}
                    for r in csv.DictReader(f)]
        for r in rows:
            r["n_agents"], r["seed"] = int(r["n_agents"]), int(r["seed"])
    done = {(r["series"], r["n_agents"], r["seed"]) for r in rows}
    new = not path.exists()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, FIELDS)
        if new:
            w.writeheader()
        for n in a.agents:
            for seed in a.seeds:
                for series in a.series:
                    if (series, n, seed) in done:
                        continue
                    r = run(series, sc, n, seed, a.value, a.value_weight, a.value_demand,
                            a.day_checkpoint)
                    w.writerow(r)
                    f.flush()
                    rows.append(r)
                    print(f"{series}, N = {n}, seed {seed}: served {100 * r['served_share']:.2f}"
                          f" %, wait {r['wait_mean']:.1f} s ({r['seconds']:.0f} s)",
                          file=sys.stderr, flush=True)
    wanted = [r for r in rows if r["series"] in a.series and r["n_agents"] in a.agents
              and r["seed"] in a.seeds]
    print(table(wanted))
    return 0


if __name__ == "__main__":
    sys.exit(main())
