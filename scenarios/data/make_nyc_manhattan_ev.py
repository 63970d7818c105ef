"""Make scenarios/data/nyc_manhattan_ev_*.csv from HIVE's Manhattan files
(../shared/data/nyc_manhattan,
BSD 3-Clause: its LICENSE.txt is copied beside them as nyc_manhattan_ev_LICENSE.txt):

* nyc_manhattan_ev_fleet.csv: HIVE's 1,200 vehicles (vehicle_id = the number of ``v<k>``) at their
lon/lat
  projected to the network's metres (x, y; the run snaps them to the nearest intersection),
  ``soc`` = HIVE's initial_soc (0.8);
* nyc_manhattan_ev_stations.csv: HIVE's 15 DCFC stations (on-shift access; the four LEVEL_2 depots
with 1,000
  plugs each are for off-shift vehicles in HIVE and are left out), 50 kW, ``plugs`` as in HIVE
  (20) or ``--plugs K`` for each.

Run: ``PYTHONPATH=. .venv/bin/python scenarios/data/make_nyc_manhattan_ev.py [SRC] [--plugs K
--out stations_K.csv]``.
"""

from __future__ import annotations

import csv
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
PREFIX = "nyc_manhattan_ev_"


def main(argv: list[str]) -> None:
    plugs = None
    out_name = PREFIX + "stations.csv"
    if "--plugs" in argv:
        k = argv.index("--plugs")
        plugs = int(argv[k + 1])
        del argv[k:k + 2]
    if "--out" in argv:
        k = argv.index("--out")
        out_name = argv[k + 1]
        del argv[k:k + 2]
    src = Path(argv[0]) if argv else Path(__file__).resolve().parents[3] / "shared/data/nyc_manhattan"
    shutil.copy(src / "LICENSE.txt", HERE / (PREFIX + "LICENSE.txt"))
    with open(src / "hive_nyc_stations.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["charger_id"] == "DCFC"]
    with open(HERE / out_name, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["station_id", "lon", "lat", "plugs", "kw"])
        for r in rows:
            w.writerow([r["station_id"], r["lon"], r["lat"],
                        plugs if plugs is not None else r["charger_count"], 50.0])
    if out_name != PREFIX + "stations.csv":
        return
    from dispatch.space.roads import load_network

    net = load_network("manhattan_osm", base=HERE)
    with open(src / "hive_fleet_1200.csv", newline="") as f:
        fleet = list(csv.DictReader(f))
    xy = net.lonlat_to_xy([float(r["lon"]) for r in fleet], [float(r["lat"]) for r in fleet])
    with open(HERE / (PREFIX + "fleet.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["vehicle_id", "x", "y", "soc"])
        for r, (x, y) in zip(fleet, xy):
            w.writerow([int(r["vehicle_id"].lstrip("v")), f"{x:.2f}", f"{y:.2f}",
                        r["initial_soc"]])


if __name__ == "__main__":
    main(sys.argv[1:])
