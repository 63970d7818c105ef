"""The edges of a road network looked up by their ends, and the legs driven along them.

:class:`EdgeTable` holds a network's edges in CSR order (its ``time`` and ``length`` matrices:
rows by tail node, columns by head node, sorted). A leg's cumulative seconds and metres are the
edges' values added one by one in path order (as ``itertools.accumulate`` and ``numpy.cumsum``
do), by the compiled :func:`dispatch._compiled.leg_sums` where the two matrices share one
canonical pattern, else in Python: the same floats bit for bit either way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property
from itertools import accumulate

import numpy as np
from scipy.sparse import csr_matrix

from dispatch.api.legs import Leg, RoadPoint
from dispatch.api.legs import as_point as _as_point


class EdgeTable:
    """The edges of the ``n``-node network ``name`` whose ``n x n`` CSR matrices ``time``
    (seconds) and ``length`` (metres) have one entry per edge ``u -> v``; read-only."""

    def __init__(self, name: str, n: int, time: csr_matrix, length: csr_matrix) -> None:
        self.name, self.n, self.time, self.length = name, n, time, length

    @cached_property
    def _keys(self) -> np.ndarray:
        """``u * n + v`` of every edge in CSR order (sorted): edge lookup by searchsorted."""
        rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.time.indptr))
        keys = rows * self.n + self.time.indices
        keys.setflags(write=False)
        return keys

    @cached_property
    def edge_lists(self) -> tuple[list[float], list[float]]:
        """Edge seconds and metres as Python lists, in CSR order."""
        return self.time.data.tolist(), self.length.data.tolist()

    @cached_property
    def leg_sums(self):
        """The compiled :func:`dispatch._compiled.leg_sums` where ``time`` and ``length`` share
        one canonical sparsity pattern (sorted, no duplicate edges: each step has one edge), else
        None (legs are summed in Python)."""
        t, m = self.time, self.length
        if not (np.array_equal(t.indptr, m.indptr) and np.array_equal(t.indices, m.indices)
                and bool((np.diff(self._keys) > 0).all())):
            return None
        from dispatch._compiled import leg_sums

        return leg_sums

    @cached_property
    def _leg_csr(self) -> tuple[np.ndarray, ...]:
        """``(indptr, indices, seconds, metres)`` for :attr:`leg_sums`: private writable copies
        (numba's call is cheaper with writable arrays; nothing writes to them)."""
        t = self.time
        return t.indptr.copy(), t.indices.copy(), t.data.copy(), self.length.data.copy()

    @cached_property
    def edge_of(self) -> dict[int, int]:
        """``u * n + v`` -> CSR data index of the edge ``u -> v`` (paths are looked up here)."""
        return dict(zip(self._keys.tolist(), range(self._keys.size)))

    def index(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """CSR data index of each edge ``u[k] -> v[k]``; ValueError naming the first non-edge."""
        u, v = np.asarray(u, dtype=np.int64), np.asarray(v, dtype=np.int64)
        keys = self._keys
        if u.size and keys.size:  # fast path: every pair an edge (a planner's path)
            lo, hi = min(u.min(), v.min()), max(u.max(), v.max())
            if lo >= 0 and hi < self.n:
                key = u * self.n + v
                k = keys.searchsorted(key)
                if k.max() < keys.size and (keys[k] == key).all():
                    return k
        ok = (u >= 0) & (u < self.n) & (v >= 0) & (v < self.n)
        key = np.where(ok, u * self.n + v, -1)
        k = np.minimum(np.searchsorted(self._keys, key), max(self._keys.size - 1, 0))
        found = ok & (self._keys.size > 0)
        if self._keys.size:
            found &= self._keys[k] == key
        if not found.all():
            bad = int(np.flatnonzero(~found)[0])
            raise ValueError(f"road network {self.name!r}: no edge {int(u[bad])} -> {int(v[bad])}")
        return k

    def edge(self, u: int, v: int) -> tuple[float, float]:
        """``(seconds, metres)`` of the edge ``u -> v``; ValueError if there is none."""
        k = int(self.index(np.array([u]), np.array([v]))[0])
        return float(self.time.data[k]), float(self.length.data[k])

    def leg(self, start: RoadPoint | int, nodes: Sequence[int] | np.ndarray) -> Leg:
        """The drive from ``start`` along ``nodes`` (``nodes[0]`` must be the start's node; each
        step must be an edge): cumulative seconds and metres, starting at the start's remaining
        seconds and metres. ValueError otherwise."""
        sums = self.leg_sums
        if sums is not None:  # compiled: one call instead of a Python loop over the edges
            if type(start) is int:  # a node (the usual start): no point to build
                node, rem, rem_m, prev = start, 0.0, 0.0, -1
            else:
                p = _as_point(start)
                node, rem, rem_m = p.node, max(p.remaining, 0.0), max(p.remaining_m, 0.0)
                prev = p.prev if not p.on_node else -1
            # (a planner's list: np.array converts it faster than asarray + reshape)
            arr = np.array(nodes, dtype=np.int64) if type(nodes) is list else \
                np.asarray(nodes, dtype=np.int64)
            if arr.ndim != 1:
                arr = arr.reshape(-1)
            if arr.size and int(arr[0]) == node:
                times, metres, ok = sums(*self._leg_csr, arr, rem, rem_m)
                if ok:  # Leg(arr, times, metres, prev), without a frozen __init__ (and its
                    # cached seconds and metres set, as the operator reads them at once)
                    leg = object.__new__(Leg)
                    leg.__dict__.update(nodes=arr, times=times, metres=metres, prev=prev,
                                        seconds=float(times[-1]), length=float(metres[-1]))
                    return leg
            nodes = arr  # not a path from the start: the checks below say why
        p = _as_point(start)
        if isinstance(nodes, list) and nodes and nodes[0] == p.node \
                and all(type(x) is int for x in nodes):
            # a planner's path: edges looked up and summed one by one in Python (a path is
            # short; numpy's per-call overhead would dominate); the sums run in the same order
            # as a cumsum, so the numbers are the same
            n, edge_of = self.n, self.edge_of
            try:
                ks = [edge_of[a * n + b] for a, b in zip(nodes[:-1], nodes[1:])]
            except KeyError:
                ks = None
            if ks is not None:
                secs, mets = self.edge_lists
                times = list(accumulate([max(p.remaining, 0.0), *[secs[k] for k in ks]]))
                metres = list(accumulate([max(p.remaining_m, 0.0), *[mets[k] for k in ks]]))
                return Leg(np.array(nodes, dtype=np.int64), np.array(times), np.array(metres),
                           p.prev if not p.on_node else -1)
            nodes = np.array(nodes, dtype=np.int64)
            k = None
        else:
            nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
            k = None
        if nodes.size == 0 or int(nodes[0]) != p.node:
            raise ValueError(f"a leg from node {p.node} must start there, got path starting "
                             f"{nodes[:1].tolist()}")
        if k is None:
            k = self.index(nodes[:-1], nodes[1:])
        times = np.empty(nodes.size)
        metres = np.empty(nodes.size)
        times[0], metres[0] = max(p.remaining, 0.0), max(p.remaining_m, 0.0)
        times[1:] = self.time.data[k]
        metres[1:] = self.length.data[k]
        return Leg(nodes, np.cumsum(times), np.cumsum(metres), p.prev if not p.on_node else -1)


def straight_line(xy: np.ndarray, time: csr_matrix
                  ) -> tuple[float | None, tuple[tuple[float, float], ...]]:
    """``(top_speed, speed_slacks)`` of the network of node metres ``xy`` and edge seconds
    ``time`` (see :attr:`dispatch.api.space.Space.top_speed`; None and none for a network
    without edges or whose nodes all stand on one point).

    A fastest drive's straight line is at most the sum of its edges' straight lines, each at
    most ``speed`` times the edge's seconds plus what it exceeds that by, and a fastest path
    takes an edge at most once, so the excesses of all edges bound the slack. The top speed is
    the fastest edge's (no slack); the slower speeds are a few percentiles of the edges' own,
    each with its slack: a few edges whose ends lie further apart than their time would let a
    car drive (a zone's connector) would otherwise weaken every bound."""
    rows = np.repeat(np.arange(xy.shape[0]), np.diff(time.indptr))
    straight = np.hypot(*(xy[time.indices] - xy[rows]).T)
    speed = straight / time.data
    top = float(speed.max()) if speed.size else 0.0
    if not (top > 0 and math.isfinite(top)):
        return None, ()
    margin = 1e-9 * float(straight.sum())  # (the rounding of the sums)
    slower = []
    for s in np.unique(np.percentile(speed, [90, 95, 99, 99.5, 99.9, 99.99])).tolist():
        if 0 < s < top:
            slower.append((s, float(np.maximum(straight - s * time.data, 0.0).sum()) + margin))
    return top, tuple(slower)


def largest_component(time: csr_matrix) -> np.ndarray:
    """Which nodes of the graph whose edges are the entries of the square CSR matrix ``time``
    are in its largest strongly connected component (scipy's ``connected_components``; of
    components of equal size, the one of the lowest label). All of them where the graph is
    strongly connected, found without scipy's graph module, whose import (0.07 s) a run on a
    generated grid then never makes."""
    if strongly_connected(time):
        return np.ones(time.shape[0], dtype=bool)
    from scipy.sparse.csgraph import connected_components

    _, labels = connected_components(time, directed=True, connection="strong")
    return labels == int(np.argmax(np.bincount(labels, minlength=1)))


def strongly_connected(time: csr_matrix) -> bool:
    """Whether every node of the graph whose edges are the entries of the square CSR matrix
    ``time`` reaches every other: node 0 reaches them all, and they all reach node 0 (a
    breadth-first search each way). True for a graph of no node or one."""
    n = time.shape[0]
    if n <= 1:
        return True
    back = time.T.tocsr()
    return _reaches_all(time.indptr, time.indices, n) and _reaches_all(back.indptr,
                                                                     back.indices, n)


def _reaches_all(indptr: np.ndarray, indices: np.ndarray, n: int) -> bool:
    """Whether a breadth-first search from node 0 along the CSR rows reaches all ``n`` nodes."""
    seen = np.zeros(n, dtype=bool)
    seen[0] = True
    frontier = np.zeros(1, dtype=np.int64)
    while frontier.size:
        ends = indptr[frontier + 1].astype(np.int64)
        sizes = ends - indptr[frontier]
        # the frontier's edges: each row's range, laid end to end
        edges = np.repeat(ends - np.cumsum(sizes), sizes) + np.arange(int(sizes.sum()))
        heads = indices[edges]
        frontier = np.unique(heads[~seen[heads]])
        seen[frontier] = True
    return bool(seen.all())
