"""The electric-fleet study of issue 21 on ``scenarios/nyc_manhattan_ev.toml`` (the Manhattan
day, HIVE's 1,200 leaf_50 cars, HIVE's 15 DCFC stations):

1. served share and mean wait of the same fleet without energy limits (``[fleet.energy]``
   removed) and with each charging strategy (``threshold``, ``idle``, ``valley``; HIVE's 20
   plugs per station);
2. the smallest number of DCFC plugs per station (15 stations) at which the served share of
   ``threshold`` charging drops by less than 1 point against the fleet without energy limits.

``--soc0 X`` starts every car at X instead of HIVE's 0.8 (a harder day). Each run writes its
tables under ``OUT/<variant>/`` (``dispatch report`` reads them); the table is printed as
Markdown and written to ``OUT/study.csv``.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/ev_study.py [--out runs/ev_study]
[--plugs 1,2,3,5,10,20] [--soc0 X] [--agents N]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.run.runner import run_one  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402


def variant(sc, name: str, *, energy=True, strategy="threshold", plugs=None, soc0=None):
    if not energy:
        return replace(sc, name=f"{sc.name}_{name}", fleet=replace(sc.fleet, energy=None),
                       charging=None)
    fleet = sc.fleet
    if soc0 is not None:
        fleet = replace(fleet, energy=replace(fleet.energy, soc0=soc0, socs=()))
    ch = replace(sc.charging, strategy=strategy)
    if plugs is not None:
        ch = replace(ch, stations=tuple(replace(s, plugs=plugs) for s in ch.stations))
    return replace(sc, name=f"{sc.name}_{name}", fleet=fleet, charging=ch)


def run(sc, out: Path, agents: int | None) -> dict:
    [spec] = sc.runs(agents=agents)
    t0 = time.perf_counter()
    s = run_one(spec, out).summary
    n = s["n_tasks"]
    row = {"variant": sc.name.split("_ev_", 1)[-1], "served_%": 100 * s["tasks_completed"] / n,
           "wait_mean_s": s["wait_time_mean"], "requests": n, "wall_s": time.perf_counter() - t0}
    print(f"  {row['variant']:<22} served {row['served_%']:6.2f} %  wait "
          f"{row['wait_mean_s']:6.1f} s  ({row['wall_s']:.0f} s)", flush=True)
    return row


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--scenario", default=str(ROOT / "scenarios/nyc_manhattan_ev.toml"))
    p.add_argument("--out", default="runs/ev_study")
    p.add_argument("--plugs", default="1,2,3,5,10,20")
    p.add_argument("--soc0", type=float, default=None)
    p.add_argument("--agents", type=int, default=None)
    p.add_argument("--strategies", default="threshold,idle,valley")
    a = p.parse_args()
    import pandas as pd

    sc = load_scenario(a.scenario)
    out = Path(a.out)
    rows = [run(variant(sc, "no_energy", energy=False), out / "no_energy", a.agents)]
    base = rows[0]["served_%"]
    for st in a.strategies.split(","):
        rows.append(run(variant(sc, st, strategy=st, soc0=a.soc0), out / st, a.agents))
    enough = None
    for k in sorted({int(x) for x in a.plugs.split(",") if x}):
        r = run(variant(sc, f"threshold_plugs{k}", plugs=k, soc0=a.soc0), out / f"plugs{k}",
                a.agents)
        r["plugs_total"] = 15 * k
        rows.append(r)
        if enough is None and base - r["served_%"] < 1.0:
            enough = k
    df = pd.DataFrame(rows)
    df["drop_points"] = base - df["served_%"]
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "study.csv", index=False)
    print(df.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    print(f"smallest DCFC plugs per station with a drop < 1 point: {enough}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
