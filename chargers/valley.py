"""``valley``: plan charging against the hourly demand. While the requests of the last full
hour are below ``valley`` times the mean hourly count so far (a demand valley: nights,
mid-mornings), idle vehicles below ``high`` charge to ``high`` at the station of least drive +
queue time, at most ``share`` of the idle vehicles at once and no more than the plugs free
(not taken, nobody queueing), lowest state of charge first; otherwise only those below ``low``
go (``threshold``'s rule). The demand is the run's own, as released so far."""

from __future__ import annotations

import numpy as np

from chargers.threshold import _check
from dispatch.api.charger import ChargingStrategy, ChargingView


class ValleyCharging(ChargingStrategy):
    """Charge to ``high`` in the demand valleys, only below ``low`` at the peaks."""

    name = "valley"

    def __init__(self, low: float = 0.2, high: float = 0.9, valley: float = 0.8,
                 share: float = 0.5) -> None:
        _check(low, high)
        if not valley > 0 or not 0 < share <= 1:
            raise ValueError(f"want valley > 0 and 0 < share <= 1, got {valley}, {share}")
        self.low, self.high, self.valley, self.share = map(float, (low, high, valley, share))

    def in_valley(self, view: ChargingView) -> bool:
        hour = int(view.time // 3600)
        seen = view.released_by_hour[:hour]  # the full hours so far
        if seen.size == 0:
            return True
        last = seen[-1]
        return bool(last < self.valley * seen.mean())

    def decide(self, view: ChargingView) -> dict:
        if self.in_valley(view):
            rows = np.flatnonzero(view.soc < self.high - 0.05)
            rows = rows[np.argsort(view.soc[rows], kind="stable")]
            free = int(np.maximum(view.plugs - view.in_use - view.waiting, 0).sum())
            rows = rows[:min(max(1, int(self.share * view.n_vehicles)), free)]
            rows = np.union1d(rows, np.flatnonzero(view.soc < self.low))
        else:
            rows = np.flatnonzero(view.soc < self.low)
        rows = rows[np.argsort(view.soc[rows], kind="stable")]  # the lowest first
        best = view.best_station(rows, self.high)
        return {int(view.vehicle_ids[r]): (view.station_ids[int(s)], self.high)
                for r, s in zip(rows.tolist(), best.tolist())}
