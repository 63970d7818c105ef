"""A vehicle's plan as data: its stops, the one schedule rule, and where a new request fits.

A :class:`Stop` is one thing a vehicle will do at one place, of a declared kind: pick a
request's passengers up (:data:`PICKUP`; a point task of the voxel world is a pickup that
completes the task), drop them off (:data:`DROPOFF`), charge (:data:`CHARGE`), reposition
(:data:`REPOSITION`), return to a depot (:data:`DEPOT`), take a driver's break
(:data:`dispatch.plan.breaks.BREAK`). A stop serving no request has ``task=None``. Each kind
is one declaration and one handler (a :class:`StopKind`), found in the table of
:mod:`dispatch.plan.kinds`. A vehicle owns an ordered list of stops, its plan
(:class:`dispatch.plan.vehicle_plan.Plan`); its SimPy process drives the plan stop by stop
(:class:`dispatch.plan.operator.Operator`), a decision inserts stops (:func:`insert`), a
breakdown or a re-assignment removes them.

**The schedule rule** (the only one: the compiled insertion, ``rtv``'s orders, the answer
checks, :meth:`dispatch.plan.operator.Operator.route_times` and the test references all use
:func:`leave` and :func:`timetable`): arrival at a stop = departure from the stop before + the
drive between them; service starts at ``max(arrival, earliest)`` (a vehicle early for a stop
waits); departure = that start + the stop's ``service`` seconds. A plan is feasible when no
occupancy exceeds the vehicle's capacity and every stop is reached by its ``latest`` time
(within ``tol``; Alonso-Mora et al., PNAS 2017): a pickup by release + ``max_wait``, a drop-off
by release + direct free-flow time + ``max_delay``. A request's stops open at its release,
which is never later than the decision, so they never wait.

The functions of the rule here are plain Python that numba compiles as they are
(:mod:`dispatch.plan._kernel`): compiled kernels call the compiled twins, Python callers
these. Where a new request fits into a plan is :mod:`dispatch.plan.insertion`'s question.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

if TYPE_CHECKING:
    from dispatch.locations import Location
    from dispatch.plan.tasks import Task

#: stop kinds (the values may be written to Parquet): a charging visit (no request;
#: :mod:`dispatch.fleet.chargers`), a repositioning move (no request;
#: :mod:`dispatch.fleet.repositioning`) and a return to the depot (:mod:`dispatch.fleet.shifts`)
#: are driven by the operator like any stop; their handlers: :mod:`dispatch.plan.kinds`
PICKUP, DROPOFF, CHARGE, REPOSITION, DEPOT = ("pickup", "dropoff", "charge", "reposition",
                                              "depot")
#: ``objective`` codes of :func:`dispatch.plan.insertion.insertion_costs`
PICKUP_TIME, ADDED_TIME = 0, 1
OBJECTIVES = {"pickup_time": PICKUP_TIME, "added_time": ADDED_TIME}
#: how late a stop may be reached and still count as on time (rounding of summed seconds)
TOL = 1e-9


@dataclass(eq=False, slots=True)
class Stop:
    """One stop of a vehicle's plan.

    ``kind`` a kind of :data:`dispatch.plan.kinds.TABLE`; ``task`` the request it serves
    (None: none, e.g. a charger visit). ``passengers`` is what the stop changes on board (+n
    at a pickup, -n at a drop-off, 0 otherwise); ``occupancy`` what is on board after it. ``latest`` is the time
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
    #: a charge stop's visit (:class:`dispatch.fleet.chargers.Visit`: the station, the target, what
    #: the vehicle does there); None for every other stop
    visit: Any = None
    #: the stop holds every seat (a driver's break): its ``occupancy`` is the vehicle's
    #: capacity, so no insertion carries a rider across it (:func:`occupancies`)
    holds_seats: bool = False


class PlannedStop(NamedTuple):
    """A stop of a route an allocator hands out (:attr:`dispatch.api.problem.Allocation.routes`,
    checked by :func:`dispatch.decide.answers.route_stops`): its kind, the request's id, where, the
    passengers it changes, the latest time, whether the request completes there (None: a
    stop of the vehicle's plan, as the plan has it) and the earliest start of its service
    (``-inf``: none; a booked pickup's requested departure)."""

    kind: str
    task_id: int
    loc: Location
    passengers: int
    latest: float
    completes: bool | None
    earliest: float = -math.inf


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
    if earliest <= arrive and earliest <= reached:
        return push
    return leave(reached, earliest, 0.0) - leave(arrive, earliest, 0.0)


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


def occupancies(load: int, stops: list[Stop], cap: int) -> None:
    """Set each stop's ``occupancy`` from ``load`` on board before the first; a stop that
    holds the seats (all ``cap`` of them) counts as full."""
    for s in stops:
        load += s.passengers
        s.occupancy = cap if s.holds_seats else load


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
    """The arrival ``times`` at ``stops`` once a request is inserted
    (:class:`dispatch.plan.insertion.Insertion`):
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


# ----------------------------------------------------------------------------- stop kinds
class StopKind:
    """How the operator drives one kind of stop: its declaration (what the stop means for the
    vehicle's state) and its handler (what happens on arrival). One instance per kind, in the
    table of :mod:`dispatch.plan.kinds`; a subclass that names no kind or handles no arrival
    is refused when it is defined."""

    #: the kind's name (:attr:`Stop.kind`)
    name: str = ""
    #: a vehicle whose plan holds it (and no request) is idle: a decision may give it a
    #: request (a repositioning move, the way home); else neither idle nor busy (a charging
    #: visit, a break)
    idle: bool = True
    #: a decision keeps it in the plan; False: giving the vehicle a request cuts it (a move)
    kept: bool = True
    #: the drive to it checks the battery (a repositioning move drives on at 0 kWh, as it
    #: always has: checking it strands such vehicles)
    checks_battery: bool = True

    def __init_subclass__(cls, **kw) -> None:
        super().__init_subclass__(**kw)
        if not cls.name or cls.arrive is StopKind.arrive:
            raise TypeError(f"stop kind {cls.__name__} must set name and define arrive()")

    def there(self, v, stop: Stop, now: float) -> bool:
        """The vehicle needs no drive to ``stop`` (it stands there already)."""
        return False

    def arrive(self, op, v, stop: Stop):
        """Generator run by the operator's process on arrival at ``stop`` (the first of
        ``v``'s plan): make the stop and take it off the plan. Returns True to drive on to
        the next stop, False when the process ends (the vehicle idle, or interrupted)."""
        raise NotImplementedError

    def dropped(self, op, v, stop: Stop) -> None:
        """The drive to ``stop`` ended without reaching it (a breakdown, an empty battery)."""
