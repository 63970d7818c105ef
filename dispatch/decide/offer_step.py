"""The offer step of a hand-out: each request a decision gives a vehicle is offered to its
rider (:class:`dispatch.api.acceptor.Offer`) before the vehicle gets its stops; a declined pair is
not handed out (see :mod:`dispatch.api.acceptor`).

The dispatcher (:meth:`dispatch.decide.dispatcher.Dispatcher._hand_out`) calls
:meth:`Offering.offer` once per pair it is about to hand out, with the estimates of the plan
the allocator chose, taken from where the decision put them: a multi-request route's planned
times (:func:`route_estimates`), an insertion into the vehicle's plan
(:func:`insertion_estimates`), or, for a vehicle without a plan (capacity 1, the pickup-time
objective), the decision's cost (travel seconds to the pickup) and the direct drive
(:func:`plain_estimates`). A request is offered only until it accepts once: one re-opened by a
breakdown or given up by a re-assignment is not asked again.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from dispatch.api.acceptor import Acceptor, Offer, Pricing
from dispatch.plan.stops import DROPOFF, PICKUP
from dispatch.plan.tasks import TaskBook, TaskState

if TYPE_CHECKING:
    from dispatch.decide.tally import Blame
    from dispatch.plan.tasks import Task

log = logging.getLogger(__name__)


#: ``(pickup_at, dropoff_at, pooled, ready_at)``: the pickup's service start, the drop-off,
#: whether the ride is shared, and when the rider is ready at the pickup (the release; a booked
#: rider's departure, a walker's arrival at the meeting point)
Estimates = tuple[float, float, bool, float]


def _ready(task: Task, earliest: float) -> float:
    return earliest if earliest > task.released_at else task.released_at


def plain_estimates(task: Task, decided_at: float, cost: float) -> Estimates:
    """:data:`Estimates` of a vehicle without a plan: it reaches the pickup
    ``cost`` seconds after the decision (a booked pickup no sooner than its departure: the
    vehicle waits there) and drives the direct route (0 s where it is unknown or the request
    has no drop-off); never pooled."""
    pickup = max(decided_at + cost, task.earliest_pickup)
    direct = task.direct_time
    ride = direct if task.dropoff is not None and direct == direct else 0.0
    return pickup, pickup + ride, False, _ready(task, task.earliest_pickup)


def insertion_estimates(task: Task, stops: list, load: int, at) -> Estimates:
    """:data:`Estimates` of an insertion ``at``
    (:class:`dispatch.plan.insertion.Insertion`) into the plan ``stops`` of a vehicle with ``load``
    on board: its planned times (the pickup's service start: its arrival, or its earliest
    time where the vehicle arrives sooner), and whether another rider is on board at the pickup or
    between the pickup and the drop-off (the stops ``at.i .. at.j - 1`` of the plan)."""
    before = load if at.i == 0 else stops[at.i - 1].occupancy
    pooled = before > 0 or (task.dropoff is not None
                            and any(stops[k].occupancy > 0 for k in range(at.i, at.j)))
    # the pickup's service starts no sooner than its earliest time (a walking rider's
    # boarding, a booked departure): the vehicle waits there
    e = at.meeting.earliest if at.meeting is not None else task.earliest_pickup
    pickup = max(at.pickup_at, e)
    dropoff = at.dropoff_at if task.dropoff is not None else pickup
    return pickup, dropoff, bool(pooled), _ready(task, e)


def route_estimates(task: Task, rows: list, times: list[float], load: int) -> Estimates:
    """:data:`Estimates` of ``task`` in a route (stop rows and planned
    arrival ``times``, :meth:`dispatch.plan.operator.Operator.route_times`) of a vehicle with
    ``load`` on board (the pickup's service start, no sooner than its row's earliest time):
    pooled when more than its own riders are on board at any stop of the ride."""
    tid = task.id
    kp = next(k for k, r in enumerate(rows) if r.kind == PICKUP and r.task_id == tid)
    kd = next((k for k, r in enumerate(rows) if r.kind == DROPOFF and r.task_id == tid), kp)
    on = load
    pooled = False
    for k, r in enumerate(rows):
        on += r.passengers
        if k == kp and on - r.passengers > 0:
            pooled = True  # someone on board when it is picked up
        if kp <= k < kd and on > task.passengers:
            pooled = True
    pickup = max(times[kp], rows[kp].earliest)  # (service waits for its earliest time)
    return pickup, (times[kd] if kd != kp else pickup), pooled, _ready(task, rows[kp].earliest)


class Offering:
    """The run's offers: the acceptor, its random stream, the pricing and the retries; it
    counts and closes what riders decline."""

    def __init__(self, book: TaskBook, acceptor: Acceptor, rng: np.random.Generator,
                 *, retries: int, pricing: Pricing | None,
                 metres: Callable[[object, object], float] | None, blame: Blame) -> None:
        self.book, self.acceptor, self.rng = book, acceptor, rng
        self.retries, self.pricing, self.metres, self.blame = retries, pricing, metres, blame
        #: requests that accepted an offer (never asked again)
        self.accepted: set[int] = set()
        self._metres: dict[int, float] = {}  # request id -> metres of its direct route
        #: declined pairs whose request stays open for a re-offer (the dispatcher wakes)
        self.reoffer = False

    def asks(self, task: Task) -> bool:
        """Whether ``task``'s rider is asked (not yet accepted an offer)."""
        return task.id not in self.accepted

    def fare(self, task: Task, pooled: bool) -> float:
        """The fare of ``task`` (nan without ``[pricing]``)."""
        if self.pricing is None:
            return math.nan
        if task.dropoff is None:
            return self.pricing.fare(0.0, 0.0, pooled)
        metres = self._metres.get(task.id)
        if metres is None:
            metres = self._metres[task.id] = float(self.metres(task.loc, task.dropoff))
        direct = task.direct_time if task.direct_time == task.direct_time else 0.0
        return self.pricing.fare(metres, direct, pooled)

    def offer(self, task: Task, vehicle_id: int, now: float,
              estimates: Estimates) -> bool:
        """Make ``task``'s rider the offer of ``estimates`` (:data:`Estimates`) from vehicle
        ``vehicle_id``: True when accepted. A declined request is closed ``declined`` once it
        has been offered ``retries + 1`` times; before that it stays open for a later
        decision."""
        pickup_at, dropoff_at, pooled, ready_at = estimates
        task.offers += 1
        fare = self.fare(task, pooled)
        task.fare = fare
        offer = Offer(task.view(), vehicle_id, now, task.released_at, pickup_at, dropoff_at,
                      task.direct_time, fare, pooled, task.offers, ready_at)
        try:
            yes = bool(self.acceptor.accept(offer, self.rng))
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self.blame.failed("acceptor", self.acceptor, e) from e
        if yes:
            self.accepted.add(task.id)
            self._metres.pop(task.id, None)
            return True
        if task.offers > self.retries:  # (its close emits the ``decline`` event)
            self._metres.pop(task.id, None)
            self.book.close(task, TaskState.DECLINED)
        else:  # open for a later decision: each declined offer is one ``decline`` event
            self.book.bus.emit(now, "decline", vehicle_id, task.id, task.loc)
            self.reoffer = True
        return False
