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
