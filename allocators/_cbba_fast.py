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
_BIG = np.iinfo(np.int64).max


def _jit(fn):
    """``numba.njit(cache=True, nogil=True)``, without the disk cache where none is writable."""
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError:  # "cannot cache function ...: no locator available"
        return numba.njit(cache=False, nogil=True)(fn)


@numba.njit
def _stamp(s, s0, order, cnt, heard, now, i, k, x):
    """Agent ``i``'s timestamp for agent ``x`` while it processes sender ``k``: ``now`` for a
    sender it heard before ``k``, else :func:`_fold`."""
    if x < k and heard[i, x]:
        return now
    return _fold(s, s0, order, cnt, i, x)


@numba.njit
def _fold(s, s0, order, cnt, i, x):
    """Agent ``i``'s timestamp for agent ``x`` (not one of its senders so far, not itself)
    after applying the ``cnt`` broadcasts ``order[:cnt]``, as the sender-by-sender updates
    would have left it: the largest of its own value and those senders' values. (A sender it
    heard reads ``now``: :func:`_stamp`.)"""
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
    between only where a rule needs one (:func:`_fold`)."""
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
    heard = got.T.copy()  # heard[i, k] = got[k, i], read row by row
    for i in range(n):
        cnt = 0
        for k in range(n):
            if not heard[i, k]:
                continue
            for j in range(m):
                yk = y0[k, j]
                zk = z0[k, j]
                yi = y[i, j]
                zi = z[i, j]
                if yi == yk and zi == zk:  # every rule leaves an agreed entry as it is
                    continue
                # CBBA's Table 1 as a decision tree on (sender's winner, receiver's winner);
                # timestamps read only on the branches that compare them: i's value for an
                # agent it heard this round is now, else folded from its senders so far
                beats = yk > yi or (yk == yi and (zk if zk >= 0 else _BIG)
                                    < (zi if zi >= 0 else _BIG))
                upd = False
                reset = False
                if zk == k:
                    if zi == i:
                        upd = beats
                    elif zi == k or zi == NONE:
                        upd = True
                    else:
                        s_in = _stamp(s, s0, order, cnt, heard, now, i, k, zi)
                        upd = s0[k, zi] > s_in or beats
                elif zk == i:
                    if zi == k:
                        reset = True
                    elif zi != i and zi != NONE:
                        s_in = _stamp(s, s0, order, cnt, heard, now, i, k, zi)
                        reset = s0[k, zi] > s_in
                elif zk == NONE:
                    if zi == k:
                        upd = True
                    elif zi != i and zi != NONE:
                        s_in = _stamp(s, s0, order, cnt, heard, now, i, k, zi)
                        upd = s0[k, zi] > s_in
                else:  # k believes a third agent m = zk wins
                    s_km = s0[k, zk]
                    s_im = _stamp(s, s0, order, cnt, heard, now, i, k, zk)
                    newer_m = s_km > s_im
                    if zi == i:
                        upd = newer_m and beats
                    elif zi == k:
                        upd = newer_m
                        reset = not newer_m
                    elif zi == NONE or zi == zk:
                        upd = newer_m
                    else:  # i believes a fourth agent n = zi wins
                        s_in = _stamp(s, s0, order, cnt, heard, now, i, k, zi)
                        newer_n = s0[k, zi] > s_in
                        upd = newer_m and (newer_n or beats)
                        reset = newer_n and s_im > s_km
                if upd:
                    y[i, j] = yk
                    z[i, j] = zk
                elif reset:
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
