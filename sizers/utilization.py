"""``utilization``: vehicles join and leave between ``min_vehicles`` and ``max_vehicles`` as
the recent utilisation (the share of on-duty vehicle-seconds spent on a plan since the last
look) leaves the band ``[low, high]``: above ``high`` the fleet grows, below ``low`` it
shrinks, each time to the size that would have run at ``target`` utilisation, by at most
``step`` vehicles per look (FleetPy's utilisation-based fleet control). A share of the
requests released since the last look left unserved above ``max_unserved`` grows the fleet
too (by ``1 / (1 - share)``, or to the utilisation's size if larger) and keeps it from
shrinking: with a wait limit, requests no vehicle reaches in time are rejected, and a fleet
too small for its demand can look little used."""

from __future__ import annotations

import math

from dispatch.api.sizer import Sizer, SizingView


class UtilizationSizer(Sizer):
    """Grow above ``high`` utilisation, shrink below ``low``, within the bounds."""

    name = "utilization"

    def __init__(self, min_vehicles: int = 1, max_vehicles: int | None = None,
                 interval: float = 900.0, low: float = 0.5, high: float = 0.8,
                 target: float | None = None, step: int | None = None,
                 max_unserved: float = 0.02) -> None:
        if int(min_vehicles) != min_vehicles or min_vehicles < 0:
            raise ValueError(f"min_vehicles must be a whole number >= 0, got {min_vehicles}")
        if max_vehicles is not None and (int(max_vehicles) != max_vehicles
                                         or max_vehicles < min_vehicles):
            raise ValueError(f"max_vehicles must be a whole number >= min_vehicles "
                             f"({min_vehicles}), got {max_vehicles}")
        if not interval > 0:
            raise ValueError(f"interval must be > 0 seconds, got {interval}")
        if not 0.0 <= low < high <= 1.0:
            raise ValueError(f"need 0 <= low < high <= 1, got low = {low}, high = {high}")
        target = (low + high) / 2 if target is None else target
        if not low <= target <= high:
            raise ValueError(f"target must lie in [low, high], got {target}")
        if step is not None and (int(step) != step or step < 1):
            raise ValueError(f"step must be a whole number >= 1, got {step}")
        self.min_vehicles, self.max_vehicles = int(min_vehicles), max_vehicles
        self.interval, self.low, self.high, self.target = float(interval), low, high, target
        self.step = None if step is None else int(step)
        if not 0.0 <= max_unserved < 1.0:
            raise ValueError(f"max_unserved must lie in [0, 1), got {max_unserved}")
        self.max_unserved = float(max_unserved)

    def _bounded(self, n: int, view: SizingView) -> int:
        top = view.on_duty + view.pool
        if self.max_vehicles is not None:
            top = min(top, int(self.max_vehicles))
        return max(min(n, top), min(self.min_vehicles, view.on_duty + view.pool))

    def initial(self, view: SizingView) -> int:
        return self._bounded(self.min_vehicles, view)

    def size(self, view: SizingView) -> int:
        u, n, miss = view.utilization, view.on_duty, view.unserved
        short = miss == miss and miss > self.max_unserved
        if not short and (u != u or self.low <= u <= self.high):
            return self._bounded(n, view)
        want = math.ceil(n * u / self.target) if n and u == u else self.min_vehicles + 1
        if short:  # (every request unserved: as many as the bounds allow)
            grow = math.ceil(max(n, 1) / (1.0 - miss)) if miss < 1.0 else view.on_duty + view.pool
            want = max(want, grow, n + 1)
        if self.step is not None:
            want = max(n - self.step, min(n + self.step, want))
        return self._bounded(want, view)
