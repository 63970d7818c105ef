"""Learning a value of a vehicle's post-decision state from simulated days (``dispatch train
value``): the trainer of :class:`learning.value.ZoneValue`.

Each vehicle's day is a chain of transitions between states ``(zone, time[, free seats])``.
Single seat (``--capacity 1``, the scenario's own fleet): idle where it last dropped off until
its next assignment (reward 0), then the trip, from the assignment to the drop-off in the
destination's zone (reward 1), and after its last trip idle to the end of the run (terminal,
value 0). Shared rides (``--capacity`` above 1): a state is the vehicle's plan after a
decision -- the zone and time where its plan ends (the drop-off of its request that completes
last), and its seats left (its seats less the passengers of the requests it holds then); each
assignment is one transition (reward 1) from the previous plan's end to the new one's, and the
last plan's end goes to the end of the run (terminal). Batch TD(0): every sweep replaces each
state's value by the mean of its transitions' targets ``r + gamma^dt V(s')``, shrunk towards
the mean of its time bin over all zones where a state has few transitions (``shrink``
pseudo-counts), until the values move by less than ``tol``.

The days come from ``--allocator`` runs (``hungarian`` by default; ``rtv`` for shared rides);
with ``--iterations 2`` or more the later days run that allocator with the value of the
previous round (approximate policy iteration). Deterministic by seed: the same arguments write
the same file, byte for byte (the days are seeded, the file's zip entries carry no clock). The
file's metadata names the training seeds; evaluate on others (the shipped studies use seeds
0-9, the training days 100 and up).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from learning.value import ROOT, ZoneValue
from learning.zones import Zones


# ---------------------------------------------------------------------------- learning
def transitions(tasks, vehicles, zones: Zones, end: float,
                repositioned: bool = False) -> dict[str, np.ndarray]:
    """The transitions of one simulated day (see the module doc) from its ``tasks`` and
    ``vehicles`` tables (pandas frames): arrays ``z, t, r, z2, t2`` (``z2 = -1``: terminal).

    ``repositioned``: the day ran with a repositioner, so an idle vehicle did not stay where it
    dropped off: its idle transition goes from the drop-off's zone to the zone of its next
    pickup (where it was sent from lies within a pickup's ``max_wait`` of it; the tables do not
    keep the vehicle's position at the assignment), and the trip starts there."""
    done = tasks[tasks["state"] == "completed"].sort_values(["agent_id", "assigned_at"])
    start = vehicles.set_index("agent_id")[["x0", "y0"]]
    z, t, r, z2, t2 = [], [], [], [], []
    by_agent = {a: g for a, g in done.groupby("agent_id")}
    for aid, (x0, y0) in start.iterrows():
        prev_z = int(zones.of_xy(np.array([[x0, y0]]))[0])
        prev_t = 0.0
        g = by_agent.get(aid)
        if g is not None:
            dz = zones.of_xy(g[["dropoff_x", "dropoff_y"]].to_numpy())
            pz = zones.of_xy(g[["x", "y"]].to_numpy()) if repositioned else None
            for k, (ta, tc, zd) in enumerate(zip(g["assigned_at"].to_numpy(),
                                                 g["completed_at"].to_numpy(), dz.tolist())):
                za = int(pz[k]) if repositioned else prev_z  # where the trip starts
                z += [prev_z, za]
                t += [prev_t, ta]
                r += [0.0, 1.0]
                z2 += [za, zd]
                t2 += [ta, tc]
                prev_z, prev_t = zd, tc
        z.append(prev_z)
        t.append(prev_t)
        r.append(0.0)
        z2.append(-1)
        t2.append(end)
    return {"z": np.array(z, np.int64), "t": np.array(t), "r": np.array(r),
            "z2": np.array(z2, np.int64), "t2": np.array(t2)}


def td_learn(tr: dict[str, np.ndarray], n_zones: int, n_bins: int, bin_s: float, gamma: float,
             shrink: float = 5.0, tol: float = 1e-4,
             max_sweeps: int = 500) -> tuple[np.ndarray, int]:
    """Batch TD(0) over the transitions (see the module doc): ``(table, sweeps)``."""
    keep = tr["z"] >= 0
    z, t, r, z2, t2 = (tr[k][keep] for k in ("z", "t", "r", "z2", "t2"))
    b = np.minimum((t // bin_s).astype(np.int64), n_bins - 1)
    b2 = (t2 // bin_s).astype(np.int64)
    nxt = (z2 >= 0) & (b2 < n_bins)
    disc = np.power(gamma, np.maximum(t2 - t, 0.0))
    s = z * n_bins + b
    s2 = np.where(nxt, z2 * n_bins + np.minimum(b2, n_bins - 1), 0)
    size = n_zones * n_bins
    count = np.bincount(s, minlength=size).astype(float)
    bin_count = np.bincount(b, minlength=n_bins).astype(float)
    v = np.zeros(size)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        target = r + disc * np.where(nxt, v[s2], 0.0)
        total = np.bincount(s, weights=target, minlength=size)
        prior = np.bincount(b, weights=target, minlength=n_bins) / np.maximum(bin_count, 1.0)
        # a state never seen (no vehicle was there) is worth 0: nothing to expect
        new = np.divide(total + shrink * np.tile(prior, n_zones), count + shrink,
                        out=np.zeros(size), where=count > 0)
        delta = np.abs(new - v).max(initial=0.0)
        v = new
        if delta < tol:
            break
    return v.reshape(n_zones, n_bins), sweeps


def fit_trips(tasks, t_col: str = "picked_up_at") -> np.ndarray:
    """Per hour of the day, least squares ``trip seconds = a + b * straight-line metres`` over
    the completed trips (an hour with fewer than 20 trips: the all-day fit)."""
    done = tasks[tasks["state"] == "completed"]
    d = np.hypot(done["dropoff_x"] - done["x"], done["dropoff_y"] - done["y"]).to_numpy()
    s = (done["completed_at"] - done["picked_up_at"]).to_numpy()
    hour = (done[t_col].to_numpy() // 3600).astype(int) % 24

    def fit(mask):
        x = np.stack([np.ones(mask.sum()), d[mask]], axis=1)
        return np.linalg.lstsq(x, s[mask], rcond=None)[0]

    every = fit(np.ones(len(d), bool)) if len(d) >= 2 else np.array([0.0, 0.1])
    return np.array([fit(hour == h) if (hour == h).sum() >= 20 else every for h in range(24)])


def _day(sc, allocator: str, params: dict, agents: int, seed: int, reposition: str | None = None):
    """Run one day with ``allocator`` (its parameters ``params``; the ``reposition`` policy,
    if one); its tasks and vehicles tables (pandas) and summary."""
    from dispatch.run.runner import run_one

    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(params.items()),
                                      allocator_tables=()))
    if reposition is not None:
        sc = replace(sc, reposition=replace(sc.reposition, policy=reposition, declared=True))
    spec = sc.runs(allocator=allocator, agents=agents, seed=seed)[0]
    res = run_one(spec)
    tabs = res.tables
    return tabs["tasks"].to_pandas(), tabs["vehicles"].to_pandas(), res.summary


#: the generator seed of :func:`trace_half`'s split (fixed: half "a" is always the same trips)
HALF_SEED = 20141221


def trace_half(trips, half: str):
    """Half ``"a"`` or ``"b"`` of a trace's trips: each trip falls in one half by a draw of a
    fixed generator (:data:`HALF_SEED`), so the two halves are disjoint samples of one day's
    demand, a day to learn on and another to test on (a trace holds one day)."""
    if half not in ("a", "b"):
        raise ValueError(f"half must be 'a' or 'b', got {half!r}")
    in_a = np.random.default_rng(HALF_SEED).random(len(trips)) < 0.5
    return trips.subset(in_a if half == "a" else ~in_a, f"trace half {half}: the other half")


def scenario_for(path: str | Path, batch_window: float, hours: float | None = None,
                 trips_per_day: float | None = None, capacity: int | None = None,
                 objective: str | None = None, half: str | None = None):
    """The scenario of a study: its sweep dropped, the batch window fixed, optionally a
    shorter run (``hours``), another demand (``trips_per_day``), other seats (``capacity``),
    another ``[dispatch] objective`` or half of its trace's trips (``half``, "a" or "b":
    :func:`trace_half`)."""
    from dispatch.config.sweep import SweepConfig
    from dispatch.scenario.load import load_scenario

    sc = load_scenario(path)
    sc = replace(sc, sweep=SweepConfig(),
                 dispatch=replace(sc.dispatch, batch_window=float(batch_window)))
    if hours is not None:
        sc = replace(sc, duration=float(hours) * 3600.0)
    if trips_per_day is not None:
        sc = replace(sc, tasks=replace(sc.tasks, trips_per_day=float(trips_per_day)))
    if capacity is not None:
        sc = replace(sc, fleet=replace(sc.fleet, capacity=int(capacity)))
    if objective is not None:
        sc = replace(sc, dispatch=replace(sc.dispatch, objective=objective))
    if half is not None:
        if sc.tasks.trips is None:
            raise ValueError(f"{Path(path).name}: half of a trace needs [tasks] source = "
                             f"\"trace\", not {sc.tasks.source!r}")
        sc = replace(sc, tasks=replace(sc.tasks, trips=trace_half(sc.tasks.trips, half)))
    return sc


def pooled_transitions(tasks, vehicles, zones: Zones, end: float,
                       capacity: int) -> dict[str, np.ndarray]:
    """The transitions of one simulated day of shared rides (see the module doc): arrays
    ``z, t, r, z2, t2`` whose zones are state rows ``zone * (capacity + 1) + seats left``
    (``z2 = -1``: terminal; a zone outside every square stays -1)."""
    seats_n = capacity + 1
    done = tasks[tasks["state"] == "completed"].sort_values(["agent_id", "assigned_at",
                                                             "task_id"])
    start = vehicles.set_index("agent_id")[["x0", "y0"]]
    by_agent = {a: g for a, g in done.groupby("agent_id")}

    def row(z, s):
        return np.where(z >= 0, z * seats_n + np.clip(s, 0, capacity), -1)

    out = {k: [] for k in ("z", "t", "r", "z2", "t2")}
    for aid, (x0, y0) in start.iterrows():
        z_prev = row(zones.of_xy(np.array([[x0, y0]])), np.array([capacity]))
        t_prev = np.zeros(1)
        g = by_agent.get(aid)
        if g is not None:
            ta = g["assigned_at"].to_numpy(float)
            tc = g["completed_at"].to_numpy(float)
            pax = (g["passengers"].to_numpy(np.int64) if "passengers" in g
                   else np.ones(len(g), np.int64))
            dz = zones.of_xy(g[["dropoff_x", "dropoff_y"]].to_numpy())
            k = np.arange(len(g))
            # the plan after assignment k ends where its last-completing request drops off
            t_end = np.maximum.accumulate(tc)
            last = np.maximum.accumulate(np.where(tc >= t_end, k, 0))
            # seats left: the passengers of the requests held at assignment k (k included)
            held = (k[None, :] <= k[:, None]) & (tc[None, :] > ta[:, None])
            seats = capacity - (held * pax[None, :]).sum(axis=1)
            z_new = row(dz[last], seats)
            out["z"] += [z_prev, z_new[:-1]]
            out["t"] += [t_prev, t_end[:-1]]
            out["r"].append(np.ones(len(g)))
            out["z2"].append(z_new)
            out["t2"].append(t_end)
            z_prev, t_prev = z_new[-1:], t_end[-1:]
        out["z"].append(z_prev)
        out["t"].append(t_prev)
        out["r"].append(np.zeros(1))
        out["z2"].append(np.full(1, -1))
        out["t2"].append(np.full(1, float(end)))
    return {"z": np.concatenate(out["z"]).astype(np.int64), "t": np.concatenate(out["t"]),
            "r": np.concatenate(out["r"]), "z2": np.concatenate(out["z2"]).astype(np.int64),
            "t2": np.concatenate(out["t2"])}


def train(scenario: str | Path, out: str | Path, *, agents: int = 500, batch_window: float = 30.0,
          seeds=(100, 101, 102), iterations: int = 1, zone: float = 3000.0, bin_s: float = 3600.0,
          half_life: float = 3600.0, weight: float = 300.0, shrink: float = 5.0,
          hours: float | None = None, cache: str | Path | None = None,
          reposition: str | None = None, allocator: str = "hungarian",
          capacity: int | None = None, objective: str | None = None, log=print,
          progress=None, reward: float | None = None,
          start: str | Path | None = None, half: str | None = None) -> ZoneValue:
    """Learn a :class:`ZoneValue` from simulated days of ``allocator`` and save it to ``out``
    (see the module doc). ``reposition``: the days run with that repositioning policy (e.g.
    ``"demand"``): the value of where a vehicle ends up when idle vehicles are moved.
    ``capacity``: seats per vehicle (None: the scenario's); above 1 the value has a class per
    number of free seats. ``progress(done, total)`` after each simulated day. ``reward``: the
    days run with a value give the allocator this ``value_reward`` (seconds a served request
    is worth: it may leave a pair worth nothing for later). ``start``: a value file the first
    round's days already run with (policy iteration resumed from it). ``half``: the days hold
    only that half of the scenario's trace (:func:`trace_half`; test on the other)."""
    import pandas as pd

    from dispatch.api.space import space_for
    from dispatch.errors import DispatchError

    try:
        sc = scenario_for(scenario, batch_window, hours, capacity=capacity,
                          objective=objective, half=half)
    except ValueError as e:  # (a half of a scenario without a trace: one line, exit 2)
        raise DispatchError(str(e)) from e
    cap = int(sc.fleet.capacity)
    space = space_for(sc.world, 0, sc.path)
    node_xy = np.asarray(space.node_positions, dtype=float)[:, :2]
    zones = Zones(node_xy, zone)
    n_bins = math.ceil(sc.duration / bin_s)
    gamma = 0.5 ** (1.0 / half_life)
    seats_n = cap + 1 if cap > 1 else 1
    value: ZoneValue | None = None
    using = None if start is None else str(Path(start).resolve())
    history = []
    rounds = max(1, iterations)
    for it in range(rounds):
        parts, trips = [], []
        for seed in seeds:
            params = {} if using is None else {"value": using}
            if using is not None and reward is not None:
                params["value_reward"] = float(reward)
            got = None
            plain = cache is not None and using is None  # days without a value are reusable
            if plain:
                key = Path(cache) / (f"{allocator}_{sc.dispatch.objective}_c{cap}_n{agents}"
                                     f"_w{batch_window:g}_h{hours}"
                                     + (f"_half{half}" if half else "")
                                     + f"_s{seed}" + (f"_r{reposition}" if reposition else ""))
                if (key / "summary.json").exists():
                    got = (pd.read_parquet(key / "tasks.parquet"),
                           pd.read_parquet(key / "vehicles.parquet"),
                           json.loads((key / "summary.json").read_text()))
            if got is None:
                got = _day(sc, allocator, params, agents, seed, reposition)
                if plain:
                    key.mkdir(parents=True, exist_ok=True)
                    got[0].to_parquet(key / "tasks.parquet")
                    got[1].to_parquet(key / "vehicles.parquet")
                    (key / "summary.json").write_text(json.dumps(got[2], default=str))
            tasks, vehicles, summary = got
            if cap > 1:
                parts.append(pooled_transitions(tasks, vehicles, zones, sc.duration, cap))
            else:
                parts.append(transitions(tasks, vehicles, zones, sc.duration,
                                         repositioned=reposition is not None))
            trips.append(tasks)
            served = summary["tasks_completed"] / max(1, summary["n_tasks"])
            wait = summary.get("wait_time_mean")
            history.append({"iteration": it, "seed": seed, "served": round(served, 6),
                            "wait_mean": None if wait is None else round(float(wait), 3)})
            log(f"iteration {it}, day seed {seed}: served {100 * served:.1f} %, "
                f"mean wait {float('nan') if wait is None else wait:.1f} s")
            if progress is not None:
                progress(len(history), rounds * len(seeds))
        tr = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        table, sweeps = td_learn(tr, zones.n * seats_n, n_bins, bin_s, gamma, shrink)
        fit = fit_trips(pd.concat(trips))
        meta = {"scenario": Path(scenario).name, "agents": agents, "batch_window": batch_window,
                "allocator": allocator, "capacity": cap, "seeds": list(seeds),
                "objective": sc.dispatch.objective,
                "held_out": "evaluate on seeds other than 'seeds' (the studies: 0-9)",
                "iterations": it + 1, "half_life": half_life, "zone": zone, "bin": bin_s,
                "shrink": shrink, "weight": weight, "transitions": len(tr["z"]),
                "reposition": reposition, "hours": hours, "sweeps": sweeps, "days": history}
        if half is not None:
            meta["half"] = half
        if reward is not None or start is not None:  # (only then: older files' bytes as before)
            meta.update(reward=reward, start=None if start is None else Path(start).name)
        value = ZoneValue(zones, node_xy, bin_s, table, gamma, weight, fit, meta, seats_n)
        value.save(out)
        using = str(Path(out).resolve())
        log(f"iteration {it}: {len(tr['z'])} transitions, {sweeps} TD sweeps, "
            f"max value {table.max():.2f}, saved {out}")
    return value


def main(argv=None) -> int:
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    p = argparse.ArgumentParser(prog="dispatch train value",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--out", default="value.npz")
    p.add_argument("--agents", type=int, default=500)
    p.add_argument("--batch-window", type=float, default=30.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102],
                   help="seeds of the training days (keep the evaluation's seeds out)")
    p.add_argument("--iterations", type=int, default=1,
                   help="rounds of days; after the first, days run with the value so far")
    p.add_argument("--allocator", default="hungarian",
                   help="the allocator of the training days (e.g. rtv for shared rides)")
    p.add_argument("--capacity", type=int, default=None,
                   help="seats per vehicle (default: the scenario's); above 1 the value has a "
                        "class per number of free seats")
    p.add_argument("--objective", default=None, choices=("pickup_time", "added_time"),
                   help="the [dispatch] objective of the training days (default: the "
                        "scenario's)")
    p.add_argument("--zone", type=float, default=3000.0, help="zone side (metres)")
    p.add_argument("--bin", type=float, default=3600.0, help="time bin (seconds)")
    p.add_argument("--half-life", type=float, default=3600.0,
                   help="seconds after which a future request counts half")
    p.add_argument("--weight", type=float, default=300.0,
                   help="seconds of pickup time one unit of value is worth in the assignment")
    p.add_argument("--shrink", type=float, default=5.0)
    p.add_argument("--hours", type=float, default=None, help="shorter days (a quick look)")
    p.add_argument("--cache", default=None,
                   help="a folder keeping the days run without a value (reused by later calls)")
    p.add_argument("--reposition", default=None,
                   help="run the training days with this repositioning policy (e.g. demand): "
                        "the value to use with it")
    p.add_argument("--reward", type=float, default=None,
                   help="the days run with a value give the allocator this value_reward (seconds "
                        "a served request is worth)")
    p.add_argument("--start", default=None,
                   help="a value file the first round's days run with (policy iteration from it)")
    p.add_argument("--half", choices=("a", "b"), default=None,
                   help="the days hold only this half of the scenario's trace (a fixed split; "
                        "test on the other half: a day the value never saw)")
    a = p.parse_args(argv)
    console = Console(stderr=True)
    with Progress(TextColumn("[bold]training days"), BarColumn(), TextColumn("{task.completed}"
                  "/{task.total}"), TimeElapsedColumn(), console=console) as bar:
        task = bar.add_task("days", total=max(1, a.iterations) * len(a.seeds))
        train(a.scenario, a.out, agents=a.agents, batch_window=a.batch_window, seeds=a.seeds,
              iterations=a.iterations, zone=a.zone, bin_s=a.bin, half_life=a.half_life,
              weight=a.weight, shrink=a.shrink, hours=a.hours, cache=a.cache,
              reposition=a.reposition, allocator=a.allocator, capacity=a.capacity,
              objective=a.objective, reward=a.reward, start=a.start, half=a.half,
              log=bar.console.print,
              progress=lambda done, total: bar.update(task, completed=done))
    return 0


if __name__ == "__main__":
    sys.exit(main())
