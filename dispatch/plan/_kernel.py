"""The compiled part of :mod:`dispatch.plan.stops`: the rule's functions compiled as they are
written
there (:func:`leave`, :func:`leave_late`, :func:`timetable`; compiled kernels of plugins
call these too, e.g. :mod:`allocators._rtv_kernel`), and the cheapest insertion of each
candidate pair of a decision (:func:`insert_pairs`, behind
:func:`dispatch.plan.insertion.insertion_costs`).
Imported on first use only (it compiles with numba, cached on disk where possible; numba's
cache does not notice a change of a called function in another file: after editing the rule
in :mod:`dispatch.plan.stops`, delete the ``__pycache__/*.nbi`` / ``*.nbc`` files of ``dispatch``
and ``allocators``).
"""

from __future__ import annotations

import types

import numba
import numpy as np

from dispatch._compiled import jit
from dispatch.plan import stops
from dispatch.plan.stops import TOL


def _twin(fn, **compiled):
    """``fn`` compiled, calling the ``compiled`` functions where it calls their Python twins
    (numba reads a function's globals: the same code, given the compiled helpers)."""
    names = dict(fn.__globals__)
    names.update(compiled)
    return jit(types.FunctionType(fn.__code__, names, fn.__name__, fn.__defaults__,
                                  fn.__closure__))


def _inline(fn):
    """``fn`` compiled into each compiled caller (so a constant ``earliest`` of ``-inf``, a
    stop that never waits, compiles to a plain sum)."""
    try:
        return numba.njit(inline="always", cache=True)(fn)
    except RuntimeError:  # (no writable cache directory: see dispatch._compiled.jit)
        return numba.njit(inline="always")(fn)


leave = _inline(stops.leave)
leave_late = _inline(stops.leave_late)
timetable = _twin(stops.timetable, leave=leave)


@_inline
def _through(t, a, lo, hi, first_leg, s_arr, s_e, s_svc, s_latest, s_occ, extra, cap, tol):
    """The plan's stops ``lo .. hi - 1`` (flat from ``a``) driven after leaving a new stop at
    ``t``: the first ``first_leg`` seconds later, each later one as long after the stop before
    it as planned, every departure by the rule (:func:`dispatch.plan.stops.leave`), with ``extra``
    more on board (0: no seat to check). Returns ``(t, shift, ok)``: the departure from stop
    ``hi - 1`` (``t`` where there is none), how much later than planned stop ``lo`` is reached,
    and False at the first stop over ``cap`` or past its latest (``tol`` seconds allowed)."""
    shift = 0.0
    for m in range(lo, hi):
        if extra and s_occ[a + m] + extra > cap:
            return t, shift, False
        if m == lo:
            t = t + first_leg
        else:
            t = t + (s_arr[a + m] - leave(s_arr[a + m - 1], s_e[a + m - 1], s_svc[a + m - 1]))
        if t > s_latest[a + m] + tol:
            return t, shift, False
        if m == lo:
            shift = t - s_arr[a + m]
        t = leave(t, s_e[a + m], s_svc[a + m])
    return t, shift, True


@jit
def _insert_one(a, k, t0, ftt, s_arr, s_svc, s_e, s_latest, s_occ, load, cap, to_p, from_p,
                to_d, from_d, r, pd, n, lp, ld, ep, svc_p, svc_d, objective,
                tol):  # pragma: no cover - compiled
    """The cheapest insertion of request ``r`` into one plan (flat stops ``a .. a + k``) by
    re-simulating the rule for every pair of positions: for plans where a stop may wait
    (its ``earliest`` after the vehicle's ready time ``t0``), which the slack of
    :func:`insert_pairs` does not model. Returns what that kernel writes for a pair."""
    inf = np.inf
    best, bi, bj, bpick, bdrop, bs1, bs2 = inf, -1, -1, inf, inf, 0.0, 0.0
    end_old = t0 if k == 0 else leave(s_arr[a + k - 1], s_e[a + k - 1], s_svc[a + k - 1])
    for i in range(k + 1):
        occ_i = load if i == 0 else s_occ[a + i - 1]
        if occ_i + n > cap:
            continue
        if i == 0:
            arr_p = t0 + ftt
        else:
            arr_p = leave(s_arr[a + i - 1], s_e[a + i - 1], s_svc[a + i - 1]) \
                + to_p[a + i - 1, r]
        if arr_p > lp + tol:
            continue
        leave_p = leave(arr_p, ep, svc_p)
        for j in range(i, k + 1):
            # the plan's stops i .. j - 1 after the pickup, then the drop-off, then the rest
            t, s1, ok = _through(leave_p, a, i, j, from_p[r, a + i] if j > i else 0.0, s_arr,
                                 s_e, s_svc, s_latest, s_occ, n, cap, tol)
            if not ok:
                break  # (a later drop-off keeps the same stops after the pickup)
            arr_d = t + (pd[r] if j == i else to_d[a + j - 1, r])
            if arr_d > ld + tol:
                continue
            t, s2, ok = _through(leave(arr_d, -inf, svc_d), a, j, k,
                                 from_d[r, a + j] if j < k else 0.0, s_arr, s_e, s_svc,
                                 s_latest, s_occ, 0, cap, tol)
            if not ok:
                continue
            c = arr_p - t0 if objective == 0 else t - end_old
            if c < best - 1e-12 or (c <= best + 1e-12 and arr_p < bpick - tol):
                best, bi, bj, bpick, bdrop, bs1, bs2 = c, i, j, arr_p, arr_d, s1, s2
    return best, bi, bj, bpick, bdrop, bs1, bs2


@jit
def insert_pairs(rows, cols, ready, first_tt, off, s_arr, s_svc, s_latest, s_occ, load, cap,
                 to_p, from_p, to_d, from_d, pd_tt, req_n, req_lp, req_ld, req_svc_p,
                 req_svc_d, objective, s_e, req_e, out_cost, out_i, out_j, out_pick, out_drop,
                 out_s1, out_s2):  # pragma: no cover - compiled
    """The kernel of :func:`dispatch.plan.insertion.insertion_costs` (one loop over the candidate
    pairs).
    Where no stop can wait (every ``earliest`` at or before the vehicle's ready time, as for
    requests' stops) the rule is a running sum, and an insertion that reaches stop ``m``
    ``delta`` seconds later is feasible when ``delta`` is within the plan's slack there (how
    much later stops ``m..`` may be reached): O(k^2) per pair. Otherwise :func:`_insert_one`
    re-simulates."""
    inf = np.inf
    tol = TOL
    last, opens = -1, -inf  # (the pairs come by vehicle: its plan's latest opening, once)
    for q in range(rows.size):
        v, r = rows[q], cols[q]
        a, b = off[v], off[v + 1]
        k = b - a
        n = req_n[r]
        t0 = ready[v]
        if v != last:
            last, opens = v, -inf
            for m in range(a, b):
                if s_e[m] > opens:
                    opens = s_e[m]
        if opens > t0 or req_e[r] > t0:
            got = _insert_one(a, k, t0, first_tt[q], s_arr, s_svc, s_e, s_latest, s_occ,
                              load[v], cap[v], to_p, from_p, to_d, from_d, r, pd_tt, n,
                              req_lp[r], req_ld[r], req_e[r], req_svc_p[r], req_svc_d[r],
                              objective, tol)
            out_cost[q], out_i[q], out_j[q], out_pick[q] = got[0], got[1], got[2], got[3]
            out_drop[q], out_s1[q], out_s2[q] = got[4], got[5], got[6]
            continue
        # no stop opens after t0, and every arrival is at t0 or later: no earliest binds
        # (the rule's departures with ``-inf``, which compile to plain sums)
        best, bi, bj, bpick, bdrop, bs1, bs2 = inf, -1, -1, inf, inf, 0.0, 0.0
        # slack[m]: how much later stops m.. of the plan may be reached (m = k: none follow)
        slack = np.empty(k + 1)
        slack[k] = inf
        for m in range(k - 1, -1, -1):
            sl = s_latest[a + m] - s_arr[a + m]
            slack[m] = sl if sl < slack[m + 1] else slack[m + 1]
        end_old = t0 if k == 0 else leave(s_arr[b - 1], -inf, s_svc[b - 1])
        for i in range(k + 1):  # the pickup after the plan's i-th stop (0: first)
            occ_i = load[v] if i == 0 else s_occ[a + i - 1]
            if occ_i + n > cap[v]:
                continue
            if i == 0:
                dep = t0
                arr_p = t0 + first_tt[q]
            else:
                dep = leave(s_arr[a + i - 1], -inf, s_svc[a + i - 1])
                arr_p = dep + to_p[a + i - 1, r]
            if arr_p > req_lp[r] + tol:
                continue
            leave_p = leave(arr_p, -inf, req_svc_p[r])
            old = 0.0  # the drive it replaces: to the next stop (from ``dep``)
            if i < k:
                old = s_arr[a + i] - dep
            # the drop-off right after the pickup
            arr_d = leave_p + pd_tt[r]
            if arr_d <= req_ld[r] + tol:
                leave_d = leave(arr_d, -inf, req_svc_d[r])
                ok = True
                delta = 0.0
                if i < k:
                    delta = leave_d + from_d[r, a + i] - dep - old
                    ok = delta <= slack[i] + tol
                    end_new = end_old + delta
                else:
                    end_new = leave_d
                if ok:
                    c = arr_p - t0 if objective == 0 else end_new - end_old
                    if c < best - 1e-12 or (c <= best + 1e-12 and arr_p < bpick - tol):
                        best, bi, bj, bpick, bdrop, bs1, bs2 = c, i, i, arr_p, arr_d, 0.0, delta
            if i == k:
                continue
            # the drop-off later: the pickup delays stops i.. by delta1
            delta1 = leave_p + from_p[r, a + i] - dep - old
            if delta1 > slack[i] + tol:
                continue
            for j in range(i + 1, k + 1):  # the drop-off after the plan's j-th stop
                if s_occ[a + j - 1] + n > cap[v]:
                    break  # on board through stop j: no later drop-off fits either
                dep_j = leave_late(s_arr[a + j - 1], delta1, -inf, s_svc[a + j - 1])
                arr_d = dep_j + to_d[a + j - 1, r]
                if arr_d > req_ld[r] + tol:
                    continue
                leave_d = leave(arr_d, -inf, req_svc_d[r])
                delta2 = 0.0
                if j < k:
                    delta2 = leave_d + from_d[r, a + j] - (s_arr[a + j] + delta1)
                    if delta1 + delta2 > slack[j] + tol:
                        continue
                    end_new = end_old + delta1 + delta2
                else:
                    end_new = leave_d
                c = arr_p - t0 if objective == 0 else end_new - end_old
                if c < best - 1e-12 or (c <= best + 1e-12 and arr_p < bpick - tol):
                    best, bi, bj, bpick, bdrop = c, i, j, arr_p, arr_d
                    bs1, bs2 = delta1, delta1 + delta2
        out_cost[q], out_i[q], out_j[q], out_pick[q] = best, bi, bj, bpick
        out_drop[q], out_s1[q], out_s2[q] = bdrop, bs1, bs2
    return 0


@jit
def candidate_pairs(cost, now, slots, planned, cap, free_at, lp, ld, n_req, ep, svc_p, svc_d,
                    pd, pickup_time, out):  # pragma: no cover - compiled
    """The set-up of a decision's insertions (:func:`dispatch.decide.plan_costs.insertion_costs_of`)
    in one loop over its vehicles (rows of ``cost``, the drives to each request's pickup;
    fleet positions ``slots``) instead of a numpy call per step: the same doubles as those
    array operations give, by the same operations in the same order.

    A row not ``planned`` (an empty plan) gets its cost of each request written into ``out``:
    the pickup and the drop-off in that order, ``inf`` past a limit or the seats (``cap`` and
    ``free_at`` by fleet position). A planned one, ready at ``max(free_at, now)``, is a
    candidate pair with each request whose pickup it reaches by the deadline and whose riders
    fit its seats.

    Returns ``(rows, cols, pair_vehicle, used, ready, seats, ucols, pair_col, first_tt)``:
    the candidate pairs by row, then column (rows of ``cost``, its columns); each pair's
    vehicle among ``used`` (the rows with a pair, ascending), their ready times and seats;
    the columns with a pair (ascending) and each pair's column among them; each pair's drive
    to the pickup."""
    inf = np.inf
    n, m = cost.shape
    rows = np.empty(n * m, np.int64)
    cols = np.empty(n * m, np.int64)
    pair_vehicle = np.empty(n * m, np.int64)
    first_tt = np.empty(n * m)
    used = np.empty(n, np.int64)
    ready = np.empty(n)
    seats = np.empty(n, np.int64)
    seen = np.zeros(m, np.bool_)
    q = 0
    u = 0
    for i in range(n):
        s = slots[i]
        if not planned[i]:
            for j in range(m):
                c = cost[i, j]
                arr_p = now + c
                e = ep[j]
                later = arr_p if (arr_p > e or np.isnan(arr_p)) else e  # (np.maximum's)
                arr_d = later + svc_p[j] + pd[j]
                if arr_p <= lp[j] + 1e-9 and arr_d <= ld[j] + 1e-9 and n_req[j] <= cap[s]:
                    out[i, j] = c if pickup_time else c + svc_p[j] + pd[j] + svc_d[j]
                else:
                    out[i, j] = inf
            continue
        f = free_at[s]
        r = f if (f > now or np.isnan(f)) else now  # (np.maximum's)
        first = True
        for j in range(m):
            c = cost[i, j]
            if r + c <= lp[j] + 1e-9 and n_req[j] <= cap[s]:
                if first:
                    first = False
                    used[u], ready[u], seats[u] = i, r, cap[s]
                    u += 1
                rows[q], cols[q], pair_vehicle[q], first_tt[q] = i, j, u - 1, c
                seen[j] = True
                q += 1
    col_at = np.full(m, -1, np.int64)
    ucols = np.empty(m, np.int64)
    k = 0
    for j in range(m):
        if seen[j]:
            col_at[j] = k
            ucols[k] = j
            k += 1
    pair_col = np.empty(q, np.int64)
    for p in range(q):
        pair_col[p] = col_at[cols[p]]
    return (rows[:q], cols[:q], pair_vehicle[:q], used[:u], ready[:u], seats[:u], ucols[:k],
            pair_col, first_tt[:q])


@jit
def gather_rows(idx, length, arr, svc, lat, occ, ear, node):  # pragma: no cover - compiled
    """The plans of the table rows ``idx`` (each row ``k`` holds ``length[k]`` stops of the
    fields ``arr``, ``svc``, ``lat``, ``occ``, ``ear``, ``node``), flat:
    ``(off, arr, svc, lat, occ, ear, node)`` with row ``idx[i]``'s stops at
    ``off[i]:off[i + 1]``, copied in one loop (no index arrays built per decision)."""
    n = idx.size
    off = np.zeros(n + 1, np.int64)
    for i in range(n):
        off[i + 1] = off[i] + length[idx[i]]
    g = off[n]
    a, s, la, e = np.empty(g), np.empty(g), np.empty(g), np.empty(g)
    o, nd = np.empty(g, np.int64), np.empty(g, np.int64)
    for i in range(n):
        k = idx[i]
        at = off[i]
        for j in range(length[k]):
            a[at + j] = arr[k, j]
            s[at + j] = svc[k, j]
            la[at + j] = lat[k, j]
            o[at + j] = occ[k, j]
            e[at + j] = ear[k, j]
            nd[at + j] = node[k, j]
    return off, a, s, la, o, e, nd
