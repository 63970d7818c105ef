"""Regenerates manhattan_trips.csv and manhattan_fleet.csv (seeded; run from this folder).

Trips: a Poisson stream of 0.1 requests/s over 2 h, origin and destination uniform over the
400 intersections of the 20 x 20 grid (destination != origin); every tenth request is willing to
wait only 5 min (a per-row max_wait). Fleet: 50 taxis on uniformly drawn intersections.
"""

import csv

import numpy as np

rng = np.random.default_rng(2026)
nodes, t, rows = 400, 0.0, []
while True:
    t += rng.exponential(10.0)
    if t > 7200:
        break
    o = int(rng.integers(nodes))
    d = int(rng.integers(nodes - 1))
    d += d >= o
    rows.append((round(t, 3), o, d, 300.0 if len(rows) % 10 == 9 else ""))
with open("manhattan_trips.csv", "w", newline="") as fh:
    w = csv.writer(fh)
    w.writerow(["t", "origin_node", "dest_node", "max_wait"])
    w.writerows(rows)
with open("manhattan_fleet.csv", "w", newline="") as fh:
    w = csv.writer(fh)
    w.writerow(["vehicle_id", "node"])
    w.writerows((i, int(n)) for i, n in enumerate(rng.integers(nodes, size=50)))
