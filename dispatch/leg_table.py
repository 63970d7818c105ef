"""Where a fleet's driving vehicles are at a decision, for all of them at once.

A decision on roads needs, for each candidate vehicle that drives a leg, the node it stands on
or drives to next and the seconds left to it (:meth:`dispatch.legs.Leg.next_at`). Asked leg by
leg that is a Python call per driving vehicle per decision, the largest part of building a
pooled decision's views (a thousand-vehicle fleet keeps a hundred or more driving with a free
seat). :class:`LegTable` keeps each vehicle's current leg as a row of arrays (rewritten when the
vehicle's leg is another object than the one its row was written from) and answers
:meth:`LegTable.where` for all the looked-at vehicles with numpy: the same comparisons and
subtractions on the same doubles as :meth:`Leg.next_at`, so the same answers.
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
        if driving:
            at = np.array(slots, dtype=np.int64)
            t = now - np.array(starts)
            times, nodes = self.times[at], self.nodes[at]
            rows = np.arange(at.size)
            last = self.length[at] - 1
            end = t >= times[rows, last]  # the leg is over: its last node
            t = np.where(t > 0.0, t, 0.0)
            i = (times <= t[:, None]).sum(axis=1)  # bisect_right (inf pads never count)
            first = i == 0  # still on the edge the leg started on
            j = np.where(first, 1, i) - 1
            exact = ~first & (t == times[rows, j])  # on node ``j`` at this instant
            nxt = np.minimum(i, last)
            left = times[rows, nxt] - t
            on = np.where(first, (self.prev[at] < 0) | (left <= 0.0), exact | (left <= 0.0))
            on |= end
            where = np.where(exact, nodes[rows, j], nodes[rows, nxt])
            where = np.where(end, nodes[rows, last], where)
            left = np.where(on, 0.0, left)
            k = np.array(looked, dtype=np.int64)[driving]
            node[k], rem[k] = where, left
            off[driving] = ~on
        return np.array(looked, dtype=np.int64)[off]
