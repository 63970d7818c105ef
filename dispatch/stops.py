"""A vehicle's plan as data: its stops, the one schedule rule, and where a new request fits.

A :class:`Stop` is one thing a vehicle will do at one place, of a declared kind: pick a
request's passengers up (:data:`PICKUP`; a point task of the voxel world is a pickup that
completes the task), drop them off (:data:`DROPOFF`), charge (:data:`CHARGE`), reposition
(:data:`REPOSITION`), wait or park (:data:`WAIT`), return to a depot (:data:`DEPOT`). A stop
serving no request has ``task=None``. A vehicle owns an ordered list of them
(:attr:`dispatch.vehicles.Vehicle.stops`); its SimPy process drives the list stop by stop
(:class:`dispatch.vehicles.Operator`), a decision inserts stops (:func:`insert`), a breakdown
or a re-assignment removes them.

**The schedule rule** (the only one: the compiled insertion, ``rtv``'s orders, the answer
checks, :meth:`dispatch.vehicles.Operator.route_times` and the test references all use
:func:`leave` and :func:`timetable`): arrival at a stop = departure from the stop before + the
drive between them; service starts at ``max(arrival, earliest)`` (a vehicle early for a stop
waits); departure = that start + the stop's ``service`` seconds. A plan is feasible when no
occupancy exceeds the vehicle's capacity and every stop is reached by its ``latest`` time
(within ``tol``; Alonso-Mora et al., PNAS 2017): a pickup by release + ``max_wait``, a drop-off
by release + direct free-flow time + ``max_delay``. A request's stops open at its release,
which is never later than the decision, so they never wait.

:func:`insertion_costs` gives, for each (vehicle, request) pair of a decision, the cheapest
feasible insertion of the request's pickup and drop-off into the vehicle's stop list (every
pair of positions, in O(k^2) per pair with the schedule's slack instead of re-simulating; a
plan with a stop that may wait is re-simulated by the rule), or ``inf``; it is compiled
(:mod:`dispatch._plan_kernel`) because busy vehicles make it the hot path of pooled dispatch.
The functions of the rule here are plain Python that numba compiles as they are: the compiled
kernels call the compiled twins, Python callers these.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from dispatch.locations import Location
    from dispatch.tasks import Task

#: stop kinds (the values may be written to Parquet)
PICKUP, DROPOFF, CHARGE, REPOSITION, WAIT, DEPOT = (
    "pickup", "dropoff", "charge", "reposition", "wait", "depot")
KINDS = (PICKUP, DROPOFF, CHARGE, REPOSITION, WAIT, DEPOT)
#: ``objective`` codes of :func:`insertion_costs`
PICKUP_TIME, ADDED_TIME = 0, 1
OBJECTIVES = {"pickup_time": PICKUP_TIME, "added_time": ADDED_TIME}
#: how late a stop may be reached and still count as on time (rounding of summed seconds)
TOL = 1e-9


@dataclass(eq=False, slots=True)
class Stop:
    """One stop of a vehicle's plan.

    ``kind`` one of :data:`KINDS`; ``task`` the request it serves (None: none, e.g. a charger
    visit). ``passengers`` is what the stop changes on board (+n at a pickup, -n at a
    drop-off, 0 otherwise); ``occupancy`` what is on board after it. ``latest`` is the time
    window's end (``inf``: none), ``earliest`` its start (service starts no sooner: the
    vehicle waits; ``-inf``: none, as for a request's stops, open since its release).
    ``leg`` is the planned drive in seconds from the stop before it (for the first stop: from
    where the vehicle stood when the stop became first), kept so a decision reads the plan's
    schedule without routing it again. ``completes``: the task ends here (after the service);
    ``service``: the seconds the stop takes once started."""

    kind: str
    task: Task | None
    loc: Location
    passengers: int
    latest: float
    completes: bool
    occupancy: int = 0
    leg: float = 0.0
    earliest: float = -math.inf
    service: float = 0.0


class PlannedStop(NamedTuple):
    """A stop of a route an allocator hands out (:attr:`dispatch.contracts.Allocation.routes`,
    checked by :func:`dispatch.answers.route_stops`): its kind, the request's id, where, the
    passengers it changes, the latest time, and whether the request completes there (None: a
    stop of the vehicle's plan, as the plan has it)."""

    kind: str
    task_id: int
    loc: Location
    passengers: int
    latest: float
    completes: bool | None


# ----------------------------------------------------------------------------- the rule
def leave(arrive: float, earliest: float, service: float) -> float:
    """Departure from a stop reached at ``arrive``: service starts at ``max(arrive,
    earliest)`` and lasts ``service`` seconds."""
    return (earliest if earliest > arrive else arrive) + service


def leave_late(arrive: float, push: float, earliest: float, service: float) -> float:
    """Departure from a stop planned to be reached at ``arrive`` and reached ``push`` seconds
    later (:func:`leave` of ``arrive + push``, summed as ``arrive + service + push`` where the
    stop does not wait, so a push adds to the planned departure as it did)."""
    if earliest > arrive + push:
        return earliest + service
    return arrive + service + push


def later(push: float, arrive: float, earliest: float) -> float:
    """How much later than planned a stop planned to be reached at ``arrive`` is left when it
    is reached ``push`` seconds later: ``push`` unless a wait for ``earliest`` takes some up
    (or, reached earlier, makes some)."""
    reached = arrive + push
    if arrive >= earliest and reached >= earliest:
        return push
    return (reached if reached >= earliest else earliest) - \
        (arrive if arrive >= earliest else earliest)


def timetable(first: float, legs, earliest, service, latest, passengers, load: int, cap: int,
              tol: float, out) -> tuple[int, bool]:
    """The rule over a whole stop sequence: the first stop is reached at ``first``, stop
    ``k > 0`` ``legs[k - 1]`` seconds after leaving stop ``k - 1``; ``out[k]`` gets each
    arrival (up to the first stop that breaks a limit). Returns ``(-1, False)`` when every
    stop keeps its limits, else the first stop that does not and whether it is the capacity
    (``load`` on board before the first stop, ``cap`` seats) that it breaks rather than its
    ``latest``."""
    t, occ = first, load
    for k in range(len(out)):
        if k:
            t = t + legs[k - 1]
        out[k] = t
        occ += passengers[k]
        if occ > cap:
            return k, True
        if t > latest[k] + tol:
            return k, False
        t = leave(t, earliest[k], service[k])
    return -1, False


def schedule(first: float, stops: list[Stop]) -> list[float]:
    """Arrival times at ``stops`` when the first is reached at ``first`` (seconds), by the
    rule and each stop's ``leg``."""
    out, t = [], first
    for k, s in enumerate(stops):
        if k:
            t += s.leg
        out.append(t)
        t = leave(t, s.earliest, s.service)
    return out


def occupancies(load: int, stops: list[Stop]) -> None:
    """Set each stop's ``occupancy`` from ``load`` on board before the first."""
    for s in stops:
        load += s.passengers
        s.occupancy = load


# ----------------------------------------------------------------------------- plan changes
def insert(plan: list, request: list, i: int, j: int) -> list:
    """The plan change of a decision: ``plan`` (stops, or anything kept per stop, such as
    their times) with ``request``'s pickup after its ``i``-th stop (0: first) and, where
    the request has one, its drop-off after its ``j``-th (``j == i``: right after the
    pickup). A new list; ``plan`` is not changed."""
    if len(request) == 1:
        return plan[:i] + request + plan[i:]
    p, d = request
    return plan[:i] + [p] + plan[i:j] + [d] + plan[j:]


def pushed(times: list[float], stops: list[Stop], i: int, j: int, shift1: float,
           shift2: float) -> list[float]:
    """The arrival ``times`` at ``stops`` once a request is inserted (:class:`Insertion`):
    stops ``i..j-1`` are reached ``shift1`` seconds later, stops from ``j`` on ``shift2``
    later, less what a wait of a stop between takes up (:func:`later`)."""
    out, push = [], 0.0
    for k, (t, s) in enumerate(zip(times, stops)):
        if k == i:
            push = shift1
        if k == j:
            push = shift2
        out.append(t + push)
        push = later(push, t, s.earliest)
    return out


# ----------------------------------------------------------------------------- insertion
class Insertion(NamedTuple):
    """Where a request's stops go in a plan (:meth:`Insertions.of`): the pickup after the
    plan's ``i``-th stop (0: first), the drop-off after its ``j``-th (``j == i``: right after
    the pickup); planned arrival at the pickup and the drop-off; how much later the plan's
    stop ``i`` is reached (``shift1``) and its stop ``j`` (``shift2``; see :func:`pushed`)."""

    i: int
    j: int
    pickup_at: float
    dropoff_at: float
    shift1: float
    shift2: float


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

    def of(self, q: int) -> Insertion:
        """Pair ``q``'s insertion."""
        return Insertion(int(self.i[q]), int(self.j[q]), float(self.pickup_at[q]),
                         float(self.dropoff_at[q]), float(self.shift1[q]),
                         float(self.shift2[q]))


def insertion_costs(rows, cols, ready, first_tt, off, s_arr, s_svc, s_latest, s_occ, load, cap,
                    to_p, from_p, to_d, from_d, pd_tt, req_n, req_lp, req_ld, req_svc_p,
                    req_svc_d, objective: int, s_earliest=None, req_earliest=None
                    ) -> Insertions:
    """The cheapest feasible insertion of each candidate pair (``rows[q]``, ``cols[q]``): a
    vehicle ``v`` (its stops are ``off[v]:off[v+1]`` of the flat stop arrays) and a request
    ``r``, by the schedule rule (see the module).

    Vehicles: ``ready[v]`` when it can leave where it is (now, or the end of a service),
    ``load[v]`` on board now, ``cap[v]`` seats. Stops (flat): planned arrival ``s_arr``,
    service ``s_svc``, ``s_latest``, occupancy after it ``s_occ``, ``s_earliest`` (None: no
    stop waits). Pair: ``first_tt[q]`` drive seconds from the vehicle's location to the
    pickup. Travel seconds between a stop ``g`` and a request ``r``: ``to_p[g, r]`` (stop ->
    pickup), ``from_p[r, g]`` (pickup -> stop), ``to_d[g, r]``, ``from_d[r, g]``; ``pd_tt[r]``
    pickup -> drop-off. Request: ``req_n`` passengers, pickup by ``req_lp``, drop-off by
    ``req_ld``, service at pickup / drop-off, pickup from ``req_earliest`` (None: its release,
    past). ``objective``: :data:`PICKUP_TIME` (cost = pickup time - ready time) or
    :data:`ADDED_TIME` (cost = how much later the plan ends). Ties (within 1e-12 s) go to the
    pickup earlier by more than 1e-9 s, then to the first positions. A plan already late
    somewhere (traffic ran slower than planned) takes no insertion that delays the late stop
    further."""
    m = len(rows)
    out = (np.full(m, np.inf), np.full(m, -1, dtype=np.int64), np.full(m, -1, dtype=np.int64),
           np.full(m, np.inf), np.full(m, np.inf), np.zeros(m), np.zeros(m))
    if m:
        from dispatch._plan_kernel import insert_pairs

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
