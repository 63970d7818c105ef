"""The empirical taxi day (``[tasks] source = "empirical"``): a day of trips drawn from the
Chicago taxi sample shipped in ``dispatch/data/chicago_taxi`` (see its NOTICE.md).

The sample is 14,518 real trips spread over 2013-2016, not one day, so it is used as what it
is: an origin-destination distribution with an hour-of-day (and weekday) profile. A day is
drawn as follows, every draw from the generator given:

* the **trips used**: those whose pickup and drop-off snap to different network nodes (12,937
  of 14,518; the rest would be zero-length rides), of the chosen ``weekday`` (``"all"``: every
  day of the week; the data's ``trip_start_day`` is 1 = Sunday .. 7 = Saturday);
* the **profile**: ``n_h`` used trips start in hour ``h``; hour ``h`` of the day gets a Poisson
  number of trips with mean ``trips_per_day x n_h / sum(n)``, so the day's expected total is
  ``trips_per_day`` and its hourly shape is the sample's;
* each trip's **origin and destination** are one used trip of that hour drawn uniformly, as a
  pair (so the OD joint distribution of the hour is kept). An hour with fewer than
  ``MIN_POOL`` used trips (a single weekday at night) draws from hours ``h-1..h+1``, then
  ``h-2..h+2``, ... (circularly) until the pool has ``MIN_POOL``;
* **release times** are uniform within the hour (the sample's times are rounded to 15 min).

The day is handed to the run as a trace of node ids (:class:`dispatch.files.traces.Trips`), so it is
released, recorded and served exactly like a trace. :func:`pickup_weights` gives the fleet's
``placement = "demand"`` start nodes: the sample's pickup nodes weighted by their trips.
"""

from __future__ import annotations

import csv
import functools
import importlib.resources
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dispatch.files.hourly import HOURS, HourlyFactors
from dispatch.files.traces import Trips

#: weekday names in the data's order (trip_start_day 1 = Sunday .. 7 = Saturday)
WEEKDAYS = ("sunday", "monday", "tuesday", "wednesday", "thursday", "friday", "saturday")
#: fewest sample trips an hour's OD draw uses before neighbouring hours are pooled in
MIN_POOL = 30
SAMPLES = ("chicago_taxi",)
_DIR = "data/chicago_taxi"


@dataclass(frozen=True, eq=False)
class TaxiSample:
    """The shipped sample, one entry per trip (see ``data/chicago_taxi/NOTICE.md``)."""

    hour: np.ndarray  # 0..23
    day: np.ndarray  # 1 = Sunday .. 7 = Saturday
    origin: np.ndarray  # network node ids (TNTP numbers)
    dest: np.ndarray
    origin_snap_m: np.ndarray
    dest_snap_m: np.ndarray
    trip_seconds: np.ndarray
    area: np.ndarray  # pickup community area (0: unknown)

    def __len__(self) -> int:
        return len(self.hour)

    def used(self, weekday: str = "all") -> np.ndarray:
        """Indices of the trips a day draws from (different end nodes; ``weekday``'s)."""
        keep = self.origin != self.dest
        if weekday != "all":
            keep &= self.day == WEEKDAYS.index(weekday) + 1
        return np.flatnonzero(keep)

    def profile(self, weekday: str = "all") -> np.ndarray:
        """The 24 counts ``n_h`` of used trips per start hour."""
        return np.bincount(self.hour[self.used(weekday)], minlength=HOURS)


def _data(name: str) -> Path:
    return Path(str(importlib.resources.files("dispatch") / _DIR / name))


@functools.lru_cache(maxsize=1)
def load_sample() -> TaxiSample:
    """The shipped Chicago taxi sample (read once per process)."""
    with open(_data("trips.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))

    def col(k, dtype=np.int64):
        a = np.array([r[k] or 0 for r in rows], dtype=dtype)
        a.setflags(write=False)
        return a

    return TaxiSample(col("hour"), col("day"), col("origin_node"), col("dest_node"),
                      col("origin_snap_m", np.float64), col("dest_snap_m", np.float64),
                      col("trip_seconds", np.float64), col("pickup_community_area"))


@functools.lru_cache(maxsize=1)
def load_factors() -> HourlyFactors:
    """The 24 hourly congestion factors calibrated from the sample (``congestion.csv``)."""
    with open(_data("congestion.csv"), newline="") as fh:
        rows = sorted(csv.DictReader(fh), key=lambda r: int(r["hour"]))
    return HourlyFactors(tuple(float(r["factor"]) for r in rows))


def hour_pools(sample: TaxiSample, weekday: str = "all",
               min_pool: int = MIN_POOL) -> list[np.ndarray]:
    """Per hour of day, the indices of the sample trips its OD pairs are drawn from."""
    used = sample.used(weekday)
    hour = sample.hour[used]
    pools = []
    for h in range(HOURS):
        for w in range(HOURS // 2 + 1):
            near = np.minimum((hour - h) % HOURS, (h - hour) % HOURS) <= w
            if near.sum() >= min_pool:
                break
        pools.append(used[near])
    return pools


def draw_day(sample: TaxiSample, trips_per_day: float, rng: np.random.Generator,
             weekday: str = "all") -> Trips:
    """A day of trips (see the module docstring): release times in ``[0, 86400)`` s, sorted;
    origin and destination as network node ids; ``max_wait`` nan (the scenario's applies)."""
    n_h = sample.profile(weekday)
    counts = rng.poisson(trips_per_day * n_h / n_h.sum())
    pools = hour_pools(sample, weekday)
    t = np.empty(int(counts.sum()))
    pick = np.empty(t.size, np.int64)
    at = 0
    for h in range(HOURS):
        k = int(counts[h])
        pick[at:at + k] = pools[h][rng.integers(len(pools[h]), size=k)]
        t[at:at + k] = 3600.0 * (h + rng.random(k))
        at += k
    order = np.argsort(t, kind="stable")
    t, pick = t[order], pick[order]
    return Trips(path=Path(f"<{SAMPLES[0]} day, {trips_per_day:g} trips/day, {weekday}>"),
                 layout="node", t=t, origin=sample.origin[pick][:, None].astype(np.float64),
                 dest=sample.dest[pick][:, None].astype(np.float64),
                 max_wait=np.full(t.size, math.nan), row=np.arange(1, t.size + 1))


def pickup_weights(sample: TaxiSample, weekday: str = "all") -> tuple[np.ndarray, np.ndarray]:
    """``(node ids, probabilities)``: the used trips' pickup nodes and their shares."""
    nodes, counts = np.unique(sample.origin[sample.used(weekday)], return_counts=True)
    return nodes, counts / counts.sum()
