"""Compiled (numba) helpers of the kernel's per-trip hot path; imported on first use only.

:func:`leg_sums` turns a node path into a leg's cumulative seconds and metres (two per trip:
to the pickup, to the drop-off). It adds the edges one by one in path order, as
``itertools.accumulate`` and ``numpy.cumsum`` do, so the sums are the same floats bit for bit.
Compiled code is cached on disk (``cache=True``); where no cache directory is writable it is
compiled in every process instead.
"""

from __future__ import annotations

import numba
import numpy as np


def jit(fn):
    """``numba.njit(cache=True)``, without the disk cache where none is writable."""
    try:
        return numba.njit(cache=True)(fn)
    except RuntimeError:  # "cannot cache function ...: no locator available"
        return numba.njit(cache=False)(fn)


@jit
def leg_sums(indptr, indices, seconds, metres, nodes, t0, m0):  # pragma: no cover - compiled
    """``(times, metres, ok)`` of the path ``nodes`` in a CSR graph whose rows hold each
    node's out-edges (``indices``: heads; ``seconds`` / ``metres``: the edges' values):
    ``times[0] = t0``, ``times[i] = times[i - 1] + seconds`` of the edge ``nodes[i - 1] ->
    nodes[i]`` (likewise ``metres`` from ``m0``). ``ok`` is False when a step is not an edge
    (or names no node); the arrays are then meaningless."""
    k = nodes.size
    n = indptr.size - 1
    times = np.empty(k)
    out_m = np.empty(k)
    times[0] = t0
    out_m[0] = m0
    for i in range(1, k):
        u = nodes[i - 1]
        v = nodes[i]
        if u < 0 or u >= n:
            return times, out_m, False
        e = -1
        for j in range(indptr[u], indptr[u + 1]):
            if indices[j] == v:
                e = j
                break
        if e < 0:
            return times, out_m, False
        times[i] = times[i - 1] + seconds[e]
        out_m[i] = out_m[i - 1] + metres[e]
    return times, out_m, True


@jit
def legs_at(times, nodes, length, prev, rows, now, starts, out_k, node, rem, out_i,
            on):  # pragma: no cover - compiled
    """Where vehicles driving legs are at ``now`` (:class:`dispatch.plan.en_route.LegTable`): for
    each ``q``, the leg in row ``rows[q]`` of ``times`` / ``nodes`` (its first ``length``
    entries; ``prev``: its start point's), started at ``starts[q]``: writes
    :meth:`dispatch.api.legs.Leg.next_at`'s ``(node, remaining)`` of ``now - starts[q]`` into
    ``node[out_k[q]]``, ``rem[out_k[q]]`` and whether it stands on the node into
    ``on[out_i[q]]``, by the same comparisons and subtractions (``max``, ``bisect_right``)."""
    for q in range(rows.size):
        r = rows[q]
        n = length[r]
        t = now - starts[q]
        k = out_k[q]
        if t >= times[r, n - 1]:
            node[k], rem[k], on[out_i[q]] = nodes[r, n - 1], 0.0, True
            continue
        if 0.0 > t:  # max(t, 0.0)
            t = 0.0
        lo, hi = 0, n  # bisect_right
        while lo < hi:
            mid = (lo + hi) // 2
            if t < times[r, mid]:
                hi = mid
            else:
                lo = mid + 1
        if lo == 0:
            left = times[r, 0] - t
            here = prev[r] < 0 or left <= 0.0
            node[k], rem[k], on[out_i[q]] = nodes[r, 0], 0.0 if here else left, here
        elif t == times[r, lo - 1]:
            node[k], rem[k], on[out_i[q]] = nodes[r, lo - 1], 0.0, True
        else:
            left = times[r, lo] - t
            node[k], rem[k], on[out_i[q]] = nodes[r, lo], left if left > 0.0 else 0.0, \
                left <= 0.0
    return 0
