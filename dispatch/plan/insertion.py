"""Where a new request fits into a vehicle's plan: the cheapest feasible insertion of its pickup
and drop-off (:func:`insertion_costs`), for each (vehicle, request) pair of a decision, by the
plan's schedule rule (:mod:`dispatch.plan.stops`): every pair of positions, in O(k^2) per pair with
the schedule's slack instead of re-simulating (a plan with a stop that may wait is
re-simulated by the rule), or ``inf``. Compiled (:mod:`dispatch.plan._kernel`, imported on the
first call) because busy vehicles make it the hot path of pooled dispatch. The brute-force
reference it is tested against is independent, in the tests
(``tests/dispatch/reference.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class Insertion(NamedTuple):
    """Where a request's stops go in a plan (:meth:`Insertions.of`): the pickup after the
    plan's ``i``-th stop (0: first), the drop-off after its ``j``-th (``j == i``: right after
    the pickup); planned arrival at the pickup and the drop-off; how much later the plan's
    stop ``i`` is reached (``shift1``) and its stop ``j`` (``shift2``; see
    :func:`dispatch.plan.stops.pushed`); with meeting points where the rider boards and alights
    (:class:`dispatch.decide.meeting.Meeting`; None: door to door)."""

    i: int
    j: int
    pickup_at: float
    dropoff_at: float
    shift1: float
    shift2: float
    meeting: object = None


@dataclass(frozen=True)
class Insertions:
    """Cheapest feasible insertions of a decision's candidate pairs (arrays aligned with the
    pairs): ``cost`` by the objective (``inf``: none feasible), and the fields of
    :class:`Insertion`."""

    cost: np.ndarray
    i: np.ndarray
    j: np.ndarray
    pickup_at: np.ndarray
    dropoff_at: np.ndarray
    shift1: np.ndarray
    shift2: np.ndarray

    def take(self, q: np.ndarray) -> Insertions:
        """The insertions of the pairs ``q`` (indices), aligned with it."""
        return Insertions(self.cost[q], self.i[q], self.j[q], self.pickup_at[q],
                          self.dropoff_at[q], self.shift1[q], self.shift2[q])

    def of(self, q: int) -> Insertion:
        """Pair ``q``'s insertion."""
        return Insertion(int(self.i[q]), int(self.j[q]), float(self.pickup_at[q]),
                         float(self.dropoff_at[q]), float(self.shift1[q]),
                         float(self.shift2[q]))


def insertion_costs(rows, cols, *, ready, first_tt, off, s_arr, s_svc, s_latest, s_occ, load, cap,
                    to_p, from_p, to_d, from_d, pd_tt, req_n, req_lp, req_ld, req_svc_p,
                    req_svc_d, objective: int, s_earliest=None, req_earliest=None
                    ) -> Insertions:
    """The cheapest feasible insertion of each candidate pair (``rows[q]``, ``cols[q]``): a
    vehicle ``v`` (its stops are ``off[v]:off[v+1]`` of the flat stop arrays) and a request
    ``r``, by the schedule rule (:mod:`dispatch.plan.stops`).

    Vehicles: ``ready[v]`` when it can leave where it is (now, or the end of a service),
    ``load[v]`` on board now, ``cap[v]`` seats. Stops (flat): planned arrival ``s_arr``,
    service ``s_svc``, ``s_latest``, occupancy after it ``s_occ``, ``s_earliest`` (None: no
    stop waits). Pair: ``first_tt[q]`` drive seconds from the vehicle's location to the
    pickup. Travel seconds between a stop ``g`` and a request ``r``: ``to_p[g, r]`` (stop ->
    pickup), ``from_p[r, g]`` (pickup -> stop), ``to_d[g, r]``, ``from_d[r, g]``; ``pd_tt[r]``
    pickup -> drop-off. Request: ``req_n`` passengers, pickup by ``req_lp``, drop-off by
    ``req_ld``, service at pickup / drop-off, pickup from ``req_earliest`` (None: its release,
    past). ``objective``: :data:`dispatch.plan.stops.PICKUP_TIME` (cost = pickup time - ready
    time) or :data:`dispatch.plan.stops.ADDED_TIME` (cost = how much later the plan ends). Ties
    (within 1e-12 s) go to the pickup earlier by more than 1e-9 s, then to the first
    positions. A plan already late somewhere (traffic ran slower than planned) takes no
    insertion that delays the late stop further."""
    m = len(rows)
    out = (np.full(m, np.inf), np.full(m, -1, dtype=np.int64), np.full(m, -1, dtype=np.int64),
           np.full(m, np.inf), np.full(m, np.inf), np.zeros(m), np.zeros(m))
    if m:
        from dispatch.plan._kernel import insert_pairs

        f = np.ascontiguousarray
        s_e = np.full(len(s_arr), -np.inf) if s_earliest is None else f(s_earliest, float)
        r_e = np.full(len(req_n), -np.inf) if req_earliest is None else f(req_earliest, float)
        insert_pairs(f(rows, np.int64), f(cols, np.int64), f(ready, float), f(first_tt, float),
                     f(off, np.int64), f(s_arr, float), f(s_svc, float), f(s_latest, float),
                     f(s_occ, np.int64), f(load, np.int64), f(cap, np.int64),
                     f(to_p, float), f(from_p, float), f(to_d, float), f(from_d, float),
                     f(pd_tt, float), f(req_n, np.int64), f(req_lp, float), f(req_ld, float),
                     f(req_svc_p, float), f(req_svc_d, float), int(objective), s_e, r_e, *out)
    return Insertions(*out)


def candidate_pairs(cost, now: float, slots, planned, *, cap, free_at, lp, ld, n_req, ep, svc_p,
                    svc_d, pd, pickup_time: bool, out):
    """The set-up of a decision's insertions, compiled
    (:func:`dispatch.plan._kernel.candidate_pairs`, which says what it returns): the costs of
    the vehicles with empty plans written into ``out``, the busy ones' candidate pairs."""
    from dispatch.plan._kernel import candidate_pairs as kernel

    f = np.ascontiguousarray
    return kernel(f(cost, float), float(now), f(slots, np.int64), f(planned, np.bool_),
                  f(cap, np.int64), f(free_at, float), f(lp, float), f(ld, float),
                  f(n_req, np.int64), f(ep, float), f(svc_p, float), f(svc_d, float),
                  f(pd, float), bool(pickup_time), out)


def gather_rows(idx, length, fields):
    """The plans of the rows ``idx`` of a plan table (``length`` stops per row of each of the
    ``fields``: arrival, service, latest, occupancy, earliest, node), flat, compiled
    (:func:`dispatch.plan._kernel.gather_rows`): ``(off, arrival, service, latest,
    occupancy, earliest, node)``, row ``idx[i]``'s stops at ``off[i]:off[i + 1]``."""
    from dispatch.plan._kernel import gather_rows as kernel

    return kernel(np.ascontiguousarray(idx, np.int64), length, *fields)
