"""Compiled (numba) consensus phase of CBBA: every receiver applies every broadcast it got.

One function, :func:`exchange`, the same rules as the reference implementation in
:meth:`allocators.auction._CBBA._apply` (CBBA's Table 1, Choi, Brunet & How 2009) applied in
the same order: senders by ascending index, each broadcast carrying the state every agent held
when the round's messages were sent (``y0, z0, s0``), each receiver updating its own row in
place (a receiver's later senders see what its earlier senders changed). The Python version
spends its time in per-sender numpy calls (a fleet of 1,000 taxis: 1,000 calls per round);
here the loops are plain loops, a few nanoseconds per (sender, receiver, task).
"""

from __future__ import annotations

import numba
import numpy as np

NONE = -1


def _jit(fn):
    """``numba.njit(cache=True, nogil=True)``, without the disk cache where none is writable."""
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError:  # "cannot cache function ...: no locator available"
        return numba.njit(cache=False, nogil=True)(fn)


@numba.njit(inline="always")
def _better(ya, za, yb, zb):
    """Bid (ya, by za) beats (yb, by zb): higher value, ties to the lower index (-1 last)."""
    big = np.iinfo(np.int64).max
    a = big if za < 0 else za
    b = big if zb < 0 else zb
    return (ya > yb) or (ya == yb and a < b)


@numba.njit(inline="always")
def _heard(s, s0, order, cnt, i, x, now, got, k):
    """Agent ``i``'s timestamp for agent ``x`` after applying the ``cnt`` broadcasts
    ``order[:cnt]`` (senders before ``k``), as the sender-by-sender updates would have left it:
    ``now`` for a sender it heard (and for itself once it heard anyone), else the largest of
    its own value and those senders' values."""
    if x < 0:
        return -1
    if (x < k and got[x, i]) or (x == i and cnt > 0):
        return now
    v = s[i, x]
    for t in range(cnt):
        w = s0[order[t], x]
        if w > v:
            v = w
    return v


@_jit
def exchange(y, z, s, got, y0, z0, s0, now):
    """Apply the broadcasts ``got[k, i]`` (agent ``i`` received ``k``'s) to ``y, z, s`` in
    place; ``y0, z0, s0`` are what was sent. Returns the number of receptions each agent
    processed (for sharing the compute time).

    Receiver by receiver (each changes only its own row, so this equals the sender-major order
    of the reference); a receiver's timestamps are folded in once at its end, and read in
    between only where a rule needs one (:func:`_heard`)."""
    n, m = y.shape
    work = np.zeros(n, np.int64)
    # per column, the largest and second largest sent timestamp (and the row of the largest)
    top1 = np.full(n, -1, np.int64)
    top2 = np.full(n, -1, np.int64)
    arg1 = np.full(n, -1, np.int64)
    for k in range(n):
        for q in range(n):
            v = s0[k, q]
            if v > top1[q]:
                top2[q] = top1[q]
                top1[q] = v
                arg1[q] = k
            elif v > top2[q]:
                top2[q] = v
    order = np.empty(n, np.int64)
    for i in range(n):
        cnt = 0
        for k in range(n):
            if not got[k, i]:
                continue
            for j in range(m):
                yk = y0[k, j]
                zk = z0[k, j]
                yi = y[i, j]
                zi = z[i, j]
                if yi == yk and zi == zk:  # every rule leaves an agreed entry as it is
                    continue
                k_is_k = zk == k
                k_is_i = zk == i
                k_none = zk == NONE
                k_m = not (k_is_k or k_is_i or k_none)
                i_is_i = zi == i
                i_is_k = zi == k
                i_none = zi == NONE
                i_other = not (i_is_i or i_is_k or i_none)
                i_same = i_other and zi == zk
                i_n = i_other and not i_same
                beats = _better(yk, zk, yi, zi)
                newer_m = False
                older_m = False
                if k_m:
                    s_km = s0[k, zk]
                    s_im = _heard(s, s0, order, cnt, i, zk, now, got, k)
                    newer_m = s_km > s_im
                    older_m = s_im > s_km
                newer_n = False
                if i_other:
                    s_kn = s0[k, zi]
                    s_in = _heard(s, s0, order, cnt, i, zi, now, got, k)
                    newer_n = s_kn > s_in
                update = (
                    (k_is_k and ((i_is_i and beats) or i_is_k
                                 or (i_other and (newer_n or beats)) or i_none))
                    or (k_m and ((i_is_i and newer_m and beats) or (i_is_k and newer_m)
                                 or (i_same and newer_m)
                                 or (i_n and newer_m and (newer_n or beats))
                                 or (i_none and newer_m)))
                    or (k_none and (i_is_k or (i_other and newer_n)))
                )
                if update:
                    y[i, j] = yk
                    z[i, j] = zk
                    continue
                reset = (
                    (k_is_i and (i_is_k or (i_other and newer_n)))
                    or (k_m and ((i_is_k and not newer_m) or (i_n and newer_n and older_m)))
                )
                if reset:
                    y[i, j] = -np.inf
                    z[i, j] = NONE
            order[cnt] = k
            cnt += 1
        work[i] = cnt
        if cnt == 0:
            continue
        # fold the timestamps in: i heard its senders now, and everything they had heard
        if cnt == n - 1:  # everyone else: the column maxima without i's own row
            for q in range(n):
                v = top2[q] if arg1[q] == i else top1[q]
                if v > s[i, q]:
                    s[i, q] = v
        else:
            for t in range(cnt):
                k = order[t]
                for q in range(n):
                    if s0[k, q] > s[i, q]:
                        s[i, q] = s0[k, q]
        for t in range(cnt):
            s[i, order[t]] = now
        s[i, i] = now
    return work
