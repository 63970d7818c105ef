"""Held-out days of a learned value of the post-decision state against the best myopic rule.

Each ``--series`` is ``ALLOCATOR[/OBJECTIVE][+demand][+value=FILE[@WEIGHT]]`` (e.g.
``hungarian/added_time+demand`` or ``hungarian/added_time+demand+value=v.npz@100``;
``+reward=R`` gives the allocator the ``value_reward`` R (seconds a served request is worth),
``+dvalue=FILE`` gives the value to the ``demand`` repositioner, ``+dmix=0.3`` its mix,
``+d.max_moves=100`` / ``+d.zone=1500`` its other keys, ``+every=60`` / ``+horizon=900`` the
``[reposition]`` interval and horizon in seconds, ``+wait`` the ``[dispatch] out_of_reach =
"wait"``: a request no taxi reaches in time at its first offer waits for its deadline),
run on ``--scenario`` for each ``--agents`` N and ``--seeds`` S, batched every
``--batch-window`` seconds; keep the value's training seeds (its file's ``seeds``) out.
Writes ``--out`` (CSV: ``series, n_agents, seed, served_share, wait_mean, passenger_km,
vehicle_km, delay_mean``; the served riders' mean delay: drop-off time less release and direct
drive; appended run by run, runs already there skipped) and prints per series and N the
mean served share and wait with 95 % t-intervals over the seeds and, against the first series,
the paired difference by seed.

Run (the measurement of docs/explanation/learning.md's look-ahead section):
``PYTHONPATH=. python benchmarks/lookahead_value.py --seeds 0 1 2 --agents 500 --series
hungarian/added_time+demand "hungarian/added_time+demand+value=FILE" --out runs/lv.csv``.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from learning.value_train import scenario_for  # noqa: E402

FIELDS = ("series", "n_agents", "seed", "served_share", "wait_mean", "passenger_km",
          "vehicle_km", "delay_mean")


def parse(series: str) -> dict:
    """The parts of a series name (see the module doc)."""
    head, *extras = series.split("+")
    allocator, _, objective = head.partition("/")
    out = {"allocator": allocator, "objective": objective or None, "demand": False,
           "params": {}, "demand_params": {}}
    for e in extras:
        key, _, val = e.partition("=")
        if key == "demand":
            out["demand"] = True
        elif key == "wait":
            out["out_of_reach"] = "wait"
        elif key == "value":
            path, _, w = val.partition("@")
            out["params"]["value"] = path
            if w:
                out["params"]["value_weight"] = float(w)
        elif key == "reward":
            out["params"]["value_reward"] = float(val)
        elif key == "dvalue":
            out["demand_params"]["value"] = val
        elif key == "dmix":
            out["demand_params"]["value_mix"] = float(val)
        elif key.startswith("d.") and key[2:] in ("zone", "max_moves"):
            out["demand_params"][key[2:]] = int(val) if key == "d.max_moves" else float(val)
        elif key in ("every", "horizon"):
            out["reposition_" + key] = float(val)
        else:
            raise SystemExit(f"unknown series part {e!r} in {series!r}")
    return out


def run(sc, spec: dict, agents: int, seed: int) -> dict:
    """One day of a series: its served share, mean wait and kilometres."""
    from dispatch.run.runner import run_one

    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(spec["params"].items()),
                                      allocator_tables=()))
    if spec["objective"]:
        sc = replace(sc, dispatch=replace(sc.dispatch, objective=spec["objective"]))
    if "out_of_reach" in spec:
        sc = replace(sc, dispatch=replace(sc.dispatch, out_of_reach=spec["out_of_reach"]))
    if spec["demand"]:
        sc = replace(sc, reposition=replace(
            sc.reposition, policy="demand", declared=True,
            interval=spec.get("reposition_every", sc.reposition.interval),
            horizon=spec.get("reposition_horizon", sc.reposition.horizon),
            params=(("demand", tuple(sorted(spec["demand_params"].items()))),)))
    res = run_one(sc.runs(allocator=spec["allocator"], agents=agents, seed=seed)[0])
    s = res.summary
    tasks = res.tables["tasks"].to_pandas()
    done = tasks[tasks["state"] == "completed"]
    pkm = float(np.hypot(done["dropoff_x"] - done["x"], done["dropoff_y"] - done["y"]).sum()
                / 1000.0)
    veh = res.tables["vehicles"].to_pandas()
    vkm = float(veh["distance"].sum() / 1000.0) if "distance" in veh else float("nan")
    return {"served_share": s["tasks_completed"] / max(1, s["n_tasks"]),
            "wait_mean": s.get("wait_time_mean"), "passenger_km": round(pkm, 1),
            "vehicle_km": round(vkm, 1), "delay_mean": s.get("delay_mean")}


def interval(x) -> tuple[float, float]:
    """Mean and 95 % t half-width."""
    from scipy import stats

    x = np.asarray(x, float)
    if len(x) < 2:
        return float(x.mean()), float("nan")
    return float(x.mean()), float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1)
                                  / math.sqrt(len(x)))


def table(rows: list[dict], series: list[str], agents: list[int], seeds: list[int]) -> str:
    """A Markdown table of the runs ``rows`` (as the CSV holds them): per N and series the mean
    and 95 % t half-width over ``seeds`` of served share, mean wait, vehicle-km and
    passenger-km, and the served share's paired difference from the first series."""
    out = [("| N | series | served % | wait s | delay s | vehicle-km | passenger-km | "
            "served vs first, pts |"), "|---|---|---|---|---|---|---|---|"]
    base = series[0]
    for n in agents:
        by = {(r["series"], int(r["seed"])): r for r in rows if int(r["n_agents"]) == n}
        for name in series:
            got = [s for s in seeds if (name, s) in by]
            if not got:
                continue

            def cell(key, scale=1.0, fmt=".1f", got=got, name=name, by=by):
                x = [scale * float(by[(name, s)].get(key) or "nan") for s in got]
                if any(math.isnan(v) for v in x):  # (a run that did not record it)
                    return "–"
                m, h = interval(x)
                return f"{m:{fmt}} ± {h:{fmt}}"

            paired = [s for s in got if (base, s) in by]
            diff = "" if name == base or not paired else "{:+.2f} ± {:.2f}".format(*interval(
                [100 * (float(by[(name, s)]["served_share"])
                        - float(by[(base, s)]["served_share"])) for s in paired]))
            out.append(f"| {n} | `{name}` | {cell('served_share', 100.0, '.2f')} | "
                       f"{cell('wait_mean')} | {cell('delay_mean')} | "
                       f"{cell('vehicle_km', fmt='.0f')} | "
                       f"{cell('passenger_km', fmt='.0f')} | {diff} |")
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--series", nargs="+", required=True)
    p.add_argument("--agents", type=int, nargs="+", default=[500])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--batch-window", type=float, default=30.0)
    p.add_argument("--hours", type=float, default=None)
    p.add_argument("--half", choices=("a", "b"), default=None,
                   help="only this half of the scenario's trace (learning.value_train.trace_half)")
    p.add_argument("--capacity", type=int, default=None)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--table", action="store_true",
                   help="only print the Markdown table of --out's runs (no new run)")
    a = p.parse_args(argv)
    if a.table:
        with a.out.open() as f:
            print(table(list(csv.DictReader(f)), a.series, a.agents, a.seeds))
        return 0
    sc = scenario_for(a.scenario, a.batch_window, a.hours, capacity=a.capacity, half=a.half)
    rows = []
    if a.out.exists():
        with a.out.open() as f:
            reader = csv.DictReader(f)
            rows = list(reader)
        if tuple(reader.fieldnames or ()) != FIELDS:
            raise SystemExit(f"{a.out} has the columns of another version of this benchmark "
                             f"({', '.join(reader.fieldnames or ())}); write to another --out")
    have = {(r["series"], int(r["n_agents"]), int(r["seed"])) for r in rows}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    for n in a.agents:
        for seed in a.seeds:
            for name in a.series:
                if (name, n, seed) in have:
                    continue
                got = {"series": name, "n_agents": n, "seed": seed,
                       **run(sc, parse(name), n, seed)}
                print(f"{name} N={n} seed {seed}: served {100 * got['served_share']:.2f} %, "
                      f"wait {got['wait_mean']:.1f} s", flush=True)
                new = not a.out.exists()
                with a.out.open("a", newline="") as f:
                    w = csv.DictWriter(f, FIELDS)
                    if new:
                        w.writeheader()
                    w.writerow(got)
                rows.append({k: str(v) for k, v in got.items()})
    base = a.series[0]
    for n in a.agents:
        by = {(r["series"], int(r["seed"])): r for r in rows if int(r["n_agents"]) == n}
        for name in a.series:
            seeds = [s for s in a.seeds if (name, s) in by and (base, s) in by]
            if not seeds:
                continue
            served = [100 * float(by[(name, s)]["served_share"]) for s in seeds]
            wait = [float(by[(name, s)]["wait_mean"]) for s in seeds]
            m, h = interval(served)
            mw, hw = interval(wait)
            line = f"N={n} {name}: served {m:.2f} ± {h:.2f} %, wait {mw:.1f} ± {hw:.1f} s"
            if name != base:
                def change(key, name=name, by=by, seeds=seeds):  # % against the first series
                    return [100 * (float(by[(name, s)].get(key) or "nan")
                                   / float(by[(base, s)].get(key) or "nan") - 1) for s in seeds]

                d = [x - 100 * float(by[(base, s)]["served_share"]) for x, s in zip(served, seeds)]
                dm, dh = interval(d)
                wm, wh = interval(change("wait_mean"))
                line += f"; vs {base}: {dm:+.2f} ± {dh:.2f} pts, wait {wm:+.1f} ± {wh:.1f} %"
                dl = change("delay_mean")
                if not any(math.isnan(x) for x in dl):
                    line += ", delay {:+.1f} ± {:.1f} %".format(*interval(dl))
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
