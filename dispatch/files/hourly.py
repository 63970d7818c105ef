"""Congestion's data: a factor per hour of the day, and its calibration from observed trips.

With congestion on (``[world] congestion``), a drive that starts at simulated time ``t`` takes
``factor(t)`` times its free-flow time, ``factor(t) = factors[floor(t / 3600) mod 24]`` (the run
starts at midnight); :class:`HourlyFactors` holds the 24 factors. How a run applies them (the
planner's costs, the vehicles' legs) is :mod:`dispatch.space.congestion`'s.

:func:`calibrate` estimates the 24 factors from observed trips: the ratio of each trip's
observed seconds to the network's free-flow shortest-path time between its snapped pickup and
drop-off nodes, robustly (the median) per hour of day; an hour with fewer than ``min_trips``
usable trips is pooled with its neighbours (hours h-1..h+1, then h-2..h+2, ..., circularly)
until the pool has enough. ``dispatch/data/chicago_taxi/congestion.csv`` holds the factors
calibrated from the Chicago taxi sample (``scripts/make_chicago_taxi.py`` writes it;
:func:`dispatch.files.empirical.load_factors` reads it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

HOURS = 24
#: Fewest usable trips behind one hour's factor before neighbouring hours are pooled in.
MIN_TRIPS = 200


@dataclass(frozen=True)
class HourlyFactors:
    """24 positive factors, one per hour of day (index 0: 00:00-01:00)."""

    factors: tuple[float, ...]

    def __post_init__(self) -> None:
        f = self.factors
        if len(f) != HOURS or any(not (math.isfinite(x) and x > 0) for x in f):
            raise ValueError(f"congestion needs {HOURS} finite factors > 0, got {list(f)!r}")

    def factor(self, t: float) -> float:
        """The factor of the hour of day that simulated time ``t`` (seconds) falls in."""
        return self.factors[math.floor(t / 3600.0) % HOURS]


NO_CONGESTION = HourlyFactors((1.0,) * HOURS)


def free_flow_times(net: Any, origin: np.ndarray, dest: np.ndarray) -> np.ndarray:
    """Free-flow shortest-path seconds from node index ``origin[k]`` to ``dest[k]`` (one
    Dijkstra per distinct origin)."""
    origin, dest = np.asarray(origin, np.int64), np.asarray(dest, np.int64)
    src, inv = np.unique(origin, return_inverse=True)
    return net.distances_from(src)[inv, dest] if src.size else np.zeros(0)


def calibrate(net: Any, origin: np.ndarray, dest: np.ndarray, hour: np.ndarray,
              seconds: np.ndarray, min_trips: int = MIN_TRIPS
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per hour of day: ``(factors, trips, widths)``: the median of observed / free-flow seconds
    over the trips of that hour (pooled with hours within ``widths[h]`` of it when the hour
    alone has fewer than ``min_trips``), and how many trips the median was taken over.

    Trips with ``origin == dest`` (no drive on the network) or ``seconds <= 0`` (not a
    measured ride) are left out. ``origin``, ``dest`` are node indices; ``hour`` in 0..23.
    ValueError when fewer than ``min_trips`` usable trips exist in the whole day."""
    origin, dest = np.asarray(origin, np.int64), np.asarray(dest, np.int64)
    hour, seconds = np.asarray(hour, np.int64), np.asarray(seconds, np.float64)
    use = (origin != dest) & (seconds > 0)
    ratio = seconds[use] / free_flow_times(net, origin[use], dest[use])
    hour = hour[use]
    if ratio.size < max(min_trips, 1):
        raise ValueError(f"calibrate: {ratio.size} usable trips, need at least {min_trips}")
    factors, trips, widths = np.empty(HOURS), np.empty(HOURS, np.int64), np.empty(HOURS, np.int64)
    for h in range(HOURS):
        for w in range(HOURS // 2 + 1):
            near = np.minimum((hour - h) % HOURS, (h - hour) % HOURS) <= w
            if near.sum() >= min_trips:
                break
        factors[h], trips[h], widths[h] = float(np.median(ratio[near])), int(near.sum()), w
    return factors, trips, widths
