"""A learned value of where a vehicle ends up: zone x time of day, by temporal-difference learning
on simulated days (issue 22), used in the assignment as DiDi (Tang et al., KDD 2019) and NeurADP
(Shah et al., AAAI 2020) do.

The value ``V(z, t)`` is the discounted number of requests a vehicle idle in zone ``z`` at time
``t`` will still serve (discount per second ``gamma``, from a half-life). It is learned from the
trips of simulated days: each vehicle's day is a chain of transitions ``(zone, time) ->
(zone', time')``: idle where it last dropped off until its next assignment (reward 0), then the
trip, from the assignment to the drop-off in the destination's zone (reward 1), and after its
last trip idle to the end of the run (terminal, value 0). Batch TD(0): every sweep replaces each
state's value by the mean of its transitions' targets ``r + gamma^dt V(s')``, shrunk towards the
mean of its time bin over all zones where a state has few transitions (``shrink`` pseudo-counts),
until the values move by less than ``tol``. The days come from ``hungarian`` runs (with
``--iterations 2`` or more, the later days from ``hungarian`` using the value of the previous
round: approximate policy iteration).

In the assignment (``hungarian`` with ``value = "path.npz"``) a pair's cost becomes

    dt = cost[i, j] + trip_j
    cost[i, j] - weight * (gamma^dt * V(zone(dropoff_j), now + dt) - V(zone(vehicle_i), now))

with ``trip_j`` the trip's expected drive (a fit of the simulated trips' durations on the
straight-line distance from pickup to drop-off, per hour of the day) and ``weight`` seconds per
served request (the exchange rate between waiting and the future). Infeasible pairs stay
``inf``; the allocator still serves as many requests as it can, and chooses which (and by whom)
by this cost. What the allocator needs is in the problem: the vehicles' nodes, the requests'
pickup and drop-off nodes and the costs; the file carries the node positions and the zones.

Train: ``dispatch train value --out value.npz`` (see ``--help``; the Chicago day at N = 500,
batched 30 s, by default). ``--reposition demand`` learns it from days with ``demand``
repositioning (idle vehicles are moved, so the idle transitions end where the next trip starts):
the value to use on top of that repositioner.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from learning.zones import Zones

ROOT = Path(__file__).resolve().parents[1]
log = logging.getLogger(__name__)


@dataclass
class ZoneValue:
    """The learned table and what using it needs (load with :meth:`load`)."""

    zones: Zones
    node_xy: np.ndarray  # (n_nodes, 2) metres: the network the value was learned on
    bin_s: float  # seconds per time bin
    table: np.ndarray  # (n_zones, n_bins) values; 0 outside a zone and after the last bin
    gamma: float  # discount per second
    weight: float  # seconds of cost per unit of value
    trip_fit: np.ndarray  # (24, 2): per hour, trip seconds = a + b * straight-line metres
    meta: dict
    _warned: bool = False

    # ------------------------------------------------------------------ using it
    def value(self, zone: np.ndarray, t: np.ndarray) -> np.ndarray:
        """``V(zone, t)`` element-wise (broadcast); 0 for zone -1 or beyond the last bin."""
        zone, t = np.broadcast_arrays(np.asarray(zone, np.int64), np.asarray(t, float))
        b = np.floor(t / self.bin_s).astype(np.int64)
        ok = (zone >= 0) & (b >= 0) & (b < self.table.shape[1])
        out = np.zeros(zone.shape)
        out[ok] = self.table[zone[ok], b[ok]]
        return out

    def trip_seconds(self, pickup: np.ndarray, dropoff: np.ndarray, t: float) -> np.ndarray:
        """Expected drive from pickup to drop-off node (the fit of the hour of ``t``)."""
        d = np.hypot(*(self.node_xy[dropoff] - self.node_xy[pickup]).T)
        a, b = self.trip_fit[int(t // 3600) % 24]
        return np.maximum(a + b * d, 0.0)

    def adjusted(self, problem, weight: float | None = None) -> np.ndarray:
        """The problem's cost with the value of each pair (see the module doc)."""
        w = self.weight if weight is None else float(weight)
        cost = np.asarray(problem.cost, dtype=float)
        if cost.size == 0 or w == 0:
            return cost
        now = float(problem.time)
        nodes = problem.agents.nodes
        if nodes is None:
            nodes = [getattr(a.loc, "node", a.loc) for a in problem.agents]
        picks = [t.loc for t in problem.tasks]
        drops = [t.loc if t.dropoff is None else t.dropoff for t in problem.tasks]
        if not all(isinstance(x, (int, np.integer)) for x in (*picks, *drops, *nodes)):
            if not self._warned:  # not road nodes (a voxel world): the value does not apply
                log.warning("the learned value applies to road networks only: costs unchanged")
                self._warned = True
            return cost
        nodes = np.asarray(nodes, dtype=np.int64)
        picks, drops = np.array(picks, np.int64), np.array(drops, np.int64)
        if max(nodes.max(initial=0), picks.max(initial=0), drops.max(initial=0)) \
                >= len(self.node_xy):
            raise ValueError("the value was learned on another network (a node id beyond its "
                             f"{len(self.node_xy)} nodes)")
        z_now = self.zones.of_node[nodes]
        z_drop = self.zones.of_node[drops]
        trip = self.trip_seconds(picks, drops, now)
        finite = np.isfinite(cost)
        c = np.where(finite, cost, 0.0)
        dt = c + trip[None, :]
        after = np.power(self.gamma, dt) * self.value(z_drop[None, :], now + dt)
        before = self.value(z_now, now)[:, None]
        return np.where(finite, cost - w * (after - before), np.inf)

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez_compressed(
            tmp, zone_size=self.zones.size, zone_origin=self.zones.origin,
            zone_keys=self.zones.keys, node_xy=self.node_xy, bin_s=self.bin_s,
            table=self.table, gamma=self.gamma, weight=self.weight, trip_fit=self.trip_fit,
            meta=json.dumps(self.meta))
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> ZoneValue:
        with np.load(Path(path), allow_pickle=False) as f:
            node_xy = f["node_xy"]
            zones = Zones(node_xy, float(f["zone_size"]), f["zone_origin"], f["zone_keys"])
            return cls(zones, node_xy, float(f["bin_s"]), f["table"], float(f["gamma"]),
                       float(f["weight"]), f["trip_fit"], json.loads(str(f["meta"])))


# ---------------------------------------------------------------------------- an option
class ValueOption:
    """The ``value`` / ``value_weight`` option of an allocator (``hungarian`` and ``magnnet``
    share it): the learned value of ``path`` and the weight to use it with (None: the file's).

    Every adjustment is per agent: row ``i`` of :meth:`costs` depends only on agent ``i``'s node,
    the tasks and the time, so a decentralized agent adjusts its own costs and gets the same
    numbers as a central one."""

    def __init__(self, path: str | Path, weight: float | None = None) -> None:
        self.path = str(path)
        self.value = ZoneValue.load(path)
        self.weight = self.value.weight if weight is None else float(weight)

    @classmethod
    def of(cls, path, weight=None) -> ValueOption | None:
        """The option of an allocator's parameters (None without a ``value`` file)."""
        return None if path is None else cls(path, weight)

    def costs(self, problem) -> np.ndarray:
        """The problem's costs less the discounted value after each trip plus the value now
        (:meth:`ZoneValue.adjusted`); ``inf`` where the cost is."""
        return self.value.adjusted(problem, self.weight)

    @property
    def offset(self) -> float:
        """A bound of how far below its travel time an adjusted cost can go (the weight times
        the largest value of the file): :meth:`costs` plus it is never negative. A constant of
        the file, so every agent knows it without hearing the others."""
        return self.weight * max(float(self.value.table.max(initial=0.0)), 0.0)

    def problem(self, problem, shift: bool = False):
        """``problem`` with :meth:`costs` as its cost matrix (plus :attr:`offset` with ``shift``,
        for allocators whose models read costs as non-negative travel times; a constant added
        to every pair changes no comparison between pairs)."""
        from dataclasses import replace as _replace

        cost = self.costs(problem)
        if shift:
            cost = cost + self.offset
        return _replace(problem, cost=np.ascontiguousarray(cost))


def travel_costs(allocation, problem):
    """``allocation`` (decided on an adjusted copy of ``problem``) with each request's cost
    read back from ``problem.cost``: what the run records stays the travel time."""
    from dataclasses import replace as _replace

    if not allocation.requests:
        return allocation
    row = {int(a): i for i, a in enumerate(problem.agent_ids.tolist())}
    col = {int(t): j for j, t in enumerate(problem.task_ids.tolist())}
    reqs = tuple(_replace(r, cost=float(problem.cost[row[r.agent_id], col[r.task_id]]))
                 for r in allocation.requests)
    return _replace(allocation, requests=reqs)


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
    """Run one day (with the ``reposition`` policy, if one); its tasks and vehicles tables
    (pandas) and summary."""
    from dispatch.run.runner import run_one

    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(params.items())))
    if reposition is not None:
        sc = replace(sc, reposition=replace(sc.reposition, policy=reposition, declared=True))
    spec = sc.runs(allocator=allocator, agents=agents, seed=seed)[0]
    res = run_one(spec)
    tabs = res.tables
    return tabs["tasks"].to_pandas(), tabs["vehicles"].to_pandas(), res.summary


def scenario_for(path: str | Path, batch_window: float, hours: float | None = None,
                 trips_per_day: float | None = None):
    """The scenario of a study: its sweep dropped, the batch window fixed, optionally a
    shorter run (``hours``) or another demand (``trips_per_day``)."""
    from dispatch.config.sweep import SweepConfig
    from dispatch.scenario.load import load_scenario

    sc = load_scenario(path)
    sc = replace(sc, sweep=SweepConfig(),
                 dispatch=replace(sc.dispatch, batch_window=float(batch_window)))
    if hours is not None:
        sc = replace(sc, duration=float(hours) * 3600.0)
    if trips_per_day is not None:
        sc = replace(sc, tasks=replace(sc.tasks, trips_per_day=float(trips_per_day)))
    return sc


def train(scenario: str | Path, out: str | Path, *, agents: int = 500, batch_window: float = 30.0,
          seeds=(100, 101, 102), iterations: int = 1, zone: float = 3000.0, bin_s: float = 3600.0,
          half_life: float = 3600.0, weight: float = 300.0, shrink: float = 5.0,
          hours: float | None = None, cache: str | Path | None = None,
          reposition: str | None = None, log=print) -> ZoneValue:
    """Learn a :class:`ZoneValue` from simulated days and save it to ``out``. ``reposition``:
    the days run with that repositioning policy (e.g. ``"demand"``): the value of where a
    vehicle ends up when idle vehicles are moved, for allocators run with it."""
    from dispatch.api.space import space_for

    sc = scenario_for(scenario, batch_window, hours)
    space = space_for(sc.world, 0, sc.path)
    node_xy = np.asarray(space.node_positions, dtype=float)[:, :2]
    zones = Zones(node_xy, zone)
    n_bins = math.ceil(sc.duration / bin_s)
    gamma = 0.5 ** (1.0 / half_life)
    t0 = time.perf_counter()
    value: ZoneValue | None = None
    history = []
    for it in range(max(1, iterations)):
        parts, trips = [], []
        for seed in seeds:
            params = {} if value is None else {"value": str(out)}
            got = None
            if cache is not None and value is None:  # plain hungarian days are reusable
                key = Path(cache) / (f"n{agents}_w{batch_window:g}_h{hours}_s{seed}"
                                     + (f"_r{reposition}" if reposition else ""))
                if (key / "summary.json").exists():
                    import pandas as pd

                    got = (pd.read_parquet(key / "tasks.parquet"),
                           pd.read_parquet(key / "vehicles.parquet"),
                           json.loads((key / "summary.json").read_text()))
            if got is None:
                got = _day(sc, "hungarian", params, agents, seed, reposition)
                if cache is not None and value is None:
                    key.mkdir(parents=True, exist_ok=True)
                    got[0].to_parquet(key / "tasks.parquet")
                    got[1].to_parquet(key / "vehicles.parquet")
                    (key / "summary.json").write_text(json.dumps(got[2], default=str))
            tasks, vehicles, summary = got
            parts.append(transitions(tasks, vehicles, zones, sc.duration,
                                     repositioned=reposition is not None))
            trips.append(tasks)
            served = summary["tasks_completed"] / max(1, summary["n_tasks"])
            history.append({"iteration": it, "seed": seed, "served": served,
                            "wait_mean": summary.get("wait_time_mean")})
            log(f"iteration {it}, day seed {seed}: served {100 * served:.1f} %, "
                f"mean wait {summary.get('wait_time_mean', float('nan')):.1f} s "
                f"({time.perf_counter() - t0:.0f} s)")
        tr = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        table, sweeps = td_learn(tr, zones.n, n_bins, bin_s, gamma, shrink)
        import pandas as pd

        fit = fit_trips(pd.concat(trips))
        meta = {"scenario": str(scenario), "agents": agents, "batch_window": batch_window,
                "seeds": list(seeds), "iterations": it + 1, "half_life": half_life,
                "zone": zone, "shrink": shrink, "transitions": len(tr["z"]),
                "reposition": reposition,
                "sweeps": sweeps, "seconds": round(time.perf_counter() - t0, 1),
                "days": history}
        value = ZoneValue(zones, node_xy, bin_s, table, gamma, weight, fit, meta)
        value.save(out)
        log(f"iteration {it}: {len(tr['z'])} transitions, {sweeps} TD sweeps, "
            f"max value {table.max():.2f}, saved {out}")
    return value


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="dispatch train value", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--out", default="value.npz")
    p.add_argument("--agents", type=int, default=500)
    p.add_argument("--batch-window", type=float, default=30.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102],
                   help="seeds of the training days (keep the evaluation's seeds out)")
    p.add_argument("--iterations", type=int, default=1,
                   help="rounds of days; after the first, days run with the value so far")
    p.add_argument("--zone", type=float, default=3000.0, help="zone side (metres)")
    p.add_argument("--bin", type=float, default=3600.0, help="time bin (seconds)")
    p.add_argument("--half-life", type=float, default=3600.0,
                   help="seconds after which a future request counts half")
    p.add_argument("--weight", type=float, default=300.0,
                   help="seconds of pickup time one unit of value is worth in the assignment")
    p.add_argument("--shrink", type=float, default=5.0)
    p.add_argument("--hours", type=float, default=None, help="shorter days (a quick look)")
    p.add_argument("--cache", default=None,
                   help="a folder keeping the plain hungarian days (reused by later calls)")
    p.add_argument("--reposition", default=None,
                   help="run the training days with this repositioning policy (e.g. demand): "
                        "the value to use with it")
    a = p.parse_args(argv)
    train(a.scenario, a.out, agents=a.agents, batch_window=a.batch_window, seeds=a.seeds,
          iterations=a.iterations, zone=a.zone, bin_s=a.bin, half_life=a.half_life,
          weight=a.weight, shrink=a.shrink, hours=a.hours, cache=a.cache,
          reposition=a.reposition,
          log=lambda s: print(s, file=sys.stderr, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
