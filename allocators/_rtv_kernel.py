"""The compiled part of :mod:`allocators.rtv`: the best stop order of a group of new requests on
one vehicle (a depth-first search over every order of the group's stops merged into the
vehicle's plan, the plan's own order kept; or, with ``reorder``, over every order of the
plan's stops and the group's together: :func:`best_orders`), for many (vehicle, group)
candidates in one call.

The schedule is the kernel's one rule (:mod:`dispatch.plan.stops`, compiled in
:mod:`dispatch.plan._kernel`: departures by its ``leave``): arrival at a stop = departure from the
one before + the drive between them; service starts at ``max(arrival, earliest)`` (``p_e``: a
plan stop's earliest time, ``r_e``: a new request's pickup's, e.g. a booked request's requested
departure; a drop-off is open); departure = that start + the service time of a stop that
completes a request (a drop-off; the pickup of a point task); a stop of the plan must be reached
by ``max(latest, planned arrival)``, a new stop by its limit; the occupancy never exceeds the
capacity; the departure from the route's last stop is no later than the vehicle's ``until`` (its
shift's end plus the grace; ``inf``: none). Departures only grow along a route, so a partial
route leaving a stop after ``until`` is cut at once.

Costs (``objective``): 0 ``delay``: the new requests' delays (drop-off time - release - direct
drive; a point task: the start of its service - release) plus how much later the plan's own
drop-offs come than planned (Alonso-Mora et al.'s sum of delays); 1 ``added_time``: how much
later the plan ends (departure from its last stop) than it did.

Compiled with numba on first use (cached on disk where possible).
"""

from __future__ import annotations

import numpy as np

from dispatch._compiled import jit
from dispatch.plan._kernel import leave

#: codes in a returned order: ``>= 0`` a new stop (``2 i`` the pickup, ``2 i + 1`` the drop-off
#: of the group's ``i``-th request), ``< 0`` the plan's stop ``-code - 1``
INF = np.inf


@jit
def best_orders(groups, gveh, start, first_eta, load, cap, off, p_pax, p_limit, p_svc, p_eta,
                p_drop, p_e, pp, p_pred, vp, poff, ppa, vn, pn, np_, nn, r_pax, r_lp, r_ld,
                r_rel, r_direct, r_hasdrop, r_e, until, old_end, svc, objective, budget, tol,
                reorder, out_cost, out_order, out_cut, out_end):  # pragma: no cover - compiled
    """For each candidate ``g``: vehicle ``gveh[g]`` (row of the per-vehicle arrays) and the
    requests ``groups[g, :]`` (indices of the batch's requests, ``-1`` padded): the cheapest
    feasible order (``out_cost[g]``, ``inf`` if none; ``out_order[g, :]`` its codes, ``-99``
    padded; ``out_end[g]`` when that order leaves its last stop). ``out_cut[g]`` is True when
    the search stopped after ``budget`` nodes (the answer is then the best found, maybe none).

    ``reorder`` False: the group's stops merged into the plan, the plan's own order kept (at
    each step the next stop is the plan's next one or one of the group's). True: every order
    of the plan's stops and the group's (Alonso-Mora et al.'s whole-trip routing), each pickup
    before its drop-off (a plan's drop-off after its pickup where that is in the plan too:
    ``p_pred[s]``, the flat index of the pickup, or ``-1``). Same schedule, limits and costs;
    the search tries the plan's stops first, then the group's in their order, so ties and a
    cut search end alike in both.

    Vehicle ``j``: it can leave at ``start[j]``; reaching its plan's first stop first it arrives
    at ``first_eta[j]`` (the kernel's planned time); ``load[j]`` on board, ``cap[j]`` seats;
    plan stops ``off[j]:off[j + 1]`` of the flat arrays (passengers, limit, service,
    planned arrival, is a drop-off, earliest); ``old_end[j]`` when its plan ends now,
    ``until[j]`` when it must end at the latest. ``r_e[r]``: the earliest start of request
    ``r``'s pickup (``-inf``: open). Drives: ``vn[j, x]`` vehicle -> new stop ``x`` (``2 r``
    pickup, ``2 r + 1`` drop-off of request ``r``), ``pn[s, x]`` plan stop -> new stop,
    ``np_[x, s]`` new stop -> plan stop, ``nn[x, y]`` between new stops. Between the plan's
    stops: kept order, ``pp[s]`` from plan stop ``s`` to ``s + 1``; reordered, any other stop
    than the first may come first, reached at ``start[j]`` + ``vp[s]`` (the drive from where
    the vehicle is, as the kernel re-routes a vehicle whose first stop changes: it finishes
    the edge it is on, then drives there), and ``ppa[poff[j] + u * n + w]`` drives from the
    plan's ``u``-th to its ``w``-th stop (``n`` stops). The arrays one mode does not read may
    be empty. Reordered, a vehicle's plan and group together hold at most 62 stops (the bits
    of the search's masks; the caller keeps longer plans in their order)."""
    G, K = groups.shape
    L = out_order.shape[1]
    # per-depth state
    st_time = np.empty(L + 1)
    st_occ = np.empty(L + 1, np.int64)
    st_cost = np.empty(L + 1)
    st_pos = np.empty(L + 1, np.int64)  # -1 start; 0.. plan stop (flat); -2 - x new stop x
    st_next = np.empty(L + 1, np.int64)  # kept order: the plan's next stop (flat index)
    # stops visited: bit boff + x new stop x; reordered, bit u the plan's u-th stop too
    st_mask = np.empty(L + 1, np.int64)
    st_try = np.empty(L + 1, np.int64)  # next choice to try at this depth
    path = np.empty(L, np.int64)
    for g in range(G):
        j = gveh[g]
        k = 0
        while k < K and groups[g, k] >= 0:
            k += 1
        a, b = off[j], off[j + 1]
        nplan = b - a
        total = nplan + 2 * k
        # choices at a depth: the plan's stops (kept order: its next one only), then the new
        nfirst = nplan if reorder else 1
        boff = nplan if reorder else 0
        choices = nfirst + 2 * k
        full = (np.int64(1) << np.int64(boff + 2 * k)) - 1
        init_mask = np.int64(0)
        for i in range(k):
            if not r_hasdrop[groups[g, i]]:
                init_mask |= np.int64(1) << np.int64(boff + 2 * i + 1)
                total -= 1
        best = INF
        best_end = INF
        nodes = 0
        cut = False
        st_time[0] = start[j]
        st_occ[0] = load[j]
        st_cost[0] = 0.0
        st_pos[0] = -1
        st_next[0] = a
        st_mask[0] = init_mask
        st_try[0] = 0
        d = 0
        while d >= 0:
            c = st_try[d]
            if c >= choices or d == total:
                d -= 1
                continue
            st_try[d] = c + 1
            pos = st_pos[d]
            t0 = st_time[d]
            mask = st_mask[d]
            if c < nfirst:  # a stop of the plan
                if reorder:
                    s = a + c
                    if mask & (np.int64(1) << np.int64(c)):
                        continue
                    q = p_pred[s]
                    if q >= 0 and not (mask & (np.int64(1) << np.int64(q - a))):
                        continue
                else:
                    s = st_next[d]
                    if s >= b:
                        continue
                if pos == -1:
                    t = first_eta[j] if s == a else t0 + vp[s]
                elif pos >= 0:
                    if reorder:
                        t = t0 + ppa[poff[j] + (pos - a) * nplan + (s - a)]
                    else:
                        t = t0 + pp[pos]
                else:
                    t = t0 + np_[-2 - pos, s]
                if t > p_limit[s] + tol:
                    continue
                occ = st_occ[d] + p_pax[s]
                if occ > cap[j]:
                    continue
                add = 0.0
                if p_drop[s] and objective == 0:
                    add = t - p_eta[s]
                dep = leave(t, p_e[s], p_svc[s])
                if dep > until[j] + tol:  # departures only grow: the plan would end too late
                    continue
                nodes += 1
                st_time[d + 1] = dep
                st_occ[d + 1] = occ
                st_cost[d + 1] = st_cost[d] + add
                st_pos[d + 1] = s
                st_next[d + 1] = s + 1
                st_mask[d + 1] = mask | (np.int64(1) << np.int64(c)) if reorder else mask
                path[d] = -(s - a) - 1
            else:
                x = c - nfirst  # group-local stop: request x // 2, pickup if even
                bit = np.int64(1) << np.int64(boff + x)
                if mask & bit:
                    continue
                i = x // 2
                pick = x % 2 == 0
                if not pick and not (mask & (bit >> np.int64(1))):
                    continue
                r = groups[g, i]
                gx = 2 * r + (0 if pick else 1)
                if pos == -1:
                    t = t0 + vn[j, gx]
                elif pos >= 0:
                    t = t0 + pn[pos, gx]
                else:
                    t = t0 + nn[-2 - pos, gx]
                limit = r_lp[r] if pick else r_ld[r]
                if t > limit + tol:
                    continue
                add = 0.0
                serve = 0.0
                e = r_e[r] if pick else -INF  # (a pickup waits for its earliest time)
                if pick:
                    if r_hasdrop[r]:
                        occ = st_occ[d] + r_pax[r]
                    else:
                        occ = st_occ[d]
                        serve = svc
                        if objective == 0:  # (served from the start of its service)
                            add = leave(t, e, 0.0) - r_rel[r]
                else:
                    occ = st_occ[d] - r_pax[r]
                    serve = svc
                    if objective == 0:
                        add = t - r_rel[r] - r_direct[r]
                if occ > cap[j]:
                    continue
                dep = leave(t, e, serve)
                if dep > until[j] + tol:
                    continue
                nodes += 1
                st_time[d + 1] = dep
                st_occ[d + 1] = occ
                st_cost[d + 1] = st_cost[d] + add
                st_pos[d + 1] = -2 - gx
                st_next[d + 1] = st_next[d]
                st_mask[d + 1] = mask | bit
                path[d] = x
            d += 1
            st_try[d] = 0
            if d == total:
                if (reorder or st_next[d] == b) and st_mask[d] == full:
                    cost = st_cost[d]
                    if objective == 1:
                        cost = st_time[d] - old_end[j]
                    if cost < best - 1e-12:
                        best = cost
                        best_end = st_time[d]
                        for q in range(total):
                            out_order[g, q] = path[q]
                        for q in range(total, L):
                            out_order[g, q] = -99
                d -= 1
            if nodes >= budget:
                cut = True
                break
        out_cost[g] = best
        out_cut[g] = cut
        out_end[g] = best_end


_ORDERS = np.array([[0, 1, 2], [0, 2, 1], [1, 0, 2]], np.int64)


@jit
def _pair_shareable(now, nn, r_pax, r_lp, r_ld, r_e, svc, cap_max, tol, orders,
                    out):  # pragma: no cover - compiled
    m = r_pax.size
    for r in range(m):
        out[r, r] = False
        for q in range(r + 1, m):
            ok = False
            for first in range(2):
                u = r if first == 0 else q
                v = q if first == 0 else r
                if now > r_lp[u] + tol:
                    continue
                # after u's pickup: 0 v's pickup, 1 u's drop-off, 2 v's drop-off
                for o in range(3):
                    t = leave(now, r_e[u], 0.0)
                    occ = r_pax[u]
                    prev = 2 * u
                    feasible = True
                    for step in range(3):
                        code = orders[o, step]
                        if code == 0:
                            x = 2 * v
                            lim = r_lp[v]
                        elif code == 1:
                            x = 2 * u + 1
                            lim = r_ld[u]
                        else:
                            x = 2 * v + 1
                            lim = r_ld[v]
                        t = t + nn[prev, x]
                        if t > lim + tol:
                            feasible = False
                            break
                        if code == 0:
                            occ += r_pax[v]
                            if occ > cap_max:
                                feasible = False
                                break
                            t = leave(t, r_e[v], 0.0)
                        else:
                            occ -= r_pax[u] if code == 1 else r_pax[v]
                            t = leave(t, -INF, svc)
                        prev = x
                    if feasible:
                        ok = True
                        break
                if ok:
                    break
            out[r, q] = ok
            out[q, r] = ok


def pair_shareable(now, nn, r_pax, r_lp, r_ld, r_e, svc, cap_max, tol):
    """``(m, m)`` bool: ``[r, q]`` True when one vehicle standing at the pickup of ``r`` or of
    ``q`` at ``now`` could serve both (some order of their four stops, each within its limit,
    each pickup starting no sooner than its earliest time ``r_e``, at most ``cap_max`` seats):
    a necessary condition for any vehicle to serve them together (a real vehicle reaches its
    first pickup at ``now`` or later, drives obey the triangle inequality, and a later arrival
    never leaves a stop sooner)."""
    out = np.zeros((r_pax.size, r_pax.size), dtype=bool)
    _pair_shareable(float(now), nn, r_pax, r_lp, r_ld, r_e, float(svc), int(cap_max),
                    float(tol), _ORDERS, out)
    return out
