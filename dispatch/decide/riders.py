"""Riders who may take the train (``[transit]``): each request's mode chosen when it is
released, the fleet legs it needs released as requests timed to the timetable, and every
rider's trip followed to one terminal state as legs (the ``legs`` table).

When a request is released, :class:`Riders` asks the timetable for the rider's options (door
to door by the fleet; fleet to a station, trains, walk; walk, trains, fleet; walk, trains,
walk: :func:`dispatch.space.journeys.rider_options`, with the fleet's estimate below) and the
run's mode choice plugin picks one. Then:

* ``fleet``: the request is released as it is;
* ``fleet+train``: a *feeder* request from the door to the street node of the first station,
  whose latest drop-off (release + direct time + ``max_delay``, which the one schedule rule
  honours) is the chosen train's departure less the walk from the node into the station, no
  later than the scenario's ``max_delay`` allows. When the vehicle lets the rider off, the
  rider walks into the station: ready by the departure, they take the trains chosen; later,
  the rest of the trip is routed again from that station at that time (the next departures,
  by the Connection Scan), counted in ``missed_connections``;
* ``train+fleet``: the walk and the trains are fixed at once, and the last leg is released at
  once as a *booked* request (:mod:`dispatch.decide.prebook`) whose requested departure is the
  rider's arrival at the last station's street node, so it is planned ahead;
* ``train``: walks and trains only, no fleet work; the rider's trip ends at once.

A rider ends ``completed`` (every leg made) or in the terminal state of the fleet request that
did not serve them (``expired``, ``rejected``, ``cut_off``...). A feeder the fleet cannot
make in time (its latest drop-off before it could arrive) is kept with no slack: it arrives
after the departure, a missed connection.

The fleet's estimate of a ride is the free-flow drive from pickup to drop-off and, for the
wait, the mean pickup wait of the last :data:`WAIT_WINDOW` riders the fleet picked up (half the
``[tasks] max_wait`` before the first; 0 without one).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field, replace

import numpy as np

from dispatch.api.mode_choice import KINDS, ModeChoice, Weights
from dispatch.decide.prebook import PrebookSource, task_source
from dispatch.decide.rider_legs import LEG_COLUMNS, Leg, Transit, percentile, seconds_of_day
from dispatch.plan.tasks import Task, TaskState

#: pickups the fleet's wait estimate averages over
WAIT_WINDOW = 100


@dataclass(eq=False, slots=True)
class Trip:
    """One rider's trip: its request id, when it was requested (``t0``), the mode chosen,
    the door and goal nodes, the legs so far (``legs``) and, for a feeder, the first station,
    the chosen departure (simulated seconds), the walk into the station and the legs planned
    after it (``rest``)."""

    request_id: int | str
    t0: float
    kind: str
    origin: int
    goal: int
    legs: list[Leg] = field(default_factory=list)
    station: int = -1
    departure: float = math.nan
    rest: list[Leg] = field(default_factory=list)
    state: str | None = None


def summary_names() -> tuple[str, ...]:
    """The summary's transit columns, in order (see :meth:`Riders.summary`)."""
    per = [f"mode_share_{k}" for k in _keys()]
    d2d = [f"door_to_door_{s}_{k}" for k in _keys() for s in ("mean", "p90")]
    return ("riders", "riders_served", *per, "vehicle_km_per_rider", "door_to_door_mean",
            "door_to_door_median", "door_to_door_p90", *d2d, "missed_connections")


def _keys() -> list[str]:
    return [k.replace("+", "_") for k in KINDS]


class Riders:
    """The riders of a run with ``[transit]`` (see the module): ``transit`` the timetable on
    the network, ``choice`` / ``weights`` the mode choice and its generalized cost, ``rng`` its
    stream, ``between(u, v)`` the free-flow seconds between two nodes, ``max_wait`` /
    ``max_delay`` the scenario's limits (None: none), ``on_leg(row)`` what writes a leg's row."""

    def __init__(self, transit: Transit, choice: ModeChoice, weights: Weights,
                 rng: np.random.Generator, *, between, limits: tuple, on_leg) -> None:
        self.transit, self.choice, self.weights, self.rng = transit, choice, weights, rng
        self.between, self.on_leg = between, on_leg
        max_wait, self.max_delay = limits
        self._waits: deque[float] = deque(maxlen=WAIT_WINDOW)
        self._first_wait = 0.0 if max_wait is None else max_wait / 2
        self._by_task: dict[int, Trip] = {}
        #: riders by the mode chosen; by terminal state; door-to-door seconds of served ones
        self.kinds: Counter = Counter()
        self.states: Counter = Counter()
        self.door_to_door: dict[str, list[float]] = {k: [] for k in KINDS}
        self.missed = 0  # feeders that let their rider off after the train left

    # ------------------------------------------------------------------ the fleet's estimate
    def estimate(self, u: int, v: int, ready: float) -> tuple[float, float] | None:
        """``(wait, ride)`` seconds of a fleet ride from node ``u`` to ``v`` (None: no road)."""
        ride = float(self.between(u, v))
        if not math.isfinite(ride):
            return None
        w = self._waits
        return (sum(w) / len(w) if w else self._first_wait), ride

    # ------------------------------------------------------------------ release
    def start(self, req, source) -> Task | None:
        """The rider of ``req`` (a trip request released now by ``source``, a
        :class:`TransitSource`): mode chosen, legs planned, fleet requests released. Returns
        the fleet request released (None: none)."""
        now = float(source.env.now)
        origin, goal = int(req.loc), int(req.dropoff)
        opts = self.transit.options(now, origin, goal, self.estimate)
        if opts:
            i = self.choice.choose([o for o, _ in opts], self.weights, self.rng)
            option, j = opts[i]
        else:  # no road and no train: the fleet's request says so (unreachable)
            option, j = None, None
        kind = "fleet" if option is None else option.kind
        trip = Trip(req.request_id, now, kind, origin, goal)
        self.kinds[kind] += 1
        tr = self.transit
        if kind == "fleet":
            return self._release(trip, source, req)
        if kind == "train":
            trip.legs = [tr.walk_in(now, origin, j), *tr.onward(j, goal)]
            self._end(trip, TaskState.COMPLETED.value)
            return None
        if kind == "fleet+train":
            first = next(g for g in j.legs if g.mode == "train")
            trip.station = tr.tt.station(first.from_stop)
            node, walk = tr.street(trip.station)
            trip.departure = first.start - tr.offset
            trip.rest = tr.onward(j, goal)
            task = self._release(trip, source, replace(req, dropoff=node,
                                                       dropoff_snap_m=math.nan))
            if task.state is TaskState.OPEN:
                self._deadline(task, trip.departure - walk)
            return task
        # train+fleet: walk, trains, walk to the street; the last leg booked for then
        last = j.legs[-1]
        trip.legs = [tr.walk_in(now, origin, j), *tr.between(j.legs),
                     tr.to_street(last.end - tr.offset, last.to_stop)]
        node, _ = tr.street(tr.tt.station(last.to_stop))
        return self._release(trip, source, replace(req, loc=node, snap_m=math.nan),
                             (now, trip.legs[-1].end))

    def _release(self, trip: Trip, source, req, booking=None) -> Task:
        # the task's id is the book's next number: known before its release, which may
        # close it at once (unreachable) and so call closed() inside
        self._by_task[source.book.released] = trip
        return source.leg(req, booking)

    def _deadline(self, task: Task, latest: float) -> None:
        """The feeder ``task`` dropped off by ``latest`` (and by the scenario's
        ``max_delay``): its ``direct_time`` set now, its ``max_delay`` the slack left (0
        where the drive alone is too long: the rider then misses the train)."""
        direct = float(self.between(task.loc, task.dropoff))
        task.direct_time = direct
        slack = max(latest - task.released_at - direct, 0.0)
        task.max_delay = slack if self.max_delay is None else min(slack, self.max_delay)

    # ------------------------------------------------------------------ closing
    def closed(self, task: Task) -> None:
        """The task book's closure of ``task``: the rider's next legs, or their end."""
        trip = self._by_task.pop(task.id, None)
        if trip is None:
            return
        if task.state is not TaskState.COMPLETED:
            self._end(trip, task.state.value)
            return
        if task.picked_up_at == task.picked_up_at:
            self._waits.append(task.picked_up_at - max(task.released_at, trip.t0))
        tr = self.transit
        off = task.dropped_at if task.dropped_at == task.dropped_at else task.completed_at
        pickup = task.loc if task.origin is None else task.origin
        trip.legs.append(Leg("fleet", task.picked_up_at, off, tr.door(pickup),
                             tr.door(task.dropoff), agent_id=task.agent_id))
        if trip.kind == "fleet+train":
            walk = tr.from_street(off, trip.station)
            trip.legs.append(walk)
            if walk.end <= trip.departure:
                trip.legs.extend(trip.rest)
            else:  # the train has left: the rest of the trip from this station, now
                self.missed += 1
                trip.legs.extend(tr.replan(trip.station, walk.end, trip.goal))
        self._end(trip, TaskState.COMPLETED.value)

    def _end(self, trip: Trip, state: str) -> None:
        """The rider's one terminal state; their legs written."""
        if trip.state is not None:
            raise RuntimeError(f"rider {trip.request_id!r} ended twice ({trip.state}, {state})")
        trip.state = state
        self.states[state] += 1
        if state == TaskState.COMPLETED.value:
            self.door_to_door[trip.kind].append(trip.legs[-1].end - trip.t0)
        for k, leg in enumerate(trip.legs):
            self.on_leg(leg.row(trip.request_id, k))

    # ------------------------------------------------------------------ the summary
    def summary(self, distance_m: float) -> dict:
        """The summary's transit columns (:func:`summary_names`): riders and those served
        (every leg made), the share of riders by the mode chosen (``mode_share_<kind>``,
        ``+`` written ``_``), vehicle-km driven per served rider (the whole fleet's
        ``distance_m``), door-to-door seconds (request to arrival at the goal) of the served
        riders (mean, median, 90th percentile) and by mode (mean, p90), and the missed
        connections."""
        n, served = sum(self.kinds.values()), self.states[TaskState.COMPLETED.value]
        out: dict = {"riders": n, "riders_served": served}
        for kind, key in zip(KINDS, _keys()):
            out[f"mode_share_{key}"] = self.kinds[kind] / n if n else math.nan
        out["vehicle_km_per_rider"] = distance_m / 1000.0 / served if served else math.nan
        every = [d for k in KINDS for d in self.door_to_door[k]]
        out["door_to_door_mean"] = float(np.mean(every)) if every else math.nan
        out["door_to_door_median"] = percentile(every, 50)
        out["door_to_door_p90"] = percentile(every, 90)
        for kind, key in zip(KINDS, _keys()):
            d = self.door_to_door[kind]
            out[f"door_to_door_mean_{key}"] = float(np.mean(d)) if d else math.nan
            out[f"door_to_door_p90_{key}"] = percentile(d, 90)
        out["missed_connections"] = self.missed
        return {k: out[k] for k in summary_names()}


class TransitSource(PrebookSource):
    """The task source of a run with ``[transit]``: each trip request it releases goes to the
    ``riders`` (:meth:`Riders.start`), which release the fleet legs through :meth:`leg`
    (booked ones as :class:`~dispatch.decide.prebook.PrebookSource` does)."""

    def __init__(self, *args, riders: Riders, **kw) -> None:
        self.riders = riders
        super().__init__(*args, **kw)

    def release(self, req, booking=None):
        if req.dropoff is None:  # (a point task: no trip to make by train)
            return self.leg(req, booking)
        return self.riders.start(req, self)

    def leg(self, req, booking=None) -> Task:
        """Release a fleet leg now (``booking``: ``(booked_at, departure)`` of a booked one)."""
        return PrebookSource.release(self, req, booking)


def riders_for(sc, space, mode_choice: ModeChoice, rng: np.random.Generator, *,
               between, recording) -> Riders:
    """``[transit]``'s riders of a run of scenario ``sc``: the timetable on the run's network
    (``space``) and clock (``[tasks] start`` on the feed's service day), the ``mode_choice``
    plugin made for it, its stream ``rng``, ``between(u, v)``: the free-flow seconds from node
    ``u`` to ``v``; the ``legs`` table and the summary's transit columns are added to
    ``recording`` (:class:`dispatch.output.rows.RunRecording`)."""
    cfg = sc.transit
    on_leg = recording.legs(LEG_COLUMNS, summary_names(),
                            ("riders", "riders_served", "missed_connections"))
    return Riders(Transit(cfg, space, seconds_of_day(sc.tasks.start)), mode_choice,
                  Weights(cfg.w_ivt, cfg.w_wait, cfg.w_walk, cfg.w_transfer,
                          cfg.transfer_penalty),
                  rng, between=between, limits=(sc.tasks.max_wait, sc.tasks.max_delay),
                  on_leg=on_leg)


def rider_source(sc, booking_rng: np.random.Generator, riders: Riders | None):
    """The run's task source class and its own arguments: prebooking's
    (:func:`dispatch.decide.prebook.task_source`), or with ``[transit]`` riders a
    :class:`TransitSource` (nothing booked by the trace; a trip's last leg after the train is
    released as a booking at once)."""
    if riders is None:
        return task_source(sc, booking_rng)
    return TransitSource, dict(share=0.0, lead=sc.tasks.prebook_lead, mode="at_booking",
                               dispatch_lead=0.0, booking_rng=booking_rng, riders=riders)
