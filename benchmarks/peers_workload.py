"""The common workload of ``benchmarks/peers.py``: files every simulator reads, and the metrics.

Standard library and numpy only: it is imported both by the project's interpreter and by the
peers' own environment (``benchmarks/.peers-venv``), which has numpy (RidePy needs it) but not
this project.

A workload folder holds

* ``trips.csv``: ``t, origin_node, dest_node`` (the project's trace format, node ids of
  :func:`dispatch.space.roads.manhattan`: node ``row * columns + column`` at ``(column, row) *
  block``);
* ``fleet.csv``: ``vehicle_id, node`` (the project's start-file format);
* ``workload.json``: grid size, block, speed, seed, horizon and end time; for shared rides
  (``benchmarks/pooling.py``) also the seats per vehicle, the requests' limits and the streets'
  jitter;
* ``grid.graphml`` (jittered streets only): the grid with each street's own length, for the
  project (RidePy's graph space is built from :meth:`Workload.streets`).

Every runner writes one JSON of :func:`metrics` (plus its wall seconds) for the driver to print.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Workload:
    """What every simulator is given: a ``columns x rows`` grid of ``block`` metres driven at
    ``speed`` m/s, requests released in ``[0, horizon)``, the run stopped at ``end`` seconds;
    ``capacity`` seats per vehicle, and each request's limits in seconds (``None``: none): its
    pickup by release + ``max_wait``, its drop-off by release + direct time + ``max_delay``
    (Alonso-Mora's Omega and Delta; the project's ``[tasks] max_wait`` and ``max_delay``,
    RidePy's ``pickup_timewindow_max`` and ``delivery_timewindow_max``)."""

    columns: int
    rows: int
    block: float
    speed: float
    seed: int
    requests: int
    vehicles: int
    horizon: float
    end: float
    capacity: int = 1
    max_wait: float | None = None
    max_delay: float | None = None
    #: each two-way street ``block x (1 + jitter x u)`` metres long, ``u`` uniform in [-1, 1]
    #: (seeded): shortest paths become unique, so simulators that break ties between equally
    #: short grid paths differently drive the same routes
    jitter: float = 0.0

    @property
    def nodes(self) -> int:
        return self.columns * self.rows

    def node_xy(self, node: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """``(column, row)`` of node ids (the project's Manhattan numbering)."""
        node = np.asarray(node)
        return node % self.columns, node // self.columns

    def streets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(u, v, metres)``: each two-way street once, between 4-neighbours (rows first,
        then columns), its length ``block`` or jittered."""
        node = np.arange(self.nodes).reshape(self.rows, self.columns)
        u = np.concatenate([node[:, :-1].ravel(), node[:-1, :].ravel()])
        v = np.concatenate([node[:, 1:].ravel(), node[1:, :].ravel()])
        metres = np.full(u.size, float(self.block))
        if self.jitter:
            rng = np.random.default_rng([self.seed, 31415])
            metres *= 1.0 + self.jitter * rng.uniform(-1.0, 1.0, u.size)
        return u, v, metres

    def direct(self, origin: np.ndarray, dest: np.ndarray) -> np.ndarray:
        """Free-flow seconds of the fastest path between nodes (the grid's Manhattan distance
        at ``speed``; jittered streets: Dijkstra's): what the drop-off limit and the detour
        ratio are measured against."""
        if not self.jitter:
            (ox, oy), (dx, dy) = self.node_xy(origin), self.node_xy(dest)
            return (np.abs(ox - dx) + np.abs(oy - dy)) * self.block / self.speed
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        u, v, metres = self.streets()
        graph = coo_matrix((metres, (u, v)), shape=(self.nodes, self.nodes)).tocsr()
        return dijkstra(graph, directed=False)[origin, dest] / self.speed

    def latest(self, t: np.ndarray, origin: np.ndarray, dest: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Each request's latest pickup and latest drop-off (``inf``: no limit)."""
        wait = math.inf if self.max_wait is None else self.max_wait
        delay = math.inf if self.max_delay is None else self.max_delay
        return t + wait, t + self.direct(origin, dest) + delay


def generate(requests: int, vehicles: int, hours: float, seed: int, *, columns: int = 20,
             rows: int = 20, block: float = 200.0, speed: float = 10.0, drain: float = 3600.0,
             capacity: int = 1, max_wait: float | None = None, max_delay: float | None = None,
             jitter: float = 0.0
             ) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A seeded Poisson workload: ``requests`` release times (a Poisson process of rate
    ``requests / horizon`` conditioned on its count: sorted uniform times, rounded to ms), origins
    and destinations uniform over the intersections with destination != origin, and one uniform
    start intersection per vehicle. Returns ``(workload, t, origin, dest, start)``. The seats,
    limits and jitter change no draw: the same seed gives the same requests for every one."""
    if requests < 1 or vehicles < 1 or not hours > 0:
        raise ValueError(f"need requests >= 1, vehicles >= 1, hours > 0; got {requests}, "
                         f"{vehicles}, {hours}")
    n = columns * rows
    t_rng, od_rng, v_rng = (np.random.default_rng(s)
                            for s in np.random.SeedSequence(seed).spawn(3))
    horizon = hours * 3600.0
    t = np.sort(np.round(t_rng.uniform(0.0, horizon, requests), 3))
    origin = od_rng.integers(n, size=requests)
    dest = od_rng.integers(n - 1, size=requests)
    dest += dest >= origin
    start = v_rng.integers(n, size=vehicles)
    w = Workload(columns, rows, block, speed, seed, requests, vehicles, horizon, horizon + drain,
                 capacity, max_wait, max_delay, jitter)
    return w, t, origin, dest, start


def prefix(w: Workload, t: np.ndarray, origin: np.ndarray, dest: np.ndarray, k: int,
           drain: float) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray]:
    """The first ``k`` requests of a workload, same fleet: same rate per vehicle, a shorter day
    (horizon: the k-th release, rounded up to a second)."""
    k = min(k, t.size)
    horizon = float(np.ceil(t[k - 1] + 1e-9))
    cut = replace(w, requests=k, horizon=horizon, end=horizon + drain)
    return cut, t[:k], origin[:k], dest[:k]


def write(folder: Path, w: Workload, t: np.ndarray, origin: np.ndarray, dest: np.ndarray,
          start: np.ndarray) -> None:
    """Write the three files of a workload folder."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "trips.csv", "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["t", "origin_node", "dest_node"])
        out.writerows(zip((f"{x:.3f}" for x in t), origin.tolist(), dest.tolist()))
    with open(folder / "fleet.csv", "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["vehicle_id", "node"])
        out.writerows(enumerate(start.tolist()))
    (folder / "workload.json").write_text(json.dumps(asdict(w), indent=1))
    if w.jitter:
        write_graphml(folder / "grid.graphml", w)


def write_graphml(path: Path, w: Workload) -> None:
    """The jittered grid as GraphML for the project (node ids are the node numbers; ``x``,
    ``y`` metres; per street ``length`` metres and ``travel_time`` seconds, both ways)."""
    u, v, metres = w.streets()
    x, y = w.node_xy(np.arange(w.nodes))
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<graphml xmlns="http://graphml.graphdrawing.org/xmlns">',
             '<key id="x" for="node" attr.name="x" attr.type="double"/>',
             '<key id="y" for="node" attr.name="y" attr.type="double"/>',
             '<key id="length" for="edge" attr.name="length" attr.type="double"/>',
             '<key id="tt" for="edge" attr.name="travel_time" attr.type="double"/>',
             '<graph edgedefault="undirected">']
    lines += [f'<node id="{i}"><data key="x">{a * w.block!r}</data>'
              f'<data key="y">{b * w.block!r}</data></node>'
              for i, (a, b) in enumerate(zip(x.tolist(), y.tolist()))]
    lines += [f'<edge source="{a}" target="{b}"><data key="length">{m!r}</data>'
              f'<data key="tt">{m / w.speed!r}</data></edge>'
              for a, b, m in zip(u.tolist(), v.tolist(), metres.tolist())]
    lines += ["</graph>", "</graphml>"]
    path.write_text("\n".join(lines) + "\n")


def read(folder: Path) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(workload, t, origin, dest, start)`` as :func:`write` left them."""
    w = Workload(**json.loads((folder / "workload.json").read_text()))
    trips = np.loadtxt(folder / "trips.csv", delimiter=",", skiprows=1, ndmin=2)
    fleet = np.loadtxt(folder / "fleet.csv", delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
    return (w, trips[:, 0], trips[:, 1].astype(np.int64), trips[:, 2].astype(np.int64),
            fleet[:, 1])


def metrics(released: np.ndarray, picked_up: np.ndarray, completed: np.ndarray,
            vehicle_m: float, *, direct: np.ndarray | None = None,
            shared: np.ndarray | None = None, passenger_m: float | None = None) -> dict:
    """The service metrics printed side by side, from per-request times (``nan``: did not
    happen by the end): requests, served (dropped off), waits (release -> pickup, over the
    requests picked up: mean and 90th percentile, seconds) and the fleet's vehicle km.

    Shared rides (``direct``: each request's free-flow direct seconds, ``shared``: another
    request was on board during its ride, ``passenger_m``: the fleet's passenger-metres) add,
    over the requests served: ``served_share``, ``detour_mean`` (in-vehicle time / direct
    time), ``delay_mean`` (drop-off - release - direct time, s), ``shared_rate``, and the
    fleet's ``occupancy`` (passenger-km / vehicle-km, MATSim DRT's)."""
    wait = (picked_up - released)[np.isfinite(picked_up)]
    nan = float("nan")
    row = {
        "requests": int(released.size),
        "served": int(np.isfinite(completed).sum()),
        "picked": int(wait.size),
        "wait_mean": float(wait.mean()) if wait.size else nan,
        "wait_p90": float(np.percentile(wait, 90)) if wait.size else nan,
        "vehicle_km": vehicle_m / 1000.0,
    }
    if direct is not None:
        done = np.isfinite(completed)
        ride, late = (completed - picked_up)[done], (completed - released - direct)[done]
        row.update(
            served_share=row["served"] / max(row["requests"], 1),
            detour_mean=float((ride / direct[done]).mean()) if done.any() else nan,
            delay_mean=float(late.mean()) if done.any() else nan,
            shared_rate=float(shared[done].mean()) if done.any() else nan,
            passenger_km=passenger_m / 1000.0,
            occupancy=passenger_m / vehicle_m if vehicle_m > 0 else nan)
    return row


def save_pickups(path: Path, released: np.ndarray, picked_up: np.ndarray,
                 vehicle: np.ndarray) -> None:
    """Per request: its wait (``nan``: not picked up) and the vehicle that picked it up (-1)."""
    np.savez(path, wait=picked_up - released, vehicle=vehicle.astype(np.int64))


def compare_pickups(a: Path, b: Path) -> dict:
    """Requests picked up by the same vehicle id in both runs: their share, the first request
    where the two part, and the wait difference b - a on them (mean, median)."""
    x, y = np.load(a), np.load(b)
    both = np.isfinite(x["wait"]) & np.isfinite(y["wait"])
    same = both & (x["vehicle"] == y["vehicle"])
    diff = (y["wait"] - x["wait"])[same]
    parted = np.flatnonzero(~same)
    return {"same": float(same.mean()), "first_parted": int(parted[0]) if parted.size else -1,
            "diff_mean": float(diff.mean()) if diff.size else float("nan"),
            "diff_median": float(np.median(diff)) if diff.size else float("nan")}
