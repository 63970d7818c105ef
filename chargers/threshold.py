"""``threshold``: below ``low`` (state of charge) an idle vehicle goes to the station of least
drive + queue time and charges to ``high``."""

from __future__ import annotations

import numpy as np

from dispatch.api.charger import ChargingStrategy, ChargingView


def _check(low: float, high: float) -> None:
    if not 0.0 <= low < high <= 1.0:
        raise ValueError(f"want 0 <= low < high <= 1, got low = {low}, high = {high}")


class ThresholdCharging(ChargingStrategy):
    """Below ``low`` go charging at the station of least drive + queue time, up to ``high``."""

    name = "threshold"

    def __init__(self, low: float = 0.2, high: float = 0.8) -> None:
        _check(low, high)
        self.low, self.high = float(low), float(high)

    def decide(self, view: ChargingView) -> dict:
        rows = np.flatnonzero(view.soc < self.low)
        rows = rows[np.argsort(view.soc[rows], kind="stable")]  # the lowest first
        best = view.best_station(rows, self.high)
        return {int(view.vehicle_ids[r]): (view.station_ids[int(s)], self.high)
                for r, s in zip(rows.tolist(), best.tolist())}
