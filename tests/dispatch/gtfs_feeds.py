"""GTFS feeds for the transit tests, written as text files: a tiny hand-made one (two lines,
one transfer, known answers), random ones, and an independent reference router (shortest paths
on the time-expanded graph, networkx)."""

from __future__ import annotations

import csv
import itertools
import math
from pathlib import Path

import networkx as nx
import numpy as np

#: the calendar of the hand-made feeds: service WK runs Monday to Friday in 2026 except
#: Wednesday 2026-03-04, when service HOL runs instead
CALENDAR = [{"service_id": "WK", "monday": 1, "tuesday": 1, "wednesday": 1, "thursday": 1,
             "friday": 1, "saturday": 0, "sunday": 0, "start_date": "20260101",
             "end_date": "20261231"}]
CALENDAR_DATES = [{"service_id": "WK", "date": "20260304", "exception_type": 2},
                  {"service_id": "HOL", "date": "20260304", "exception_type": 1}]


def write_feed(folder: Path, tables: dict[str, list[dict]]) -> Path:
    """Write ``{file name: rows}`` as GTFS text files (header: the first row's keys)."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, rows in tables.items():
        with open(folder / name, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
            w.writeheader()
            w.writerows(rows)
    return folder


def hms(t: float) -> str:
    t = int(t)
    return f"{t // 3600:02d}:{t // 60 % 60:02d}:{t % 60:02d}"


def _place(x: float, y: float) -> tuple[float, float]:
    """lon, lat of a point ``x`` m east and ``y`` m north of (-73.98, 40.75)."""
    k = math.pi / 180 * 6371008.8
    return -73.98 + x / (k * math.cos(math.radians(40.75))), 40.75 + y / k


def tiny_tables() -> dict[str, list[dict]]:
    """Two lines 2 km apart at each station, one transfer. Red (route R): A -> B -> C, trips
    R1 08:00 / 08:05 / 08:10, R2 08:10 / 08:15 / 08:20, R3 24:10 / 24:15 / 24:20 (past
    midnight). Green (route G): D -> B -> E, G1 08:02 / 08:07 / 08:13, G2 08:07 / 08:12 /
    08:18. B is a station with a platform per line; changing there takes 180 s
    (``transfers.txt``). Service WK; on 2026-03-04 only HOL runs: trip R9, A 09:00 -> C 09:10."""
    places = {"A": (0, 0), "B": (2000, 0), "C": (4000, 0), "D": (2000, -2000),
              "E": (2000, 2000)}
    stops = []
    for sid, (x, y) in places.items():
        lon, lat = _place(x, y)
        stops.append({"stop_id": sid, "stop_name": f"Station {sid}", "stop_lat": f"{lat:.7f}",
                      "stop_lon": f"{lon:.7f}", "location_type": 1 if sid == "B" else "",
                      "parent_station": ""})
    for plat in ("BR", "BG"):
        stops.append({**stops[1], "stop_id": plat, "location_type": "", "parent_station": "B"})
    trips, times = [], []
    runs = {"R1": ("R", "WK", [("A", "08:00:00"), ("BR", "08:05:00"), ("C", "08:10:00")]),
            "R2": ("R", "WK", [("A", "08:10:00"), ("BR", "08:15:00"), ("C", "08:20:00")]),
            "R3": ("R", "WK", [("A", "24:10:00"), ("BR", "24:15:00"), ("C", "24:20:00")]),
            "G1": ("G", "WK", [("D", "08:02:00"), ("BG", "08:07:00"), ("E", "08:13:00")]),
            "G2": ("G", "WK", [("D", "08:07:00"), ("BG", "08:12:00"), ("E", "08:18:00")]),
            "R9": ("R", "HOL", [("A", "09:00:00"), ("BR", "09:05:00"), ("C", "09:10:00")])}
    for tid, (route, service, calls) in runs.items():
        trips.append({"route_id": route, "service_id": service, "trip_id": tid})
        for seq, (sid, t) in enumerate(calls, start=1):
            times.append({"trip_id": tid, "arrival_time": t, "departure_time": t,
                          "stop_id": sid, "stop_sequence": seq})
    return {"agency.txt": [{"agency_id": "T", "agency_name": "Tiny", "agency_url": "http://x",
                            "agency_timezone": "America/New_York"}],
            "stops.txt": stops,
            "routes.txt": [{"route_id": r, "route_short_name": r, "route_type": 1}
                           for r in ("R", "G")],
            "trips.txt": trips, "stop_times.txt": times,
            "calendar.txt": [dict(r) for r in CALENDAR],
            "calendar_dates.txt": [dict(r) for r in CALENDAR_DATES],
            "transfers.txt": [{"from_stop_id": "B", "to_stop_id": "B", "transfer_type": 2,
                               "min_transfer_time": 180}]}


def random_tables(rng: np.random.Generator, *, stations: int = 24, lines: int = 6,
                  size: float = 3000.0, hours: tuple[float, float] = (7.0, 9.5)):
    """A random feed on service WK: ``stations`` in a ``size`` m square (every third one a
    parent station with a platform), ``lines`` routes of 4 to 8 stations run both ways every
    4 to 12 minutes from ``hours[0]`` to ``hours[1]`` (hops 60 to 240 s, dwells 0 to 30 s),
    random change times in ``transfers.txt`` at some stations and one between two stations."""
    xy = rng.uniform(0, size, (stations, 2))
    stops = []
    call_id = {}
    for i, (x, y) in enumerate(xy):
        lon, lat = _place(x, y)
        sid = f"S{i}"
        row = {"stop_id": sid, "stop_name": sid, "stop_lat": f"{lat:.7f}",
               "stop_lon": f"{lon:.7f}", "location_type": "", "parent_station": ""}
        if i % 3 == 0:
            stops.append({**row, "location_type": 1})
            stops.append({**row, "stop_id": f"{sid}P", "parent_station": sid})
            call_id[i] = f"{sid}P"
        else:
            stops.append(row)
            call_id[i] = sid
    trips, times = [], []
    for line in range(lines):
        path = rng.choice(stations, size=int(rng.integers(4, 9)), replace=False)
        hops = rng.integers(60, 241, path.size - 1)
        headway = int(rng.integers(4, 13)) * 60
        for direction, (p, h) in enumerate(((path, hops), (path[::-1], hops[::-1]))):
            t0 = hours[0] * 3600 + int(rng.integers(0, headway))
            k = 0
            while t0 < hours[1] * 3600:
                tid = f"L{line}D{direction}T{k}"
                trips.append({"route_id": f"L{line}", "service_id": "WK", "trip_id": tid})
                t = t0
                for seq, s in enumerate(p):
                    dwell = int(rng.integers(0, 31)) if 0 < seq < p.size - 1 else 0
                    times.append({"trip_id": tid, "arrival_time": hms(t),
                                  "departure_time": hms(t + dwell), "stop_id": call_id[int(s)],
                                  "stop_sequence": seq + 1})
                    if seq < h.size:
                        t += dwell + int(h[seq])
                t0 += headway
                k += 1
    transfers = [{"from_stop_id": f"S{i}", "to_stop_id": f"S{i}", "transfer_type": 2,
                  "min_transfer_time": int(rng.integers(0, 301))}
                 for i in range(0, stations, 2)]
    transfers.append({"from_stop_id": "S1", "to_stop_id": "S2", "transfer_type": 2,
                      "min_transfer_time": 200})
    return {"stops.txt": stops,
            "routes.txt": [{"route_id": f"L{i}", "route_type": 1} for i in range(lines)],
            "trips.txt": trips, "stop_times.txt": times,
            "calendar.txt": [dict(r) for r in CALENDAR], "transfers.txt": transfers}


class Reference:
    """Earliest arrivals by Dijkstra (networkx) on the time-expanded graph of a timetable's
    feed, built from the feed's calls (not from the router's connections): a node per call's
    arrival and departure and per (station, time) a rider can wait at; edges weigh the
    seconds between their events. The footpaths are the model's input, read from the
    timetable. Calls leaving after ``window[1]`` (or before ``window[0]``) are left out."""

    def __init__(self, tt, window: tuple[float, float] = (-math.inf, math.inf)) -> None:
        feed = tt.feed
        st = tt.stop_station[feed.call_stop]
        arr, dep, trip = feed.call_arrival, feed.call_departure, feed.call_trip
        g = nx.DiGraph()
        waits: dict[int, set[float]] = {}
        self.time = {}
        for i in range(trip.size - 1):
            if trip[i] != trip[i + 1] or not window[0] <= dep[i] <= window[1]:
                continue
            g.add_edge(("dep", i), ("arr", i + 1), weight=arr[i + 1] - dep[i])
            g.add_edge(("wait", st[i], dep[i]), ("dep", i), weight=0.0)
            waits.setdefault(st[i], set()).add(dep[i])
            if i > 0 and trip[i - 1] == trip[i]:  # stay aboard through call i
                g.add_edge(("arr", i), ("dep", i), weight=dep[i] - arr[i])
        for node in list(g.nodes):
            if node[0] != "arr":
                continue
            i = node[1]
            v = st[i]
            for k in range(tt.fp_ptr[v], tt.fp_ptr[v + 1]):
                w, d = int(tt.fp_to[k]), float(tt.fp_dur[k])
                t = arr[i] + d
                if w != v:
                    g.add_edge(node, ("walked", w, t), weight=d)
                    g.add_edge(("walked", w, t), ("wait", w, t), weight=0.0)
                else:
                    g.add_edge(node, ("wait", w, t), weight=d)
                waits.setdefault(w, set()).add(t)
        self.chain = {}
        for s, ts in waits.items():
            ts = sorted(ts)
            for a, b in itertools.pairwise(ts):
                g.add_edge(("wait", s, a), ("wait", s, b), weight=b - a)
            self.chain[s] = np.array(ts)
        self.g, self.st, self.arr, self.n = g, st, arr, tt.n_stations

    def arrivals(self, origin: int, t0: float) -> np.ndarray:
        """Per station, the earliest arrival from ``origin`` ready at ``t0`` (inf: never)."""
        out = np.full(self.n, np.inf)
        out[origin] = t0
        ts = self.chain.get(origin, np.array([]))
        k = int(np.searchsorted(ts, t0))
        if k == ts.size:
            return out
        first = ("wait", origin, ts[k])
        dist = nx.single_source_dijkstra_path_length(self.g, first)
        for node, d in dist.items():
            t = ts[k] + d
            if node[0] == "arr":
                s = self.st[node[1]]
                assert abs(t - self.arr[node[1]]) < 1e-6  # weights are the events' gaps
            elif node[0] == "walked":
                s = node[1]
            else:
                continue
            out[s] = min(out[s], t)
        return out
