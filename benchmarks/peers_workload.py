"""The common workload of ``benchmarks/peers.py``: files every simulator reads, and the metrics.

Standard library and numpy only: it is imported both by the project's interpreter and by the
peers' own environment (``benchmarks/.peers-venv``), which has numpy (RidePy needs it) but not
this project.

A workload folder holds

* ``trips.csv``: ``t, origin_node, dest_node`` (the project's trace format, node ids of
  :func:`dispatch.roads.manhattan`: node ``row * columns + column`` at ``(column, row) * block``);
* ``fleet.csv``: ``vehicle_id, node`` (the project's start-file format);
* ``workload.json``: grid size, block, speed, seed, horizon and end time.

Every runner writes one JSON of :func:`metrics` (plus its wall seconds) for the driver to print.
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Workload:
    """What every simulator is given: a ``columns x rows`` grid of ``block`` metres driven at
    ``speed`` m/s, requests released in ``[0, horizon)``, the run stopped at ``end`` seconds."""

    columns: int
    rows: int
    block: float
    speed: float
    seed: int
    requests: int
    vehicles: int
    horizon: float
    end: float

    @property
    def nodes(self) -> int:
        return self.columns * self.rows

    def node_xy(self, node: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """``(column, row)`` of node ids (the project's Manhattan numbering)."""
        node = np.asarray(node)
        return node % self.columns, node // self.columns


def generate(requests: int, vehicles: int, hours: float, seed: int, *, columns: int = 20,
             rows: int = 20, block: float = 200.0, speed: float = 10.0, drain: float = 3600.0
             ) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A seeded Poisson workload: ``requests`` release times (a Poisson process of rate
    ``requests / horizon`` conditioned on its count: sorted uniform times, rounded to ms), origins
    and destinations uniform over the intersections with destination != origin, and one uniform
    start intersection per vehicle. Returns ``(workload, t, origin, dest, start)``."""
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
    w = Workload(columns, rows, block, speed, seed, requests, vehicles, horizon, horizon + drain)
    return w, t, origin, dest, start


def prefix(w: Workload, t: np.ndarray, origin: np.ndarray, dest: np.ndarray, k: int,
           drain: float) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray]:
    """The first ``k`` requests of a workload, same fleet: same rate per vehicle, a shorter day
    (horizon: the k-th release, rounded up to a second)."""
    k = min(k, t.size)
    horizon = float(np.ceil(t[k - 1] + 1e-9))
    cut = Workload(w.columns, w.rows, w.block, w.speed, w.seed, k, w.vehicles, horizon,
                   horizon + drain)
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


def read(folder: Path) -> tuple[Workload, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(workload, t, origin, dest, start)`` as :func:`write` left them."""
    w = Workload(**json.loads((folder / "workload.json").read_text()))
    trips = np.loadtxt(folder / "trips.csv", delimiter=",", skiprows=1, ndmin=2)
    fleet = np.loadtxt(folder / "fleet.csv", delimiter=",", skiprows=1, dtype=np.int64, ndmin=2)
    return (w, trips[:, 0], trips[:, 1].astype(np.int64), trips[:, 2].astype(np.int64),
            fleet[:, 1])


def metrics(released: np.ndarray, picked_up: np.ndarray, completed: np.ndarray,
            vehicle_m: float) -> dict:
    """The service metrics printed side by side, from per-request times (``nan``: did not
    happen by the end): requests, served (dropped off), waits (release -> pickup, over the
    requests picked up: mean and 90th percentile, seconds) and the fleet's vehicle km."""
    wait = (picked_up - released)[np.isfinite(picked_up)]
    return {
        "requests": int(released.size),
        "served": int(np.isfinite(completed).sum()),
        "picked": int(wait.size),
        "wait_mean": float(wait.mean()) if wait.size else float("nan"),
        "wait_p90": float(np.percentile(wait, 90)) if wait.size else float("nan"),
        "vehicle_km": vehicle_m / 1000.0,
    }


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
