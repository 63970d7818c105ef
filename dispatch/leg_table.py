"""Where a fleet's driving vehicles are at a decision, for all of them at once.

A decision on roads needs, for each candidate vehicle that drives a leg, the node it stands on
or drives to next and the seconds left to it (:meth:`dispatch.legs.Leg.next_at`). Asked leg by
leg that is a Python call per driving vehicle per decision, the largest part of building a
pooled decision's views (a thousand-vehicle fleet keeps a hundred or more driving with a free
seat). :class:`LegTable` keeps each vehicle's current leg as a row of arrays (rewritten when the
vehicle's leg is another object than the one its row was written from) and answers
:meth:`LegTable.where` for all the looked-at vehicles in one compiled loop
(:func:`dispatch._compiled.legs_at`): the same comparisons and subtractions on the same
doubles as :meth:`Leg.next_at`, so the same answers.
"""

from __future__ import annotations

import numpy as np


class LegTable:
    """The legs of a fleet's vehicles, one row per fleet position: cumulative seconds (``inf``
    past the leg's end), nodes, the start point's ``prev`` and the leg's length."""

    def __init__(self, n: int, width: int = 16) -> None:
        self._src: list = [None] * n  # the leg each row was written from
        self.prev = np.full(n, -1, dtype=np.int64)
        self.length = np.ones(n, dtype=np.int64)
        self.width = width
        self.times = np.full((n, width), np.inf)
        self.nodes = np.zeros((n, width), dtype=np.int64)

    def _write(self, k: int, leg) -> None:
        times = leg.times
        n = len(times)
        if n > self.width:
            width = max(n, 2 * self.width)
            grown = np.full((len(self._src), width), np.inf)
            grown[:, :self.width] = self.times
            nodes = np.zeros((len(self._src), width), dtype=np.int64)
            nodes[:, :self.width] = self.nodes
            self.times, self.nodes, self.width = grown, nodes, width
        row = self.times[k]
        row[:n] = times
        row[n:] = np.inf
        self.nodes[k, :n] = leg.nodes
        self.prev[k] = leg.prev
        self.length[k] = n
        self._src[k] = leg

    def where(self, vehicles: list, idx: np.ndarray, looked: list[int], node: np.ndarray,
              rem: np.ndarray, now: float, stands) -> np.ndarray:
        """For the vehicles at fleet positions ``idx[k]``, ``k`` in ``looked`` (each driving a
        leg or stopped off a node): write where each is at ``now`` into ``node[k]`` and
        ``rem[k]`` (a driving one: :meth:`dispatch.legs.Leg.next_at` of its leg at ``now`` less
        its start; a stopped one: ``stands(loc)``, the space's answer) and return the ``k``
        of those part-way along an edge, ascending."""
        src = self._src
        slots = idx[looked].tolist() if looked else []
        vs = [vehicles[s] for s in slots]
        legs = [v._leg for v in vs]
        off = np.zeros(len(looked), dtype=bool)
        driving = list(range(len(looked)))
        stopped = [i for i, leg in enumerate(legs) if leg is None]
        if stopped:  # stopped part-way along an edge (or off the nodes)
            for i in stopped:
                k = looked[i]
                node[k], rem[k], off[i] = stands(vs[i].loc)
            driving = [i for i in driving if legs[i] is not None]
            vs, slots, legs = ([x[i] for i in driving] for x in (vs, slots, legs))
        for s, leg in zip(slots, legs):
            if leg is not src[s]:
                self._write(s, leg)
        starts = [v.leg_start for v in vs]
        looked_at = np.array(looked, dtype=np.int64)
        if driving:
            from dispatch._compiled import legs_at

            on = np.ones(len(looked), dtype=bool)
            d = np.array(driving, dtype=np.int64)
            legs_at(self.times, self.nodes, self.length, self.prev,
                    np.array(slots, dtype=np.int64), float(now), np.array(starts, dtype=float),
                    looked_at[d], node, rem, d, on)
            off[d] = ~on[d]
        return looked_at[off]
