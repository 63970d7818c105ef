"""Tasks (trips), their life cycle, the task book, and the task sources (SimPy processes).

A task is a **trip**: a pickup and, for taxis, a drop-off (the paper's point tasks are trips
without one). Life cycle::

    open -> assigned -> picked_up -> completed
      \\-> expired | rejected | unreachable | cut_off | failed   (terminal, from any live state)
      \\-> declined   (terminal, from open: its rider declined the offer, see dispatch.api.acceptor)

``expired``: its ``ttl`` or ``max_wait`` ran out while it was open; ``rejected``: when the
dispatcher first considered it, no vehicle could reach its pickup within its ``max_wait``;
``unreachable``: no vehicle of the fleet can ever reach it; ``cut_off``: the run ended first;
``failed``: its vehicle broke down with the passenger on board. A vehicle holds its tasks as
stops of its plan (:mod:`dispatch.plan.stops`), so pooling adds stops to a vehicle, not states to a
task. A request carries ``passengers`` (default 1) and two limits (Alonso-Mora et al.): pickup by
release + ``max_wait``, drop-off by release + ``direct_time`` + ``max_delay`` (``direct_time``:
the free-flow fastest drive from pickup to drop-off, set by the dispatcher when the request is
first considered).

The :class:`TaskBook` keeps only live tasks, indexed (open ones in id order): no step scans the
history of the run. A task leaving the book is handed to the ``on_close`` subscribers (the
recorder writes its row, the run statistics count it) and forgotten.
"""

from __future__ import annotations

import logging
import math
from array import array
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np
import simpy

from dispatch.api.problem import TaskView
from dispatch.config.tasks import TaskConfig
from dispatch.events import EventBus
from dispatch.files.empirical import draw_day, load_sample
from dispatch.locations import Location

log = logging.getLogger(__name__)


class TaskState(str, Enum):
    OPEN = "open"
    ASSIGNED = "assigned"
    PICKED_UP = "picked_up"
    COMPLETED = "completed"
    EXPIRED = "expired"
    REJECTED = "rejected"
    UNREACHABLE = "unreachable"
    #: the run ended first, the request still waiting or aboard (no rider cancelled it)
    CUT_OFF = "cut_off"
    FAILED = "failed"
    DECLINED = "declined"

    @property
    def terminal(self) -> bool:
        return self in TERMINAL


# the states as module constants: ``TaskState.OPEN`` is a lookup through the enum's metaclass,
# several times slower than a global, and the hot paths read states a dozen times per trip
OPEN, ASSIGNED, PICKED_UP, COMPLETED = (TaskState.OPEN, TaskState.ASSIGNED, TaskState.PICKED_UP,
                                        TaskState.COMPLETED)
TERMINAL = frozenset({TaskState.COMPLETED, TaskState.EXPIRED, TaskState.REJECTED,
                      TaskState.UNREACHABLE, TaskState.CUT_OFF, TaskState.FAILED,
                      TaskState.DECLINED})
#: the event emitted when a task enters a terminal state
CLOSE_EVENT = {TaskState.COMPLETED: "complete", TaskState.EXPIRED: "expire",
               TaskState.REJECTED: "reject", TaskState.UNREACHABLE: "unreachable",
               TaskState.CUT_OFF: "cut_off", TaskState.FAILED: "failed",
               TaskState.DECLINED: "decline"}
#: the states a task may move to from each live state
MOVES = {
    TaskState.OPEN: {TaskState.ASSIGNED, TaskState.EXPIRED, TaskState.REJECTED,
                     TaskState.UNREACHABLE, TaskState.CUT_OFF, TaskState.DECLINED,
                     # (failed: a promise a breakdown broke: dispatch.decide.prebook)
                     TaskState.FAILED},
    TaskState.ASSIGNED: {TaskState.PICKED_UP, TaskState.OPEN, TaskState.CUT_OFF,
                         TaskState.FAILED},
    TaskState.PICKED_UP: {TaskState.COMPLETED, TaskState.OPEN, TaskState.CUT_OFF,
                          TaskState.FAILED},
}


@dataclass(eq=False, slots=True)
class Task:
    """One task's record; the task book moves it through its states."""

    id: int
    kind: str
    loc: Location  # pickup
    released_at: float
    dropoff: Location | None = None
    max_wait: float = math.nan  # seconds from release to pickup the request accepts
    snap_m: float = math.nan  # metres from the requested pickup to the node it was snapped to
    dropoff_snap_m: float = math.nan
    state: TaskState = TaskState.OPEN
    assigned_at: float = math.nan
    agent_id: int = -1
    cost: float = math.nan  # planned seconds from the vehicle to the pickup at assignment
    picked_up_at: float = math.nan
    completed_at: float = math.nan
    closed_at: float = math.nan
    conflicted: bool = False
    offered: bool = False  # appeared in at least one allocation problem
    reassigned: int = 0  # times it went back to open because its vehicle broke down
    transfers: int = 0  # ... of those, with the passenger on board (picked up again elsewhere)
    origin: Location | None = None  # the requested pickup (``loc`` moves on a transfer)
    passengers: int = 1
    max_delay: float = math.nan  # seconds of delay over the direct drive the request accepts
    direct_time: float = math.nan  # free-flow fastest seconds from pickup to drop-off
    shared: bool = False  # another request was on board during its ride
    dropped_at: float = math.nan  # when its passengers got off (before any service time)
    #: when it was booked (nan: not booked; its ``released_at`` is then the requested
    #: departure, see dispatch.decide.prebook) and whether it was accepted so (a promise)
    booked_at: float = math.nan
    promised: bool = False
    offers: int = 0  # offers made to its rider (dispatch.api.acceptor; 0 without an acceptor)
    fare: float = math.nan  # the fare of its last offer ([pricing]; nan without)
    #: meeting points (dispatch.decide.meeting): metres the rider may walk to a boarding point and
    #: from an alighting point (0: door to door), and their walking speed (m/s); a source sets
    #: both, from its request or the scenario's ``[tasks]``, where the rider walks
    max_walk: float = 0.0
    walk_speed: float = TaskConfig.walk_speed
    #: the meeting points of its ride as handed out (None: door to door) and the metres walked
    meeting: object = None
    #: the user's id of its request (an int or a str): a trace row's id
    #: (dispatch.files.traces.Trips.ids), else its number among the requests drawn (generated
    #: demand, an empirical day); the results' ``request_id``
    request_id: int | str = -1

    @property
    def cell(self):
        """The voxel name of :attr:`loc` (the pickup)."""
        return self.loc

    @property
    def earliest_pickup(self) -> float:
        """The pickup's earliest time at the door: a booked request's requested departure (its
        ``released_at``, see dispatch.decide.prebook), ``-inf`` for an immediate one."""
        return self.released_at if self.booked_at == self.booked_at else -math.inf

    @property
    def deadline(self) -> float:
        """Latest pickup time the request accepts (inf without a max_wait, and once its
        passenger has been picked up: a transfer is owed, whatever the time)."""
        if math.isnan(self.max_wait) or self.transfers:
            return math.inf
        return self.released_at + self.max_wait

    @property
    def dropoff_deadline(self) -> float:
        """Latest drop-off time the request accepts (inf without a max_delay or a direct time,
        and once a breakdown made it a transfer)."""
        if math.isnan(self.max_delay) or math.isnan(self.direct_time) or self.transfers:
            return math.inf
        return self.released_at + self.direct_time + self.max_delay

    def view(self) -> TaskView:
        if self.passengers == 1 and self.max_delay != self.max_delay:  # (the usual case)
            return TaskView(self.id, self.kind, self.loc,  # type: ignore[arg-type]
                            self.released_at, self.dropoff, self.deadline)
        return TaskView(self.id, self.kind, self.loc, self.released_at,  # type: ignore[arg-type]
                        self.dropoff, self.deadline, self.passengers, self.dropoff_deadline)


class RequestIds:
    """The request id of every task of a run, by task id (``ids[task_id]``; :attr:`values`:
    the sequence itself). Integer ids are kept as int64s (a day of a million requests: 8 MB,
    not the 36 MB of as many Python ints), string ids as references."""

    __slots__ = ("values",)

    def __init__(self) -> None:
        self.values: array | list = array("q")

    def append(self, request_id: int | str) -> None:
        try:
            self.values.append(request_id)
        except (TypeError, OverflowError):  # a string (an int beyond int64): a list from now
            self.values = [*self.values, request_id]

    def __getitem__(self, task_id: int) -> int | str:
        return self.values[task_id]


class TaskBook:
    """The live tasks of a run and their state changes (each emitted as an event).

    ``open`` holds open tasks by id in release order (re-opened tasks go back in id order);
    ``live`` counts released tasks not yet terminal. ``on_close`` callables receive each task
    as it reaches its terminal state, after which the book forgets it."""

    def __init__(self, env: simpy.Environment, bus: EventBus) -> None:
        self.env, self.bus = env, bus
        self.open: dict[int, Task] = {}
        self.live = 0
        self.released = 0
        #: every released task's request id, by task id (the events and assignments tables
        #: name the request of each row: they are written after the task left the book)
        self.request_ids = RequestIds()
        self.on_close: list[Callable[[Task], None]] = []
        self._active: dict[int, Task] = {}  # assigned or picked up
        #: assigned, not yet picked up (a vehicle is driving to its pickup), by id
        self.assigned: dict[int, Task] = {}

    def _move(self, task: Task, state: TaskState) -> None:
        if state not in MOVES.get(task.state, ()):
            raise RuntimeError(f"task {task.id} cannot go from {task.state.value} to "
                               f"{state.value}")
        if task.state is OPEN:
            del self.open[task.id]
        elif state is OPEN or state in TERMINAL:
            del self._active[task.id]
        if task.state is ASSIGNED:
            del self.assigned[task.id]
        elif state is ASSIGNED:
            self.assigned[task.id] = task
        task.state = state

    def release(self, kind: str, loc: Location, dropoff: Location | None = None, *,
                max_wait: float = math.nan, snap_m: float = math.nan,
                dropoff_snap_m: float = math.nan, passengers: int = 1,
                max_delay: float = math.nan, request_id: int | str | None = None) -> Task:
        """A new open task released now, numbered in release order; its ``request_id`` (kept
        in :attr:`request_ids`) is the one given, or its own id where none is."""
        task = Task(self.released, kind, loc, float(self.env.now), dropoff, max_wait, snap_m,
                    dropoff_snap_m)
        task.request_id = task.id if request_id is None else request_id
        self.request_ids.append(task.request_id)
        if passengers != 1:
            task.passengers = passengers
        if max_delay == max_delay:
            task.max_delay = max_delay
        self.released += 1
        self.live += 1
        self.open[task.id] = task
        self.bus.emit(self.env.now, "release", -1, task.id, loc)
        return task

    def assign(self, task: Task, agent_id: int, cost: float) -> None:
        self._move(task, ASSIGNED)
        self._active[task.id] = task
        if task.booked_at == task.booked_at:  # a booked request accepted: a promise
            task.promised = True
        task.assigned_at, task.agent_id, task.cost = float(self.env.now), agent_id, cost
        self.bus.emit(self.env.now, "assign", agent_id, task.id, task.loc)

    def picked_up(self, task: Task, at: Location | None = None) -> None:
        self._move(task, PICKED_UP)
        self._active[task.id] = task
        if math.isnan(task.picked_up_at):  # a transferred passenger keeps their first pickup
            task.picked_up_at = float(self.env.now)
        self.bus.emit(self.env.now, "pickup", task.agent_id, task.id,  # at: where it boards
                      task.loc if at is None else at)

    def reopen(self, task: Task, pickup: Location | None = None) -> None:
        """Give a task back to the pool because its vehicle broke down: an assigned one as it
        was; a picked-up one (a transfer) with its new pickup where the passenger waits."""
        transfer = task.state is PICKED_UP
        self._move(task, OPEN)
        task.reassigned += 1
        if transfer:
            task.transfers += 1
            if task.origin is None:
                task.origin = task.loc
            task.loc = pickup if pickup is not None else task.loc
        self.open[task.id] = task
        if next(reversed(self.open)) != max(self.open):  # keep id order (release order)
            self.open = dict(sorted(self.open.items()))
        self.bus.emit(self.env.now, "reopen", task.agent_id, task.id, task.loc)
        # the row describes the assignment that holds at the end; the history is in events
        task.agent_id, task.cost, task.assigned_at = -1, math.nan, math.nan

    def unassign(self, task: Task) -> None:
        """Give an assigned task (not picked up) back to the pool because the dispatcher
        re-assigned its vehicle (``[dispatch] reassign``): open again, keeping its release
        time and deadline; the dispatcher records the ``reassign`` event."""
        if task.state is not ASSIGNED:
            raise RuntimeError(f"task {task.id} is {task.state.value}, not assigned")
        self._move(task, OPEN)
        self.open[task.id] = task
        if next(reversed(self.open)) != max(self.open):  # keep id order (release order)
            self.open = dict(sorted(self.open.items()))
        task.agent_id, task.cost, task.assigned_at = -1, math.nan, math.nan

    def close(self, task: Task, state: TaskState) -> None:
        """Move ``task`` to the terminal ``state`` and hand it to the ``on_close`` callables."""
        if state not in TERMINAL:
            raise ValueError(f"{state.value} is not a terminal state")
        self._move(task, state)
        now = float(self.env.now)
        task.closed_at = now
        if state is COMPLETED:
            task.completed_at = now
        self.live -= 1
        where = task.dropoff if state is COMPLETED and task.dropoff is not None \
            else task.loc
        self.bus.emit(now, CLOSE_EVENT[state], task.agent_id, task.id, where)
        for fn in self.on_close:
            fn(task)

    def close_all(self, state: TaskState) -> None:
        """Close every live task (the run is over)."""
        for task in sorted([*self.open.values(), *self._active.values()], key=lambda t: t.id):
            self.close(task, state)


# ----------------------------------------------------------------------------- demand


@dataclass(frozen=True, slots=True)
class Request:
    """A trip request to release: where, and what the trace said about it. Released, it is a
    :class:`Task` (an agent's bid for a task in a decision round is
    :class:`dispatch.api.problem.Bid`)."""

    kind: str
    loc: Location
    dropoff: Location | None = None
    max_wait: float = math.nan
    snap_m: float = math.nan
    dropoff_snap_m: float = math.nan
    passengers: int = 1
    max_delay: float = math.nan
    max_walk: float = math.nan  # nan: the scenario's
    walk_speed: float = math.nan
    #: its trace row's id, or its number among the requests drawn (None: the task's own id)
    request_id: int | str | None = None


class Demand:
    """Turns a scenario's task description into requests in its space: ``draw`` makes a
    generated one (static, periodic, poisson) with the ``request_id`` given; ``from_trace``
    converts a trace's trips: it checks them all when called and returns an iterator that
    makes each trip's request when it is asked for, in the trips' (release) order (a day of
    a million trips is never a million requests at once). ``valid(loc)`` says whether a
    task there can be served at all (a cell inside an obstacle cannot)."""

    def draw(self, request_id: int | None = None) -> Request:
        raise NotImplementedError

    def from_trace(self, trips) -> Iterator[Request]:
        raise NotImplementedError

    def valid(self, loc: Location) -> bool:
        return True


# ----------------------------------------------------------------------------- sources


class TaskSource:
    """The SimPy process that releases tasks into the book, starts their expiry timers and
    wakes the dispatcher; ``finished`` turns True (and ``on_done`` is called) when it has
    nothing more to release.

    ``tasks``: the scenario's ``[tasks]``, whose limits hold for a request without its own;
    ``count``: tasks to release (a generated source; None: no end) or the first trips of
    ``trips`` to release (None: all): a trace's, or an empirical day's, released as a trace."""

    def __init__(self, env: simpy.Environment, book: TaskBook, demand: Demand,
                 tasks: TaskConfig, count: int | None, rng: np.random.Generator,
                 *, notify: Callable[[], None], trips=None) -> None:
        self.env, self.book, self.demand, self.tasks = env, book, demand, tasks
        self.kind = "trace" if tasks.source in ("trace", "empirical") else tasks.source
        self.count, self.rng, self.notify, self.trips = count, rng, notify, trips
        self.finished = False
        self.on_done: Callable[[], None] = lambda: None
        self.process = env.process(self._run())

    @classmethod
    def of(cls, env: simpy.Environment, book: TaskBook, demand: Demand, tasks: TaskConfig,
           count: int | None, *, day_rng: Callable[[], np.random.Generator],
           rng: np.random.Generator, notify: Callable[[], None], **extra) -> TaskSource:
        """The source of a scenario's ``[tasks]`` releasing ``count`` tasks where it has a
        count (static: the run's). An empirical day is drawn now (from ``day_rng()``) and
        released as a trace. ``extra``: a subclass's own arguments
        (:class:`dispatch.decide.prebook.PrebookSource`)."""
        trips = tasks.trips
        if tasks.source == "empirical":
            trips = draw_day(load_sample(), tasks.trips_per_day, day_rng(), tasks.weekday)
            # each request's id: its number in the day drawn (0 the first)
            trips = replace(trips, ids=np.arange(len(trips), dtype=np.int64))
        return cls(env, book, demand, tasks, count, rng, notify=notify, trips=trips, **extra)

    def _done(self) -> None:
        self.finished = True
        self.on_done()

    def release(self, req: Request) -> Task:
        """Release ``req`` now: a task of the book, open (or closed unreachable), its expiry
        timer started and the dispatcher told."""
        task = self._made(req)
        return self._opened(task, self._limit(task))

    def _made(self, req: Request) -> Task:
        """The book's task of ``req`` with the scenario's limits where the request has none
        (its nan)."""
        t = self.tasks
        wait = req.max_wait if not math.isnan(req.max_wait) else _nan_if_none(t.max_wait)
        delay = req.max_delay if not math.isnan(req.max_delay) else _nan_if_none(t.max_delay)
        task = self.book.release(req.kind, req.loc, req.dropoff, max_wait=wait,
                                 snap_m=req.snap_m, dropoff_snap_m=req.dropoff_snap_m,
                                 passengers=req.passengers, max_delay=delay,
                                 request_id=req.request_id)
        walk = t.max_walk if math.isnan(req.max_walk) else req.max_walk
        if walk > 0:  # (door to door otherwise: the task's defaults)
            task.max_walk = walk
            task.walk_speed = t.walk_speed if math.isnan(req.walk_speed) else req.walk_speed
        return task

    def _opened(self, task: Task, expire_after: float) -> Task:
        """``task`` open for dispatch (closed unreachable where it lies in an obstacle), its
        expiry ``expire_after`` seconds from now (``inf``: never)."""
        if not self.demand.valid(task.loc) or (task.dropoff is not None
                                               and not self.demand.valid(task.dropoff)):
            log.warning("task %d lies in an obstacle; closed as unreachable", task.id)
            self.book.close(task, TaskState.UNREACHABLE)
            return task
        if expire_after < math.inf:
            self.env.process(self._expire(task, expire_after))
        self.notify()
        return task

    def _limit(self, task: Task) -> float:
        """Seconds from release after which an open task expires (ttl, max_wait)."""
        return min(self.tasks.ttl if self.tasks.ttl is not None else math.inf,
                   math.inf if math.isnan(task.max_wait) else task.max_wait)

    def rearm(self, task: Task) -> None:
        """A task re-opened after a breakdown expires at the same time it would have; a
        transferred passenger never does."""
        if task.transfers:
            return
        left = task.released_at + self._limit(task) - self.env.now
        if left <= 0:
            self.book.close(task, TaskState.EXPIRED)
        elif left < math.inf:
            self.env.process(self._expire(task, left))

    def _expire(self, task: Task, after: float):
        yield self.env.timeout(after)
        if task.state is OPEN and not task.transfers:
            self.book.close(task, TaskState.EXPIRED)

    def _released(self, request) -> None:
        """Hand a generated request out now (a subclass may hold it back: prebooking)."""
        self.release(request)

    def _generate(self):
        """Process steps: the generated requests (static, periodic, poisson), each handed to
        :meth:`_released` when drawn; ends when the count is reached (never without one)."""
        t, count = self.tasks, self.count
        if self.kind == "static":
            for i in range(count or 0):
                self._released(self._draw(i))
            return
        if self.kind == "periodic":
            def gap():
                return t.interval
        else:
            def gap():
                return float(self.rng.exponential(1.0 / t.rate))
        released = 0
        while count is None or released < count:
            yield self.env.timeout(gap())
            if t.max_active is not None and self.book.live >= t.max_active:
                self.book.bus.emit(self.env.now, "skipped")
                continue
            self._released(self._draw(released))
            released += 1

    def _draw(self, i: int) -> Request:
        """The generated request ``i`` (0: the first drawn), its request id ``i``: the draw
        order, which a booked request entering later keeps."""
        return self.demand.draw(request_id=i)

    def _run(self):
        if self.kind == "trace":
            requests = self.demand.from_trace(self.trips)
            for t in self.trips.t[: self.count]:
                if t > self.env.now:
                    yield self.env.timeout(t - self.env.now)
                self.release(next(requests))  # made now, not before its time
            self._done()
            return
        yield from self._generate()
        self._done()
        if self.kind == "static":
            yield self.env.timeout(0)


def _nan_if_none(limit: float | None) -> float:
    """A scenario's limit as a task holds it: nan where the scenario sets none."""
    return math.nan if limit is None else limit
