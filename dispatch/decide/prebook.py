"""Prebooking: requests booked ahead of their departure, and the promise an accepted one is.

A request is *booked* when it is made before the time it wants to depart: a trace's
``booked_at`` column (seconds, or a date-time like its ``departure_time``; blank: not booked),
or for generated demand ``[tasks] prebook_share`` of the requests, drawn from the run's
prebooking stream, booked ``[tasks] prebook_lead`` seconds ahead. A booked request's
*requested departure* is its release time (a trace row's time; for generated demand the
booking time plus the lead): its ``released_at``, its pickup window ``[released_at,
released_at + max_wait]`` and its drop-off limit count from it, and its pickup stop's
``earliest`` (:class:`dispatch.plan.stops.Stop`) is it, so no vehicle picks it up sooner (a vehicle
early for it waits there, and may serve other requests before it where the insertion finds room).

When it enters dispatch is ``[dispatch] prebook``: ``"at_booking"`` (default: at its booking
time) or ``"lead"`` (``[dispatch] prebook_lead`` seconds before its departure, not before its
booking; default the ``[tasks] prebook_lead``). Entered, it is an open request like any other:
the first decision that can insert it into a vehicle's plan accepts it, and from then on it is
*promised* (the tasks table's ``promised``). A promise is kept: its stops stay in a plan (a
decision may insert other requests around them); only a breakdown takes them out, and then the
request is open again for any vehicle to take (moved between vehicles) until its pickup window
closes, when it ends ``failed`` (the breakdown broke the promise; the ``events`` table names
the vehicle's ``breakdown``). The summary counts ``promises`` and ``promises_broken`` (promised
requests that ended ``failed`` or ``expired``; one the run's end cuts is ``cut_off``, not
broken).

Prebooking needs plans (a road network): with it on, every decision inserts into the vehicles'
plans as a pooled fleet's do (:class:`dispatch.decide.pipeline.Pipeline` with ``pooled``), so a
vehicle holding a promise later in its plan still takes requests before it. An allocator that
builds its own routes (``multi_request``: ``rtv``) reads a booked pickup's earliest time from
its view (:attr:`dispatch.api.problem.TaskView.earliest`, :func:`earliest_views`) and the plans'
(:attr:`dispatch.api.problem.StopView.earliest`), and its routes wait for them by the one schedule
rule (:mod:`dispatch.plan.stops`); the dispatcher times every route by that rule, so no route picks
a
booked rider up before the requested departure.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dispatch.files.traces import Trips
from dispatch.plan.tasks import TaskSource, TaskState

#: ``[dispatch] prebook`` values
MODES = ("at_booking", "lead")


def synthesize(trips: Trips, share: float, lead: float, rng: np.random.Generator) -> Trips:
    """``trips`` with ``share`` of them (each independently, from ``rng``) booked ``lead``
    seconds before its release time (a booking before the run's start is made at 0)."""
    pick = rng.random(len(trips)) < share
    booked = np.where(pick, np.maximum(trips.t - lead, 0.0), math.nan)
    return replace(trips, booked_at=booked)


def entry_times(trips: Trips, mode: str, lead: float) -> np.ndarray:
    """When each trip enters dispatch: its release time where not booked; booked, its booking
    (``at_booking``) or ``lead`` seconds before its release, not before its booking
    (``lead``); never before 0."""
    b = trips.booked_at
    if b is None:
        return trips.t.copy()
    when = b if mode == "at_booking" else np.maximum(b, trips.t - lead)
    return np.where(np.isfinite(b), np.maximum(when, 0.0), trips.t)


def in_entry_order(trips: Trips, entry: np.ndarray) -> tuple[Trips, np.ndarray]:
    """``(trips, entry)`` reordered by entry time (stable: ties keep the trace's order)."""
    order = np.argsort(entry, kind="stable")
    return trips.take(order), entry[order]


def earliest_views(requests: list, views: tuple) -> tuple:
    """``views`` of ``requests`` (aligned) with each booked request's pickup no earlier than
    its requested departure (:attr:`dispatch.api.problem.TaskView.earliest`; a view's own, e.g. a
    meeting point's, kept where later); ``views`` itself where none is booked."""
    if not any(t.booked_at == t.booked_at for t in requests):  # (nan: not booked)
        return views
    return tuple(v if v.earliest >= t.earliest_pickup else replace(v, earliest=t.earliest_pickup)
                 for t, v in zip(requests, views))


class PrebookSource(TaskSource):
    """The task source of a run with prebooking: it releases each request when it enters
    dispatch (see the module) with its requested departure as its release time, and a
    promised request whose pickup window closes while open (a breakdown took it out of its
    plan) ends ``failed``.

    ``share`` / ``lead``: ``[tasks] prebook_share`` / ``prebook_lead``; ``mode`` /
    ``dispatch_lead``: ``[dispatch] prebook`` / ``prebook_lead``; ``booking_rng``: the run's
    prebooking stream (which trips are booked)."""

    def __init__(self, *args, share: float, lead: float, mode: str, dispatch_lead: float,
                 booking_rng: np.random.Generator, **kw) -> None:
        self.share, self.lead, self.mode = share, lead, mode
        self.dispatch_lead, self.booking_rng = dispatch_lead, booking_rng
        self._pending = 0  # generated requests booked, not yet entered (mode "lead")
        self._drawn = False  # the generator is done drawing
        super().__init__(*args, **kw)

    def release(self, req, booking: tuple[float, float] | None = None):
        """Release ``req`` now; ``booking``: ``(booked_at, departure)`` of a booked one."""
        if booking is None:
            return super().release(req)
        task = self._made(req)
        task.booked_at, task.released_at = float(booking[0]), float(booking[1])
        # its limits count from the requested departure
        return self._opened(task, task.released_at + self._limit(task) - self.env.now)

    def _expire(self, task, after: float):
        yield self.env.timeout(after)
        if task.state is TaskState.OPEN and not task.transfers:
            # open again after it was promised: only a breakdown takes a promise out of a plan
            self.book.close(task, TaskState.FAILED if task.promised else TaskState.EXPIRED)

    def rearm(self, task) -> None:
        if task.transfers:
            return
        left = task.released_at + self._limit(task) - self.env.now
        if left <= 0:
            self.book.close(task, TaskState.FAILED if task.promised else TaskState.EXPIRED)
        elif left < math.inf:
            self.env.process(self._expire(task, left))

    def _booking(self) -> tuple[float, float] | None:
        """A generated request made now: booked ``(now, now + lead)`` with probability
        ``share``, else None."""
        if self.booking_rng.random() < self.share:
            now = float(self.env.now)
            return now, now + self.lead
        return None

    def _enter(self, req, booking):
        """Process: release a booked generated request when it enters dispatch (``lead``)."""
        at = booking[1] - self.dispatch_lead
        if at > self.env.now:
            yield self.env.timeout(at - self.env.now)
        self.release(req, booking)
        self._pending -= 1
        if self._drawn and not self._pending:
            self._done()

    def _released(self, req) -> None:
        booking = self._booking() if self.share > 0 else None
        if booking is not None and self.mode == "lead":
            self._pending += 1
            self.env.process(self._enter(req, booking))
            return
        self.release(req, booking)

    def _run(self):
        if self.kind == "trace":
            trips = self.trips
            if self.count is not None:
                trips = trips.subset(np.arange(len(trips)) < self.count, "tasks.count")
            if self.share > 0 and not trips.prebooked:
                trips = synthesize(trips, self.share, self.lead, self.booking_rng)
            trips, entry = in_entry_order(trips,
                                          entry_times(trips, self.mode, self.dispatch_lead))
            requests = self.demand.from_trace(trips)
            booked = trips.booked_at
            for k, at in enumerate(entry.tolist()):
                if at > self.env.now:
                    yield self.env.timeout(at - self.env.now)
                b = math.nan if booked is None else float(booked[k])
                self.release(next(requests), None if b != b else (b, float(trips.t[k])))
            self._done()
            return
        yield from self._generate()
        self._drawn = True
        if not self._pending:
            self._done()
        yield self.env.timeout(0)


def task_source(sc, booking_rng) -> tuple[type[TaskSource], dict]:
    """The run's task source class and its own arguments: :class:`PrebookSource` where some
    request is booked ahead (``booking_rng``: its stream), else :class:`TaskSource`."""
    t, d = sc.tasks, sc.dispatch
    if not t.prebooked:
        return TaskSource, {}
    return PrebookSource, dict(
        share=t.prebook_share, lead=t.prebook_lead, mode=d.prebook,
        dispatch_lead=t.prebook_lead if d.prebook_lead is None else d.prebook_lead,
        booking_rng=booking_rng)
