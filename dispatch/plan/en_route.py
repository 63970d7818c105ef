"""Where a fleet's driving vehicles are at a decision, for all of them at once.

A decision on roads needs, for each candidate vehicle that drives a leg, the node it stands on
or drives to next and the seconds left to it (:meth:`dispatch.api.legs.Leg.next_at`). Asked leg by
leg that is a Python call per driving vehicle per decision, the largest part of building a
pooled decision's views (a thousand-vehicle fleet keeps a hundred or more driving with a free
seat). :class:`LegTable` keeps each vehicle's current leg as a row of arrays (rewritten when the
vehicle's leg was set since the row was written: a version the fleet keeps) and answers
:meth:`LegTable.where` for all the looked-at vehicles in one compiled loop
(:func:`dispatch._compiled.legs_at`): the same comparisons and subtractions on the same
doubles as :meth:`Leg.next_at`, so the same answers.
"""

from __future__ import annotations

import numpy as np


class LegTable:
    """The legs of a fleet's vehicles, one row per fleet position: cumulative seconds (``inf``
    past the leg's end), nodes, the start point's ``prev``, the leg's length and its start
    time.

    The fleet keeps two arrays the table reads (updated by a vehicle's ``leg`` setter):
    ``driving`` (it has a leg) and ``version`` (bumped at every leg set). A row is written
    at a decision that looks at the vehicle when its version is not the one the row was written
    at, so a decision costs no Python step for the vehicles whose legs it already holds."""

    def __init__(self, n: int, driving: np.ndarray, version: np.ndarray,
                 width: int = 16) -> None:
        self.driving, self.version = driving, version
        self._written = np.full(n, -1, dtype=np.int64)  # the version each row was written at
        self.start = np.zeros(n)
        self.prev = np.full(n, -1, dtype=np.int64)
        self.length = np.ones(n, dtype=np.int64)
        self.width = width
        self.times = np.full((n, width), np.inf)
        self.nodes = np.zeros((n, width), dtype=np.int64)

    def _write(self, k: int, v) -> None:
        leg = v._leg
        times = leg.times
        n = len(times)
        if n > self.width:
            width = max(n, 2 * self.width)
            size = self.times.shape[0]
            grown = np.full((size, width), np.inf)
            grown[:, :self.width] = self.times
            nodes = np.zeros((size, width), dtype=np.int64)
            nodes[:, :self.width] = self.nodes
            self.times, self.nodes, self.width = grown, nodes, width
        row = self.times[k]
        row[:n] = times
        row[n:] = np.inf
        self.nodes[k, :n] = leg.nodes
        self.prev[k] = leg.prev
        self.length[k] = n
        self.start[k] = v.leg_start
        self._written[k] = self.version[k]

    def where(self, vehicles: list, idx: np.ndarray, looked: np.ndarray, node: np.ndarray,
              rem: np.ndarray, now: float, *, stands) -> np.ndarray:
        """For the vehicles at fleet positions ``idx[k]``, ``k`` in ``looked`` (ascending; each
        driving a leg or stopped off a node): write where each is at ``now`` into ``node[k]``
        and ``rem[k]`` (a driving one: :meth:`dispatch.api.legs.Leg.next_at` of its leg at ``now``
        less its start; a stopped one: ``stands(loc)``, the space's answer) and return the
        ``k`` of those part-way along an edge, ascending."""
        looked = np.asarray(looked, dtype=np.int64)
        slots = idx[looked]
        drives = self.driving[slots]
        off = np.zeros(looked.size, dtype=bool)
        if not drives.all():  # stopped part-way along an edge (or off the nodes)
            for i in (~drives).nonzero()[0].tolist():
                k = int(looked[i])
                node[k], rem[k], off[i] = stands(vehicles[int(slots[i])].loc)
        d = drives.nonzero()[0]
        if d.size:
            from dispatch._compiled import legs_at

            ds = slots[d]
            stale = ds[self._written[ds] != self.version[ds]]
            for s in stale.tolist():  # (legs set since the row was written)
                self._write(s, vehicles[s])
            on = np.ones(looked.size, dtype=bool)
            legs_at(self.times, self.nodes, self.length, self.prev, ds, float(now),
                    self.start[ds], looked[d], node, rem, d, on)
            off[d] = ~on[d]
        return looked[off]
