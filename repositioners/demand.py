"""The ``demand`` repositioner: idle vehicles drive toward zones whose recent demand exceeds
their idle supply.

Zones are the cells of a regular grid of ``zone`` metres over the network's node coordinates
(:class:`learning.zones.Zones`); a vehicle sent to a zone drives to its centre node (the
node nearest the mean position of the zone's nodes). At each call (every ``[reposition]
interval`` seconds):

1. demand ``d[z]``: requests released in zone ``z`` in the last ``[reposition] horizon``
   seconds (their pickups); nothing moves when there were none;
2. idle supply ``s[z]``: idle vehicles in ``z``, a vehicle already repositioning counted in
   its target's zone;
3. the share of the ``S`` idle vehicles each zone should hold, proportional to its demand:
   ``S d[z] / sum(d)`` rounded to whole vehicles by largest remainder (ties: lower zone);
4. surplus ``s[z] - share[z]`` (only vehicles standing still may move) and deficit
   ``share[z] - s[z]``; ``k = min(surplus, deficit, max_moves)`` vehicles move;
5. the ``k`` deficit slots with the largest gap (the ``j``-th missing vehicle of zone ``z``
   has gap ``deficit[z] - j``; ties: lower zone) are filled by a minimum-total-travel-time
   assignment (:func:`scipy.optimize.linear_sum_assignment`) of the surplus zones' standing
   vehicles, in which each surplus zone keeps its share (zero-cost "stay" columns that only
   its own vehicles may fill), so no zone gives away more than its surplus.

With a learned ``value`` (a file of ``dispatch train value``, :mod:`learning.value`), step 3
splits the idle vehicles by a mix of demand and value: zone ``z``'s weight is ``(1 - value_mix)
d[z] / sum(d) + value_mix v[z] / sum(v)``, with ``v[z]`` the value now of a vehicle at the
zone's centre node (negative values counted as 0), so idle vehicles are also moved toward
where the value says a vehicle will serve more, not only where requests came lately. A value
that is zero everywhere (or ``value_mix = 0``) moves exactly as without one.

Deterministic: no randomness is drawn.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy.optimize import linear_sum_assignment

from dispatch.api.repositioner import Repositioner, RepositionView
from learning.zones import Zones


def shares(total: int, weights: np.ndarray) -> np.ndarray:
    """``total`` whole units split in proportion to ``weights`` (>= 0, positive sum) by largest
    remainder; ties go to the lower index."""
    quota = total * weights / weights.sum()
    out = np.floor(quota).astype(np.int64)
    left = int(total - out.sum())
    if left:
        out[np.lexsort((np.arange(weights.size), -(quota - out)))[:left]] += 1
    return out


class DemandRepositioner(Repositioner):
    """Idle vehicles drive toward grid zones whose recent demand exceeds their idle supply."""

    name = "demand"
    spaces = ("road",)

    def __init__(self, zone: float = 1000.0, max_moves: int = 20, value: str | None = None,
                 value_mix: float = 0.5) -> None:
        if isinstance(zone, bool) or not isinstance(zone, (int, float)) \
                or not math.isfinite(zone) or zone <= 0:
            raise ValueError(f"zone must be a number of metres > 0, got {zone!r}")
        if isinstance(max_moves, bool) or not isinstance(max_moves, int) or max_moves < 1:
            raise ValueError(f"max_moves must be an integer >= 1, got {max_moves!r}")
        self.zone, self.max_moves = float(zone), max_moves
        if isinstance(value_mix, bool) or not isinstance(value_mix, (int, float)) \
                or not 0.0 <= value_mix <= 1.0:
            raise ValueError(f"value_mix must be a number in [0, 1], got {value_mix!r}")
        self.value_mix = float(value_mix)
        self.value = None
        if value is not None:
            from learning.value import ZoneValue

            self.value = ZoneValue.load(value)
        self._net = None
        self._zones: Zones | None = None

    def zones(self, space) -> Zones:
        """The zones of ``space`` (computed once per network)."""
        if self._net is not space or self._zones is None:
            self._zones, self._net = Zones(space.xy, self.zone), space
        return self._zones

    def weights(self, view: RepositionView, zones: Zones, demand: np.ndarray) -> np.ndarray:
        """Each zone's weight in the split of the idle vehicles: its demand, mixed with the
        value of its centre node now where there is a value (module doc)."""
        d = demand.astype(np.float64)
        if self.value is None or self.value_mix == 0.0:
            return d
        from dispatch.api.value import check_network

        check_network(self.value, view.space.xy, f"the demand repositioner's value "
                      f"{self.value.meta.get('file', '')}")
        centre = zones.centre_nodes
        v = np.zeros(zones.n)
        has = centre >= 0
        v[has] = np.maximum(self.value.value(centre[has], np.full(has.sum(), view.time)), 0.0)
        if not v.sum() > 0:  # a value of zero: demand alone, exactly
            return d
        return (1.0 - self.value_mix) * d / d.sum() + self.value_mix * v / v.sum()

    def reposition(self, view: RepositionView) -> Mapping[int, int]:
        """The moves of one call (see the module docstring)."""
        zones = self.zones(view.space)
        nz = zones.n
        demand = np.bincount(zones.of_node[view.request_nodes], minlength=nz)
        if view.n_vehicles == 0 or demand.sum() == 0:
            return {}
        vz = zones.of_node[np.where(view.moving, view.targets, view.nodes)]
        still = ~view.moving
        supply = np.bincount(vz, minlength=nz)
        share = shares(view.n_vehicles, self.weights(view, zones, demand))
        movable = np.bincount(vz[still], minlength=nz)
        surplus = np.minimum(np.maximum(supply - share, 0), movable)
        deficit = np.maximum(share - supply, 0)
        k = int(min(surplus.sum(), deficit.sum(), self.max_moves))
        if k == 0:
            return {}
        slot_zone = np.repeat(np.arange(nz), deficit)
        rank = np.arange(slot_zone.size) - np.repeat(np.cumsum(deficit) - deficit, deficit)
        slot_zone = slot_zone[np.lexsort((slot_zone, -(deficit[slot_zone] - rank)))[:k]]
        rows = np.flatnonzero(still & (surplus[vz] > 0))
        times = view.travel_times(rows, zones.centre_nodes[slot_zone])
        keep = np.repeat(np.flatnonzero(surplus), (movable - surplus)[surplus > 0])
        finite = times[np.isfinite(times)]
        big = (float(finite.max()) + 1.0 if finite.size else 1.0) * (k + keep.size + 1)
        cost = np.hstack([np.where(np.isfinite(times), times, big),
                          np.where(vz[rows][:, None] == keep[None, :], 0.0, big)])
        r, c = linear_sum_assignment(cost)
        return {int(view.vehicle_ids[rows[i]]): int(zones.centre_nodes[slot_zone[j]])
                for i, j in zip(r, c) if j < k and cost[i, j] < big}
