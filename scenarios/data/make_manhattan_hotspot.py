"""Regenerates manhattan_hotspot_trips.csv and manhattan_hotspot_fleet.csv (seeded; run from
this folder).

Trips: a Poisson stream of 0.1 requests/s over 2 h on the 20 x 20 grid of manhattan.toml; half
the pickups fall in the hotspot, the 5 x 5 intersections of the lower-left corner (nodes
row * 20 + column, row and column < 5), the others uniform; destinations uniform (!= origin).
Fleet: 80 taxis on uniformly drawn intersections. (benchmarks/reposition.py draws the same
kind of day for several seeds.)
"""

import csv

import numpy as np

rng = np.random.default_rng(2026)
nodes, t, rows = 400, 0.0, []
corner = np.array([r * 20 + c for r in range(5) for c in range(5)])
while True:
    t += rng.exponential(10.0)
    if t > 7200:
        break
    o = int(rng.choice(corner)) if rng.random() < 0.5 else int(rng.integers(nodes))
    d = int(rng.integers(nodes - 1))
    d += d >= o
    rows.append((round(t, 3), o, d))
with open("manhattan_hotspot_trips.csv", "w", newline="") as fh:
    w = csv.writer(fh)
    w.writerow(["t", "origin_node", "dest_node"])
    w.writerows(rows)
with open("manhattan_hotspot_fleet.csv", "w", newline="") as fh:
    w = csv.writer(fh)
    w.writerow(["vehicle_id", "node"])
    w.writerows((i, int(n)) for i, n in enumerate(rng.integers(nodes, size=80)))
