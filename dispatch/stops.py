"""A vehicle's plan as data: its stop list, and where a new request fits into it.

A :class:`Stop` is one thing a vehicle will do at one place: pick a request's passengers up, or
drop them off (a point task of the voxel world is a pickup that completes the task). A vehicle
owns an ordered list of them (:attr:`dispatch.vehicles.Vehicle.stops`); its SimPy process
drives the list stop by stop (:class:`dispatch.vehicles.Operator`), a decision inserts stops,
a breakdown or a re-assignment removes them, nothing else changes the plan.

Feasibility (Alonso-Mora et al., PNAS 2017): a stop list is feasible when no occupancy exceeds
the vehicle's capacity and every stop is reached by its ``latest`` time: a pickup by release +
``max_wait``, a drop-off by release + direct free-flow time + ``max_delay``. Vehicles never wait
for a request (a request is released before it is offered), so a schedule is a running sum:
arrival at a stop = departure from the one before + the drive between them, departure = arrival
+ the service time of a stop that completes a task.

:func:`insertion_costs` gives, for each (vehicle, request) pair of a decision, the cheapest
feasible insertion of the request's pickup and drop-off into the vehicle's stop list (every
pair of positions, in O(k^2) per pair with the schedule's slack instead of re-simulating), or
``inf``; it is compiled (numba) because busy vehicles make it the hot path of pooled dispatch.
:func:`brute_force_insertion` is the plain exhaustive search it is tested against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from dispatch.locations import Location
    from dispatch.tasks import Task

PICKUP, DROPOFF = "pickup", "dropoff"
#: a charging visit (no request; :mod:`dispatch.charging`) and a repositioning move (no request;
#: :mod:`dispatch.reposition`), driven by the operator like any stop
CHARGE, REPOSITION = "charge", "reposition"
#: ``objective`` codes of :func:`insertion_costs`
PICKUP_TIME, ADDED_TIME = 0, 1
OBJECTIVES = {"pickup_time": PICKUP_TIME, "added_time": ADDED_TIME}


@dataclass(eq=False, slots=True)
class Stop:
    """One stop of a vehicle's plan.

    ``passengers`` is what the stop changes on board (+n at a pickup, -n at a drop-off, 0 at a
    point task); ``occupancy`` what is on board after it. ``latest`` is the time window's end
    (``inf``: none); the window opens at the request's release. ``leg`` is the planned drive in
    seconds from the stop before it (for the first stop: from where the vehicle stood when the
    stop became first), kept so a decision reads the plan's schedule without routing it again.
    ``completes``: the task ends here (after the service time)."""

    kind: str
    task: Task
    loc: Location
    passengers: int
    latest: float
    completes: bool
    occupancy: int = 0
    leg: float = 0.0
    #: a charge stop's visit (:class:`dispatch.charging.Visit`: the station, the target, what
    #: the vehicle does there); None for every other stop
    visit: Any = None

    @property
    def earliest(self) -> float:
        return self.task.released_at


def occupancies(load: int, stops: list[Stop]) -> None:
    """Set each stop's ``occupancy`` from ``load`` on board before the first."""
    for s in stops:
        load += s.passengers
        s.occupancy = load


def schedule(first: float, stops: list[Stop], service: float) -> list[float]:
    """Arrival times at ``stops`` when the first is reached at ``first`` (seconds)."""
    out, t = [], first
    for k, s in enumerate(stops):
        if k:
            t += s.leg
        out.append(t)
        if s.completes:
            t += service
    return out


def _jit(fn):
    from dispatch._compiled import jit

    return jit(fn)


def _insert_pairs(rows, cols, ready, first_tt, off, s_arr, s_svc, s_latest, s_occ,
                  load, cap, to_p, from_p, to_d, from_d, pd_tt, req_n, req_lp, req_ld,
                  req_svc_p, req_svc_d, objective, out_cost, out_i, out_j, out_pick, out_drop,
                  out_s1, out_s2):  # pragma: no cover - compiled
    """The compiled kernel of :func:`insertion_costs` (one loop over the candidate pairs)."""
    inf = np.inf
    tol = 1e-9
    for q in range(rows.size):
        v, r = rows[q], cols[q]
        a, b = off[v], off[v + 1]
        k = b - a
        n = req_n[r]
        t0 = ready[v]
        best, bi, bj, bpick, bdrop, bs1, bs2 = inf, -1, -1, inf, inf, 0.0, 0.0
        # slack[m]: how much later stops m.. of the plan may be reached (m = k: none follow)
        slack = np.empty(k + 1)
        slack[k] = inf
        for m in range(k - 1, -1, -1):
            sl = s_latest[a + m] - s_arr[a + m]
            slack[m] = sl if sl < slack[m + 1] else slack[m + 1]
        end_old = t0 if k == 0 else s_arr[b - 1] + s_svc[b - 1]
        for i in range(k + 1):  # the pickup after the plan's i-th stop (0: first)
            occ_i = load[v] if i == 0 else s_occ[a + i - 1]
            if occ_i + n > cap[v]:
                continue
            if i == 0:
                dep = t0
                arr_p = t0 + first_tt[q]
            else:
                dep = s_arr[a + i - 1] + s_svc[a + i - 1]
                arr_p = dep + to_p[a + i - 1, r]
            if arr_p > req_lp[r] + tol:
                continue
            leave_p = arr_p + req_svc_p[r]
            old = 0.0  # the drive it replaces: to the next stop (from ``dep``)
            if i < k:
                old = s_arr[a + i] - dep
            # the drop-off right after the pickup
            arr_d = leave_p + pd_tt[r]
            if arr_d <= req_ld[r] + tol:
                leave_d = arr_d + req_svc_d[r]
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
                dep_j = s_arr[a + j - 1] + s_svc[a + j - 1] + delta1
                arr_d = dep_j + to_d[a + j - 1, r]
                if arr_d > req_ld[r] + tol:
                    continue
                leave_d = arr_d + req_svc_d[r]
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


_KERNEL = None


def _kernel():
    global _KERNEL
    if _KERNEL is None:
        _KERNEL = _jit(_insert_pairs)
    return _KERNEL


@dataclass(frozen=True)
class Insertions:
    """Cheapest feasible insertions of a decision's candidate pairs (arrays aligned with the
    pairs): ``cost`` by the objective (``inf``: none feasible); the pickup goes after the plan's
    ``i``-th stop (0: before the first) and the drop-off after its ``j``-th (``j == i``: right
    after the pickup); planned arrival at the pickup ``pickup_at`` and drop-off ``dropoff_at``
    (absolute seconds); how much later the stops between the two are reached (``shift1``) and
    those after the drop-off (``shift2``)."""

    cost: np.ndarray
    i: np.ndarray
    j: np.ndarray
    pickup_at: np.ndarray
    dropoff_at: np.ndarray
    shift1: np.ndarray
    shift2: np.ndarray

    def of(self, q: int) -> tuple:
        """Pair ``q``'s ``(i, j, pickup_at, dropoff_at, shift1, shift2)``."""
        return (int(self.i[q]), int(self.j[q]), float(self.pickup_at[q]),
                float(self.dropoff_at[q]), float(self.shift1[q]), float(self.shift2[q]))


def insertion_costs(rows, cols, ready, first_tt, off, s_arr, s_svc, s_latest, s_occ, load, cap,
                    to_p, from_p, to_d, from_d, pd_tt, req_n, req_lp, req_ld, req_svc_p,
                    req_svc_d, objective: int) -> Insertions:
    """The cheapest feasible insertion of each candidate pair (``rows[q]``, ``cols[q]``): a
    vehicle ``v`` (its stops are ``off[v]:off[v+1]`` of the flat stop arrays) and a request
    ``r``.

    Vehicles: ``ready[v]`` when it can leave where it is (now, or the end of a service),
    ``load[v]`` on board now, ``cap[v]`` seats. Stops (flat): planned arrival ``s_arr``,
    service after it ``s_svc``, ``s_latest``, occupancy after it ``s_occ``. Pair: ``first_tt[q]``
    drive seconds from the vehicle's location to the pickup. Travel seconds between a stop
    ``g`` and a request ``r``: ``to_p[g, r]`` (stop -> pickup), ``from_p[r, g]`` (pickup -> stop),
    ``to_d[g, r]``, ``from_d[r, g]``; ``pd_tt[r]`` pickup -> drop-off. Request: ``req_n``
    passengers, pickup by ``req_lp``, drop-off by ``req_ld``, service at pickup / drop-off.
    ``objective``: :data:`PICKUP_TIME` (cost = pickup time - ready time) or :data:`ADDED_TIME`
    (cost = how much later the plan ends). Ties (within 1e-12 s) go to the pickup earlier by
    more than 1e-9 s, then to the first positions. A plan already late somewhere (traffic ran slower than planned) takes no
    insertion that delays the late stop further."""
    m = len(rows)
    out = (np.full(m, np.inf), np.full(m, -1, dtype=np.int64), np.full(m, -1, dtype=np.int64),
           np.full(m, np.inf), np.full(m, np.inf), np.zeros(m), np.zeros(m))
    if m:
        f = np.ascontiguousarray
        _kernel()(f(rows, np.int64), f(cols, np.int64), f(ready, float), f(first_tt, float),
                  f(off, np.int64), f(s_arr, float), f(s_svc, float), f(s_latest, float),
                  f(s_occ, np.int64), f(load, np.int64), f(cap, np.int64),
                  f(to_p, float), f(from_p, float), f(to_d, float), f(from_d, float),
                  f(pd_tt, float), f(req_n, np.int64), f(req_lp, float), f(req_ld, float),
                  f(req_svc_p, float), f(req_svc_d, float), int(objective), *out)
    return Insertions(*out)


def brute_force_insertion(ready: float, first_tt, stops: list[tuple], load: int, cap: int,
                          request: tuple, tt, objective: int):
    """The exhaustive search :func:`insertion_costs` must agree with: every (pickup, drop-off)
    position pair, each new plan re-simulated from scratch. ``stops``: ``(loc, passengers,
    latest, service)``; ``request``: ``(pickup loc, drop-off loc, passengers, pickup latest,
    drop-off latest, service at pickup, service at drop-off)``; ``first_tt(loc)``: seconds from
    the vehicle to ``loc``; ``tt(a, b)``: seconds between two locations. Returns ``(cost, i,
    j, pickup time)`` or ``(inf, -1, -1, inf)``."""
    p, d, n, lp, ld, svc_p, svc_d = request

    def simulate(plan):
        t, occ, prev, arrivals = ready, load, None, []
        for loc, pax, latest, svc in plan:
            t += first_tt(loc) if prev is None else tt(prev, loc)
            occ += pax
            if occ > cap or t > latest + 1e-9:
                return None
            arrivals.append(t)
            t += svc
            prev = loc
        return arrivals, t

    base = simulate(stops)
    end_old = ready if not stops else base[1] if base else math.nan
    best = (math.inf, -1, -1, math.inf)
    k = len(stops)
    for i in range(k + 1):
        for j in range(i, k + 1):
            plan = list(stops)
            plan.insert(j, (d, -n, ld, svc_d))
            plan.insert(i, (p, n, lp, svc_p))
            got = simulate(plan)
            if got is None:
                continue
            arrivals, end = got
            pick = arrivals[i]
            c = pick - ready if objective == PICKUP_TIME else end - end_old
            if c < best[0] - 1e-12 or (c <= best[0] + 1e-12 and pick < best[3] - 1e-9):
                best = (c, i, j, pick)
    return best
