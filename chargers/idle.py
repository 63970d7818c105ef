"""``idle``: charge opportunistically. An idle vehicle below ``high`` within ``radius`` drive
seconds of a station with a free plug goes there and charges to ``high``; below ``low`` it
goes to the station of least drive + queue time wherever it is (``threshold``'s rule)."""

from __future__ import annotations

import numpy as np

from chargers.threshold import _check
from dispatch.api.charger import ChargingStrategy, ChargingView


class IdleCharging(ChargingStrategy):
    """Charge when idle near a station with a free plug; below ``low`` anywhere."""

    name = "idle"

    def __init__(self, low: float = 0.2, high: float = 0.8, radius: float = 300.0) -> None:
        _check(low, high)
        if not radius >= 0:
            raise ValueError(f"radius must be >= 0 seconds, got {radius}")
        self.low, self.high, self.radius = float(low), float(high), float(radius)

    def decide(self, view: ChargingView) -> dict:
        out = {}
        low = np.flatnonzero(view.soc < self.low)
        low = low[np.argsort(view.soc[low], kind="stable")]  # the lowest first
        for r, s in zip(low.tolist(), view.best_station(low, self.high).tolist()):
            out[int(view.vehicle_ids[r])] = (view.station_ids[int(s)], self.high)
        rows = np.flatnonzero((view.soc >= self.low) & (view.soc < self.high - 0.05))
        if rows.size:
            free = (view.plugs - view.in_use).astype(np.int64)
            t = view.travel_times(rows)
            order = np.argsort(t.min(axis=1), kind="stable")
            for k in order.tolist():  # nearest first; no more than the free plugs
                ok = np.flatnonzero((t[k] <= self.radius) & (free > 0))
                if ok.size:
                    s = int(ok[np.argmin(t[k, ok])])
                    free[s] -= 1
                    out[int(view.vehicle_ids[rows[k]])] = (view.station_ids[s], self.high)
        return out
