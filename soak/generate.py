"""Scenarios drawn at random over the configuration space a user can set, each small enough
to run in seconds, from a seed alone (one ``numpy.random.Generator``).

A :class:`Case` is a scenario document (the TOML tables as nested dicts) and the small CSV
files it names (a header and rows each), so that :mod:`soak.shrink` can cut keys, values and
rows and write the result again. Two worlds:

* **road**: a generated grid of a few blocks, the shipped 20 x 20 grid with the first
  rows of its shipped trace (``scenarios/data/manhattan_trips.csv``), or Manhattan's street
  network (``manhattan_osm``) with the first minutes of the NYC taxi day and, mostly, the
  subway (``[transit]``: the shipped feed, every key and mode choice), cut to minutes; shared
  rides, batching, both objectives, requests out of reach waiting (``out_of_reach``), every
  allocator, walking, prebooking (a share or a trace's
  ``booked_at``; entry at booking or by lead), offers with each acceptor and pricing, shifts
  (a start file's columns) and sizing, electric fleets with each charging strategy,
  repositioning, congestion, breakdowns (by rate and by file, transfer or failure), radio
  ranges and blackouts, service times, drivers' breaks;
* **voxel**: the paper's world made small (size, cell, obstacles), UAVs and UGVs, each
  task source, every voxel planner, radio ranges, latency, loss and blackouts.

Every value is drawn inside the range its key accepts. Combinations the loader refuses by
design may still be drawn; the soak counts them as *refused* with the loader's message.
"""

from __future__ import annotations

import copy
import csv
import functools
import io
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.tomltext import dumps

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_TRIPS = ROOT / "scenarios" / "data" / "manhattan_trips.csv"
NYC_TRIPS = ROOT / "dispatch" / "data" / "nyc_manhattan" / "nyc_taxi_2014-12-21_20k.csv"
MODE_CHOICES = ("cheapest", "logit", "train_first")
WORLDS = ("road", "voxel")
ROAD_ALLOCATORS = ("hungarian", "greedy", "fcfs", "random", "auction", "local_hungarian", "rtv")
VOXEL_ALLOCATORS = ("hungarian", "greedy", "fcfs", "random", "auction", "local_hungarian",
                    "magnnet")
VOXEL_PLANNERS = ("astar", "astar", "reservation", "rrt_star", "rstar")


def _write_whole(path: Path, data: str | bytes) -> None:
    """``data`` (text as UTF-8) into ``path`` through a temporary name and an atomic rename."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    os.replace(tmp, path)


@dataclass
class Case:
    """A scenario: its document, the CSV files it names (``name -> (header, rows)``) and its
    binary files (``name -> bytes``: a learned value, ``value.npz``), kept whole."""

    world: str
    doc: dict
    files: dict[str, tuple[list[str], list[list]]] = field(default_factory=dict)
    blobs: dict[str, bytes] = field(default_factory=dict)

    def copy(self) -> Case:
        return Case(self.world, copy.deepcopy(self.doc), copy.deepcopy(self.files),
                    dict(self.blobs))

    def write(self, directory: Path, name: str = "scenario.toml") -> Path:
        """Write the scenario and its files into ``directory``, each whole (a temporary name,
        then a rename: a soak killed meanwhile leaves no half-written file); return the
        scenario's path."""
        directory.mkdir(parents=True, exist_ok=True)
        for fname, (header, rows) in self.files.items():
            buf = io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            w.writerow(header)
            w.writerows(["" if v is None else v for v in row] for row in rows)
            _write_whole(directory / fname, buf.getvalue())
        for fname, data in self.blobs.items():
            _write_whole(directory / fname, data)
        path = directory / name
        _write_whole(path, dumps(self.doc))
        return path

    @classmethod
    def read(cls, directory: Path, name: str = "scenario.toml") -> Case:
        """The case written in ``directory`` (its scenario and every CSV file beside it, the
        cells kept as text; every ``.npz`` file as bytes)."""
        import tomllib

        doc = tomllib.loads((directory / name).read_text(encoding="utf-8"))
        files = {}
        for f in sorted(directory.glob("*.csv")):
            with f.open(encoding="utf-8", newline="") as fh:
                header, *rows = list(csv.reader(fh))
            files[f.name] = (header, rows)
        blobs = {f.name: f.read_bytes() for f in sorted(directory.glob("*.npz"))}
        return cls("road" if "network" in doc.get("world", {}) else "voxel", doc, files, blobs)

    def text(self) -> str:
        """The scenario's TOML text (its files aside)."""
        return dumps(self.doc)


def _r(rng, lo: float, hi: float, digits: int = 1) -> float:
    return round(float(rng.uniform(lo, hi)), digits)


def _pick(rng, options):
    return options[int(rng.integers(len(options)))]


def _p(rng, p: float) -> bool:
    return bool(rng.random() < p)


def draw(seed: int, index: int = 0, world: str | None = None) -> Case:
    """Run ``index`` of the soak of ``seed`` (in ``world``, else either at random): drawn from
    ``numpy.random.default_rng([seed, index])`` alone, so the same pair gives the same
    scenario and files."""
    rng = np.random.default_rng([seed, index])
    world = world or _pick(rng, WORLDS)
    case = _road(rng) if world == "road" else _voxel(rng)
    case.doc = {"name": f"soak{seed}_{index}", "seed": int(rng.integers(0, 2**31 - 1)),
                **case.doc}
    return case


# ----------------------------------------------------------------------------- road


def _shipped_trips(n: int) -> list[list]:
    with SHIPPED_TRIPS.open(encoding="utf-8") as fh:
        rows = list(csv.reader(fh))[1: n + 1]
    return [[float(t), int(o), int(d)] for t, o, d, *_ in rows]


@functools.lru_cache(maxsize=1)
def _osm_nodes() -> np.ndarray:
    """The node ids of Manhattan's street network (``manhattan_osm``), read once."""
    from dispatch.space.roads import load_network

    return np.asarray(load_network("manhattan_osm", base=ROOT).ids, dtype=np.int64)


def _nyc_trips(seconds: float) -> list[list]:
    """The NYC taxi day's trips released in its first ``seconds`` (``t`` from midnight, which
    is also the subway feed's service day's midnight), by coordinates."""
    from dispatch.files.traces import parse_datetime, seconds_between

    out = []
    midnight = None
    with NYC_TRIPS.open(encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            when = parse_datetime(row["departure_time"])
            midnight = midnight or when.replace(hour=0, minute=0, second=0, microsecond=0)
            t = seconds_between(when, midnight)
            if t > seconds:
                break
            out.append([t, float(row["o_lat"]), float(row["o_lon"]), float(row["d_lat"]),
                        float(row["d_lon"])])
    return out


def _node(rng, nodes) -> int:
    """A node drawn uniformly: of ``0 .. nodes - 1`` (a grid), or of the ids ``nodes``."""
    if isinstance(nodes, int):
        return int(rng.integers(nodes))
    return int(nodes[rng.integers(len(nodes))])


def _transit(rng) -> dict:
    """A ``[transit]`` table on the shipped subway feed, every key drawn in its range."""
    choice = _pick(rng, MODE_CHOICES)
    table: dict = {"feed": "nyc_subway", "service_date": "2026-09-23",
                   "max_access_walk": _r(rng, 100, 1500, 0), "mode_choice": choice}
    for key, lo, hi in (("walk_speed", 0.5, 2.5), ("transfer_walk", 0, 600),
                        ("min_change", 0, 300), ("w_ivt", 0.5, 2), ("w_wait", 0.5, 4),
                        ("w_walk", 0.5, 4), ("w_transfer", 0.5, 4),
                        ("transfer_penalty", 0, 900)):
        if _p(rng, 0.3):
            table[key] = _r(rng, lo, hi, 2)
    if choice == "logit" and _p(rng, 0.5):
        table["logit"] = {"scale": _r(rng, 0.01, 1.0, 2)}
    elif choice == "train_first" and _p(rng, 0.5):
        table["train_first"] = {"slack": _r(rng, 0, 1800, 0)}
    return table


def _road(rng) -> Case:
    doc: dict = {}
    files: dict = {}
    shipped = _p(rng, 0.3)
    osm = shipped and _p(rng, 0.4)
    if osm:
        world = {"network": "manhattan_osm"}
        trips = _nyc_trips(_r(rng, 60, 600, 0))
        header = ["t", "o_lat", "o_lon", "d_lat", "d_lon"]
    elif shipped:
        cols = rows = 20
        world = {"network": "manhattan", "blocks": [20, 20], "block": 200.0, "speed": 10.0}
        trips = _shipped_trips(int(rng.integers(5, 60)))
    else:
        cols, rows = int(rng.integers(2, 8)), int(rng.integers(2, 8))
        world = {"network": "manhattan", "blocks": [cols, rows], "block": _r(rng, 50, 400, 0),
                 "speed": _r(rng, 3, 20)}
        n = int(rng.integers(1, 50))
        t = np.sort(np.round(rng.uniform(0, _r(rng, 60, 1800, 0), n), 1))
        trips = []
        for ti in t:
            o, d = rng.choice(cols * rows, size=2, replace=False)
            trips.append([float(ti), int(o), int(d)])
    nodes = _osm_nodes() if osm else cols * rows
    if not osm:
        header = ["t", "origin_node", "dest_node"]
    if _p(rng, 0.2):
        world["congestion"] = [_r(rng, 1.0, 2.0, 2) for _ in range(24)]
    doc["duration"] = round(max(r[0] for r in trips) + _r(rng, 60, 3600, 0), 1)
    doc["world"] = world
    agents = int(rng.integers(1, 9))
    capacity = int(_pick(rng, (1, 1, 2, 3, 4)))
    fleet: dict = {"agents": agents, "capacity": capacity}
    tasks: dict = {"source": "trace", "trace": "trips.csv"}
    dispatch: dict = {"allocator": _pick(rng, ROAD_ALLOCATORS), "planner": "dijkstra"}
    # the trace's optional columns: riders per request, own limits, bookings
    if capacity > 1 and _p(rng, 0.4):
        header.append("passengers")
        for r in trips:
            r.append(int(rng.integers(1, capacity + 1)))
    if _p(rng, 0.2):
        header.append("max_wait")
        for r in trips:
            r.append(_r(rng, 30, 900, 0) if _p(rng, 0.7) else None)
    prebook = _p(rng, 0.35)
    if prebook and _p(rng, 0.5):
        header.append("booked_at")
        for r in trips:
            r.append(round(max(0.0, r[0] - _r(rng, 0, 1800, 0)), 1) if _p(rng, 0.5) else None)
    elif prebook:
        tasks["prebook_share"] = _pick(rng, (0.3, 0.6, 1.0, _r(rng, 0.05, 1.0, 2)))
        tasks["prebook_lead"] = _r(rng, 0, 3600, 0)
    if prebook and _p(rng, 0.4):
        dispatch["prebook"] = "lead"
        if _p(rng, 0.5):
            dispatch["prebook_lead"] = _r(rng, 0, 1800, 0)
    files["trips.csv"] = (header, trips)
    if _p(rng, 0.8):
        tasks["max_wait"] = _r(rng, 30, 900, 0)
        if _p(rng, 0.25):
            dispatch["out_of_reach"] = "wait"  # (a request out of reach waits, not rejected)
    if _p(rng, 0.6 if capacity > 1 else 0.25):
        tasks["max_delay"] = _r(rng, 30, 1200, 0)
    if _p(rng, 0.3):
        tasks["service_time"] = _r(rng, 0, 60)
    if _p(rng, 0.15):
        tasks["ttl"] = _r(rng, 10, 900, 0)
    if _p(rng, 0.3):
        tasks["max_walk"] = _r(rng, 0, 2.5 * world.get("block", 200.0), 0)
        if _p(rng, 0.5):
            tasks["walk_speed"] = _r(rng, 0.5, 2.5, 2)
        if _p(rng, 0.5):
            tasks["meeting_points"] = int(rng.integers(1, 10))
    doc["tasks"] = tasks
    if _p(rng, 0.3):
        dispatch["batch_window"] = _pick(rng, (5.0, 30.0, _r(rng, 0.5, 60)))
    if _p(rng, 0.5 if capacity > 1 else 0.2):
        dispatch["objective"] = "added_time"
    if not prebook and capacity == 1 and "max_walk" not in tasks and _p(rng, 0.15):
        dispatch["reassign"] = True  # (refused with shared rides, bookings and walks)
    if _p(rng, 0.1):
        dispatch["lazy_costs"] = True
    _road_fleet(rng, doc, fleet, files, nodes, dispatch)
    doc["fleet"] = fleet
    doc["dispatch"] = dispatch
    _road_extras(rng, doc, files, nodes, agents)
    if osm and _p(rng, 0.7):
        doc["transit"] = _transit(rng)
    blobs = {} if osm else _lookahead(rng, doc, world, capacity)
    return Case("road", doc, files, blobs)


VALUE_ALLOCATORS = ("hungarian", "local_hungarian", "rtv")


def _lookahead(rng, doc, world, capacity: int) -> dict[str, bytes]:
    """A learned value of the grid (random, of the file's valid shape: zones, time bins, seat
    classes, discount, weight) for the allocators and the ``demand`` repositioner that take
    one, with its keys (``value_weight``, ``value_reward``, ``value_mix``); ``{}`` where none
    is drawn."""
    dispatch = doc["dispatch"]
    alloc = dispatch["allocator"] in VALUE_ALLOCATORS and _p(rng, 0.25)
    repo = "reposition" in doc and _p(rng, 0.4)
    if not (alloc or repo):
        return {}
    if alloc:
        params: dict = {"value": "value.npz"}
        if _p(rng, 0.5):
            params["value_weight"] = _r(rng, 0, 900, 0)
        if dispatch["allocator"] != "local_hungarian" and _p(rng, 0.2):
            params["value_reward"] = _r(rng, 60, 1800, 0)
        dispatch["allocator_params"] = {dispatch["allocator"]: params}
    if repo:
        doc["reposition"]["demand"]["value"] = "value.npz"
        if _p(rng, 0.5):
            doc["reposition"]["demand"]["value_mix"] = _r(rng, 0, 1, 2)
    return {"value.npz": _value_file(rng, world, capacity)}


def _value_file(rng, world, capacity: int) -> bytes:
    """The bytes of a :class:`learning.value.ZoneValue` file on the grid ``world``."""
    from dispatch.space.roads import manhattan
    from learning.value import ZoneValue
    from learning.zones import Zones

    cols, rows = (int(b) for b in world["blocks"])
    xy = np.asarray(manhattan(cols, rows, float(world["block"]), float(world["speed"])).xy,
                    dtype=float)[:, :2]
    zones = Zones(xy, _r(rng, 50, 2000, 0))
    seats = capacity + 1 if capacity > 1 else 1
    table = np.round(rng.uniform(0.0, 5.0, (zones.n * seats, int(rng.integers(1, 5)))), 3)
    value = ZoneValue(zones, xy, float(_pick(rng, (300.0, 1800.0, 3600.0))), table,
                      0.5 ** (1.0 / _r(rng, 60, 7200, 0)), _r(rng, 0, 600, 0),
                      np.tile([_r(rng, 0, 300, 0), _r(rng, 0.05, 0.3, 2)], (24, 1)),
                      {"soak": True}, seats)
    return value.to_bytes()


def _road_fleet(rng, doc, fleet, files, nodes, dispatch) -> None:
    agents = fleet["agents"]
    shifts = _p(rng, 0.25)
    if shifts or _p(rng, 0.2):
        header = ["vehicle_id", "node"]
        rows = [[i, _node(rng, nodes)] for i in range(agents)]
        if shifts:
            header += ["shift_start", "shift_end", "depot"]
            span = doc["duration"]
            for r in rows:
                s = _r(rng, 0, span * 0.5, 0) if _p(rng, 0.6) else 0.0
                e = round(s + _r(rng, 60, span, 0), 1) if _p(rng, 0.8) else None
                r += [s, e, _node(rng, nodes) if _p(rng, 0.5) else None]
            if _p(rng, 0.5):
                fleet["shift_grace"] = _r(rng, 0, 900, 0)
            if _p(rng, 0.35):
                fleet["sizing"] = "utilization"
                lo = _r(rng, 0.1, 0.6, 2)
                fleet["sizing_params"] = {
                    "min_vehicles": int(rng.integers(0, agents + 1)),
                    "interval": _r(rng, 30, 900, 0), "low": lo,
                    "high": round(min(1.0, lo + _r(rng, 0.05, 0.4, 2)), 2)}
        files["fleet.csv"] = (header, rows)
        fleet["start"] = "fleet.csv"
        del fleet["agents"]
    if _p(rng, 0.2) and dispatch["allocator"] != "rtv":
        fleet["breaks"] = {"after": _r(rng, 120, 1800, 0), "duration": _r(rng, 30, 600, 0)}
    if _p(rng, 0.25):
        battery = _r(rng, 0.5, 60, 1)
        fleet["energy"] = {"battery_kwh": battery, "wh_per_km": _r(rng, 80, 400, 0),
                           "soc0": _r(rng, 0.05, 1.0, 2), "reserve": _r(rng, 0.0, 0.3, 2)}
        if _p(rng, 0.5):
            fleet["energy"]["idle_kwh_per_hour"] = _r(rng, 0, 2, 2)
        if _p(rng, 0.3):
            fleet["energy"]["max_charge_kw"] = _r(rng, 3, 150, 0)
        if _p(rng, 0.3):
            fleet["energy"]["sample"] = _r(rng, 30, 900, 0)
        if _p(rng, 0.7):
            k = int(rng.integers(1, 4))
            files["stations.csv"] = (["station_id", "node", "plugs", "kw"],
                                     [[f"S{i}", _node(rng, nodes), int(rng.integers(1, 4)),
                                       _r(rng, 3, 150, 1)] for i in range(k)])
            doc["chargers"] = {"file": "stations.csv"}
            strategy = _pick(rng, ("threshold", "idle", "valley"))
            low = _r(rng, 0.05, 0.5, 2)
            params = {"low": low, "high": round(min(1.0, low + _r(rng, 0.1, 0.6, 2)), 2)}
            if strategy == "idle" and _p(rng, 0.5):
                params["radius"] = _r(rng, 0, 900, 0)
            doc["charging"] = {"strategy": strategy, "interval": _r(rng, 10, 600, 0),
                               strategy: params}


def _road_extras(rng, doc, files, nodes, agents) -> None:
    if _p(rng, 0.2):
        name = _pick(rng, ("always", "threshold", "logit"))
        acceptor: dict = {"name": name}
        if _p(rng, 0.5):
            acceptor["retries"] = int(rng.integers(0, 3))
        if name == "threshold":
            acceptor["threshold"] = {"max_wait": _r(rng, 30, 900, 0),
                                     "max_detour": _r(rng, 1.0, 3.0, 2)}
        elif name == "logit":
            acceptor["logit"] = {"b0": _r(rng, 0, 5), "b_wait": -_r(rng, 0, 0.5, 2),
                                 "b_ivt": -_r(rng, 0, 0.2, 2)}
        doc["acceptor"] = acceptor
        if _p(rng, 0.5):
            doc["pricing"] = {"base": _r(rng, 0, 5), "per_km": _r(rng, 0, 3),
                              "per_minute": _r(rng, 0, 1), "sharing_discount": _r(rng, 0, 0.5, 2)}
            if name == "logit":
                acceptor["logit"]["b_fare"] = -_r(rng, 0, 0.3, 2)
    if _p(rng, 0.2):
        doc["reposition"] = {"policy": "demand", "interval": _r(rng, 10, 900, 0),
                             "horizon": _r(rng, 60, 3600, 0),
                             "demand": {"zone": _r(rng, 100, 2000, 0),
                                        "max_moves": int(rng.integers(1, 10))}}
    _faults(rng, doc, files, agents if "agents" in doc["fleet"] else
            len(files.get("fleet.csv", ([], []))[1]))


def _faults(rng, doc, files, agents: int) -> None:
    faults: dict = {}
    if _p(rng, 0.2):
        faults["rate"] = _r(rng, 0.1, 5.0, 2)
        faults["repair"] = _pick(rng, (_r(rng, 10, 900, 0), float("inf")))
    if _p(rng, 0.15) and doc.get("world", {}).get("network") and agents:
        rows = [[_r(rng, 0, doc["duration"], 0), int(rng.integers(agents)),
                 _pick(rng, (_r(rng, 10, 900, 0), float("inf")))]
                for _ in range(int(rng.integers(1, 4)))]
        files["failures.csv"] = (["t", "vehicle_id", "duration"], rows)
        faults["file"] = "failures.csv"
    if faults and _p(rng, 0.5):
        faults["on_board"] = _pick(rng, ("transfer", "fail"))
    if _p(rng, 0.15):
        a = _r(rng, 0, doc["duration"], 0)
        faults["blackout"] = [[a, round(a + _r(rng, 1, 600, 0), 1)]]
    if faults:
        doc["faults"] = faults
    if _p(rng, 0.2):
        comms: dict = {"range": _r(rng, 5, 3000, 0)}
        if _p(rng, 0.5):
            comms["latency"] = _r(rng, 0, 0.5, 3)
        if _p(rng, 0.5):
            comms["loss"] = _r(rng, 0, 0.5, 2)
        doc["comms"] = comms


# ----------------------------------------------------------------------------- voxel


def _voxel(rng) -> Case:
    cell = _pick(rng, (1.0, 1.0, 2.0))
    size = [cell * int(rng.integers(4, 16)), cell * int(rng.integers(4, 16)),
            cell * int(rng.integers(2, 7))]
    doc: dict = {"duration": _r(rng, 5, 120, 0)}
    doc["world"] = {"size": size, "cell": cell, "physics": False,
                    "obstacles": {"count": int(rng.integers(0, 8)), "min_size": [1.0, 1.0, 1.0],
                                  "max_size": [_r(rng, 1, 6, 0), _r(rng, 1, 6, 0),
                                               _r(rng, 1, size[2], 0)]}}
    agents = int(rng.integers(1, 9))
    doc["fleet"] = {"agents": agents, "uav_fraction": _pick(rng, (0.0, 0.5, 1.0, 0.25)),
                    "uav_speed": _r(rng, 1, 8), "ugv_speed": _r(rng, 0.5, 5)}
    source = _pick(rng, ("static", "periodic", "poisson"))
    tasks: dict = {"source": source, "ground_fraction": _pick(rng, (0.0, 0.5, 1.0))}
    if source == "static":
        tasks["count"] = int(rng.integers(1, 3 * agents + 1))
    elif source == "periodic":
        tasks.update(interval=_r(rng, 0.5, 5), count=int(rng.integers(1, 30)))
    else:
        tasks.update(rate=_r(rng, 0.1, 3, 2), count=int(rng.integers(1, 30)))
    if source != "static" and _p(rng, 0.5):
        tasks["max_active"] = int(rng.integers(1, 10))
    if _p(rng, 0.4):
        tasks["ttl"] = _r(rng, 2, 60)
    if _p(rng, 0.3):
        tasks["max_wait"] = _r(rng, 2, 60)
    if _p(rng, 0.3):
        tasks["service_time"] = _r(rng, 0, 5)
    doc["tasks"] = tasks
    doc["dispatch"] = {"allocator": _pick(rng, VOXEL_ALLOCATORS),
                       "planner": _pick(rng, VOXEL_PLANNERS)}
    if _p(rng, 0.4):
        doc["dispatch"]["batch_window"] = _r(rng, 0.1, 5)
    files: dict = {}
    _faults(rng, doc, files, agents)
    doc.get("faults", {}).pop("on_board", None)
    return Case("voxel", doc, files)
