"""Derive dispatch/data/chicago_taxi/ from the Chicago taxi trip sample (reproducible).

    python scripts/make_chicago_taxi.py [SAMPLE_CSV]

SAMPLE_CSV defaults to ../shared/data/taxi/chicago_taxi_trips_sample.csv (the tensorflow/tfx
copy of 15,002 City of Chicago "Taxi Trips"). Writes, beside dispatch/data/chicago_taxi/NOTICE.md:

* ``trips.csv``: one row per sample trip that has pickup and drop-off coordinates and a
  ``trip_seconds``: ``hour`` (trip_start_hour, 0..23), ``day`` (trip_start_day, 1 = Sunday ..
  7 = Saturday), ``origin_node`` / ``dest_node`` (Chicago Regional TNTP node numbers: the
  nearest node to the pickup / drop-off point), ``origin_snap_m`` / ``dest_snap_m`` (metres to
  that node), ``trip_seconds``, ``pickup_community_area``;
* ``congestion.csv``: per hour of day the factor of :func:`dispatch.files.hourly.calibrate`
  (median observed / free-flow seconds), the trips it was taken over and the pooling width.

Prints the snapping and filtering statistics.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.files.hourly import calibrate
from dispatch.space.roads import load_network

DEFAULT = ROOT.parent / "shared" / "data" / "taxi" / "chicago_taxi_trips_sample.csv"
OUT = ROOT / "dispatch" / "data" / "chicago_taxi"
NEED = ("pickup_latitude", "pickup_longitude", "dropoff_latitude", "dropoff_longitude",
        "trip_seconds")


def main(src: Path, out: Path = OUT) -> None:
    with open(src, newline="") as fh:
        rows = list(csv.DictReader(fh))
    kept = [r for r in rows if all(r[k].strip() for k in NEED)]
    print(f"{src.name}: {len(rows)} trips; {len(kept)} with pickup and drop-off coordinates "
          f"and trip_seconds ({len(rows) - len(kept)} dropped: a blank one of those)")
    col = {k: np.array([float(r[k]) for r in kept]) for k in NEED}
    net = load_network("chicago", base=ROOT)
    o, so = net.nearest(net.lonlat_to_xy(col["pickup_longitude"], col["pickup_latitude"]))
    d, sd = net.nearest(net.lonlat_to_xy(col["dropoff_longitude"], col["dropoff_latitude"]))
    ids = np.asarray(net.ids)
    for name, s in (("pickup", so), ("drop-off", sd)):
        print(f"snapping {name}s to the nearest of {net.n} nodes: median {np.median(s):.0f} m, "
              f"p95 {np.percentile(s, 95):.0f} m, max {s.max():.0f} m")
    same = int((o == d).sum())
    zero = int((col["trip_seconds"] <= 0).sum())
    print(f"{same} trips snap pickup and drop-off to one node (demand and calibration leave "
          f"them out); {zero} have trip_seconds 0 (calibration leaves them out)")
    hour = np.array([int(r["trip_start_hour"]) for r in kept])
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "trips.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["hour", "day", "origin_node", "dest_node", "origin_snap_m", "dest_snap_m",
                    "trip_seconds", "pickup_community_area"])
        for k, r in enumerate(kept):
            w.writerow([hour[k], int(r["trip_start_day"]), int(ids[o[k]]), int(ids[d[k]]),
                        f"{so[k]:.1f}", f"{sd[k]:.1f}", int(float(r["trip_seconds"])),
                        r["pickup_community_area"].split(".")[0]])
    factors, trips, widths = calibrate(net, o, d, hour, col["trip_seconds"])
    with open(out / "congestion.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["hour", "factor", "trips", "pooled_hours"])
        for h in range(24):
            w.writerow([h, f"{factors[h]:.4f}", trips[h], widths[h]])
    print("congestion factors (hour: factor [trips, +-hours pooled]):")
    print("  " + ", ".join(f"{h}: {factors[h]:.2f}" + (f" [{trips[h]}, +-{widths[h]}]"
                                                       if widths[h] else f" [{trips[h]}]")
                           for h in range(24)))
    print(f"wrote {out / 'trips.csv'} ({len(kept)} rows) and {out / 'congestion.csv'}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT)
