"""Reservation-based execution: who holds which cell when, and the paper's conflict rule.

Used only when the run's planner is reservation-aware (``Planner.reservation_aware``; the
``reservation`` planner). With any other planner vehicles follow their untimed paths as before.

Time model (the one definition; the kernel, planners and tests all use :func:`occupancy`)
    A *timed route* is a list ``[(t0, c0), (t1, c1), ..., (tn, cn)]`` of cells and the times the
    vehicle is *in* them: it stands in ``c0`` from ``t0``, and step ``i`` (``c_{i-1} -> c_i``, a
    legal move of :mod:`dispatch.api.motion`) takes ``d_i = step length x cell size / speed``
    seconds and ends at ``t_i``; it starts at ``t_i - d_i >= t_{i-1}`` (the difference is a
    wait in ``c_{i-1}``). Reservations are half-open intervals ``[start, end)`` of continuous
    time on cells:

    * a cell a vehicle stands in is held from when it started entering it until the end of the
      step that leaves it;
    * during a step the vehicle holds every cell of the step's bounding box (from cell, to cell
      and, for a diagonal, the corner cells it sweeps past: the same box that must be free of
      obstacles), so two vehicles can never cross diagonals in one 2x2 block; a head-on swap
      (``A -> B`` while another goes ``B -> A`` at overlapping times) holds both cells twice and
      is a conflict like any other;
    * the route's last cell is held to infinity: a vehicle that arrives, serves, goes idle (or
      never had a task) stands where it is, holding its cell until it is given a route again.
      So a plan may end only in a cell nobody else reserves later.

    Two reservations conflict when they share a cell and overlap by more than :data:`EPS`
    seconds (so a vehicle may enter a cell at the instant another's step out of it ends).

The conflict rule (MAGNNET paper, execution): the vehicle with the lower task cost keeps its
path, the other replans; if no path exists it waits. :class:`Traffic` applies it:

* *Priority* is ``(task cost, vehicle id)``, lower first; the task cost is the allocation's
  ``c_ij`` (fixed for the task, so priorities never oscillate). Idle vehicles come last
  (``(inf, id)``). Reservations nobody can displace (*hard*) are the step each vehicle is
  executing (a step is never interrupted) and those of vehicles serving a task at its cell.
* When a vehicle needs a route (it was just given a task, or it is waiting without one) it plans
  around the hard reservations and those of higher-priority vehicles, leaving every other
  vehicle's cell free for a moment (its *inertia*: one straight step's time, the least it needs
  to leave). Lower-priority vehicles whose reservations its route crosses are *displaced*: each
  replans (a ``replan`` event) from the end of its current step, in priority order, by the same
  rule, so displacement cascades down the priority order only. A displaced vehicle with a task
  that finds no route holds its cell and waits; a displaced *idle* vehicle parks instead:
  it moves to the nearest cell nobody reserves later (``plan_timed`` with ``goal=None``; its
  ``move`` and ``replan`` events carry task id -1). So an idle vehicle parked on another's goal
  or in a one-cell passage makes way instead of blocking it until the horizon.
* If some displaced vehicle can neither move nor stay (it is in the way and boxed in), the
  whole transaction is undone and tried once more with a longer inertia (four steps: more time
  to get out of the way). If that fails too, the idle vehicles on the requester's untimed
  shortest path park off it around every reservation (say in a side pocket it must wait for),
  and the requester plans around *every* reservation; failing that it keeps what it had (a
  vehicle asks only while it holds its cell or follows a conflict-free route, so that is
  safe): it waits.
* A waiting vehicle retries when reservations are released (a request changed the table), when
  a vehicle becomes idle (so it can be displaced), and every ``planner.retry_after`` seconds;
  at most once per instant.

Every wait is a ``wait`` event (the vehicle stands in its cell from then until the step of its
next ``move`` starts, i.e. the move's time minus the step's duration) and every displacement a
``replan`` event; the ``vehicles`` table counts ``waits``, ``replans`` and ``wait_seconds``.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import simpy

from dispatch.api.motion import EPS, step_box, step_is_legal, step_length, step_seconds
from dispatch.api.problem import AgentView
from dispatch.locations import Cell
from dispatch.plan.vehicle_plan import request_stops

if TYPE_CHECKING:
    from dispatch.api.contracts import Planner
    from dispatch.api.voxels import Grid

INF = math.inf
#: A request displaces vehicles leaving each one's cell free for this many of its straight
#: steps; if that fails, for the next (more time to get out of the way).
INERTIA_STEPS = (1.0, 4.0)

Route = list[tuple[float, Cell]]


def overlaps(s1: float, e1: float, s2: float, e2: float) -> bool:
    """Whether ``[s1, e1)`` and ``[s2, e2)`` overlap by more than :data:`EPS`."""
    return s1 < e2 - EPS and s2 < e1 - EPS


def occupancy(route: Route, speed: float, cell_m: float) -> list[tuple[Cell, float, float]]:
    """The reservations ``(cell, start, end)`` of a timed route (see the module docstring)."""
    out: list[tuple[Cell, float, float]] = []
    since = route[0][0]
    for (_, a), (t, b) in zip(route, route[1:]):
        dep = t - step_seconds(a, b, speed, cell_m)
        out.append((a, since, t))
        out.extend((c, dep, t) for c in step_box(a, b) if c != a and c != b)
        since = dep
    out.append((route[-1][1], since, INF))
    return out


def route_error(grid, route: Route, flies: bool, speed: float) -> str | None:
    """Why ``route`` is not a legal timed route of a vehicle, or None."""
    if not route:
        return "empty route"
    for (t0, a), (t1, b) in zip(route, route[1:]):
        if not step_is_legal(grid, a, b, flies):
            return f"illegal step {a} -> {b}"
        if t1 - t0 < step_seconds(a, b, speed, grid.cell) - EPS:
            return f"step {a} -> {b} from t={t0} to t={t1} is faster than {speed} m/s"
    return None


class Entry(NamedTuple):
    """One reservation of one cell: ``[start, end)`` held by vehicle ``owner``. ``committed``
    marks the step the vehicle is executing (it cannot be taken back)."""

    start: float
    end: float
    owner: int
    committed: bool


class ReservationTable:
    """Reservations per cell, and per owner so that an owner's can be replaced at once."""

    def __init__(self) -> None:
        self._cells: dict[Cell, list[Entry]] = {}
        self._owned: dict[int, list[tuple[Cell, Entry]]] = {}

    def add(self, owner: int, cells: Iterable[tuple[Cell, float, float]],
            committed: bool = False) -> None:
        mine = self._owned.setdefault(owner, [])
        for cell, start, end in cells:
            if end - start <= EPS:
                continue
            e = Entry(start, end, owner, committed)
            self._cells.setdefault(cell, []).append(e)
            mine.append((cell, e))

    def clear(self, owner: int) -> None:
        """Drop every reservation of ``owner``."""
        for cell, e in self._owned.pop(owner, ()):
            entries = self._cells[cell]
            entries.remove(e)
            if not entries:
                del self._cells[cell]

    def at(self, cell: Cell) -> list[Entry]:
        """The reservations of one cell (read-only by convention)."""
        return self._cells.get(cell, [])

    def owned(self, owner: int) -> list[tuple[Cell, Entry]]:
        return list(self._owned.get(owner, ()))

    def view(self, include: Callable[[Entry], bool], t0: float,
             extra: dict[Cell, list[tuple[float, float]]] | None = None) -> TableView:
        """The reservations ``include`` keeps (and the ``extra`` intervals per cell), as a
        planner sees them from time ``t0`` on."""
        return TableView(self, include, t0, extra or {})


class TableView:
    """A read-only view of a :class:`ReservationTable` for a planner (the
    :class:`dispatch.api.contracts.Reservations` protocol): :meth:`blocked` gives the sorted,
    merged intervals of the kept reservations of a cell that end after ``t0``."""

    def __init__(self, table: ReservationTable, include: Callable[[Entry], bool],
                 t0: float, extra: dict[Cell, list[tuple[float, float]]]) -> None:
        self._table, self._include, self.t0, self._extra = table, include, t0, extra
        self._cache: dict[Cell, tuple[tuple[float, float], ...]] = {}

    def blocked(self, cell: Cell) -> tuple[tuple[float, float], ...]:
        hit = self._cache.get(cell)
        if hit is None:
            spans = [(e.start, e.end) for e in self._table.at(cell)
                     if e.end > self.t0 + EPS and self._include(e)]
            spans.extend(iv for iv in self._extra.get(cell, ()) if iv[1] > self.t0 + EPS)
            spans.sort()
            merged: list[list[float]] = []
            for s, e in spans:
                if merged and s <= merged[-1][1] + EPS:
                    merged[-1][1] = max(merged[-1][1], e)
                else:
                    merged.append([s, e])
            hit = self._cache[cell] = tuple((s, e) for s, e in merged)
        return hit

    def conflicts(self, cells: Iterable[tuple[Cell, float, float]]) -> bool:
        """Whether any of ``cells``' reservations overlaps a kept one."""
        return any(overlaps(s, e, a, b) for c, s, e in cells for a, b in self.blocked(c))


@dataclass(eq=False)
class TimedVehicle:
    """What reservation-based execution keeps of one vehicle (owned by :class:`Traffic`, not
    by the vehicle): its timed ``route`` (``route[0]`` is the cell it stands in, or is stepping
    into with the step's arrival time; a one-cell route holds that cell indefinitely), the
    ``step`` being executed ``(from, to, departure, arrival)``, the task it serves, whether it
    has ``arrived`` there (its reservations are hard then), the SimPy event ``changed`` that
    fires when its route is replaced, when it last asked for a route, a breakdown waiting for
    the end of its step, and the counts of the ``vehicles`` table (waits, replans, seconds
    standing on the way). Its id, kind, speed and cell are the vehicle's."""

    vehicle: Any
    route: Route
    changed: Any
    task: Any = None
    step: tuple | None = None
    arrived: bool = False
    last_try: float = -INF
    waits: int = 0
    replans: int = 0
    wait_seconds: float = 0.0
    waiting_since: float | None = None
    breaking: bool = False

    # the vehicle's own, read through (the conflict rule reads them off the record)
    id = property(lambda self: self.vehicle.id)
    kind = property(lambda self: self.vehicle.kind)
    speed = property(lambda self: self.vehicle.speed)
    flies = property(lambda self: self.vehicle.flies)
    cell = property(lambda self: self.vehicle.loc)


class Traffic:
    """The run's reservation table, the conflict rule (see the module docstring) and the
    vehicles' timed drives.

    Each vehicle's drive process (:meth:`start`, one per vehicle for the whole run) follows
    its :class:`TimedVehicle` record's ``route`` and calls :meth:`start_step` when it commits to a
    step; :meth:`request` is called when a vehicle is given a task and when a waiting vehicle
    tries again. A record's ``changed`` fires when a request changed that vehicle's route, and
    :attr:`released` whenever a request changed the table or a vehicle became idle
    (:meth:`notify`).
    """

    def __init__(self, env: simpy.Environment, planner: Planner, grid: Grid, vehicles,
                 emit: Callable[..., None]) -> None:
        self.env, self.planner, self.grid, self.emit = env, planner, grid, emit
        self.table = ReservationTable()
        #: vehicle id -> its record
        self.vehicles = {v.id: TimedVehicle(v, [(0.0, v.loc)], env.event()) for v in vehicles}
        self.retry_after = float(self.planner.retry_after)
        self.released = self.env.event()
        for t in self.vehicles.values():
            self._reserve(t)

    @classmethod
    def in_space(cls, env: simpy.Environment, planner: Planner, space, vehicles,
                 emit: Callable[..., None]) -> Traffic:
        """The traffic of a run in ``space``, a voxel world: its grid holds the reservations
        (a reservation-aware planner serves voxel worlds only; the registry refuses one that
        declares another space, :func:`dispatch.api.registry.capabilities`)."""
        return cls(env, planner, space.grid, vehicles, emit)

    def execution(self, op) -> TimedExecution:
        """The operator's execution on this traffic (``execution`` of
        :class:`dispatch.plan.operator.Operator`, which calls it with itself)."""
        return TimedExecution(self, op)

    def of(self, v) -> TimedVehicle:
        """The record of vehicle ``v``."""
        return self.vehicles[v.id]

    # --------------------------------------------------------------- classification
    @staticmethod
    def priority(v: TimedVehicle) -> tuple[float, int]:
        """Lower goes first: the task's cost, then the id; idle vehicles last."""
        return (INF if v.task is None else v.task.cost, v.id)

    def _keeps(self, w: TimedVehicle, steps: float) -> tuple[Callable[[Entry], bool], dict]:
        """What ``w`` plans around: hard reservations (executing steps, serving vehicles) and
        those of higher-priority vehicles; plus every lower-priority vehicle's *inertia*: its
        commit cell for the time of ``steps`` straight steps (it cannot leave faster than one;
        a displaced vehicle may need more time to get out of the way)."""
        pw = self.priority(w)
        vehicles = self.vehicles

        def keep(e: Entry) -> bool:
            if e.owner == w.id:
                return False
            o = vehicles[e.owner]
            return e.committed or o.arrived or self.priority(o) < pw

        inertia: dict[Cell, list[tuple[float, float]]] = {}
        for o in vehicles.values():
            if o is not w and not o.arrived and self.priority(o) > pw:
                t, c = self.commit_point(o)
                inertia.setdefault(c, []).append((t, t + steps * self.grid.cell / o.speed))
        return keep, inertia

    def commit_point(self, v: TimedVehicle) -> tuple[float, Cell]:
        """Where and when ``v`` can next change its mind: the end of the step it is executing,
        or its cell now."""
        t, c = v.route[0]
        return max(t, self.env.now), c

    # --------------------------------------------------------------- table
    def _reserve(self, v: TimedVehicle) -> None:
        self.table.clear(v.id)
        if v.step is not None and v.step[3] > self.env.now:
            a, b, dep, arr = v.step
            self.table.add(v.id, ((c, dep, arr) for c in step_box(a, b)), committed=True)
        self.table.add(v.id, occupancy(v.route, v.speed, self.grid.cell))

    def start_step(self, v: TimedVehicle) -> tuple[Cell, float]:
        """``v`` leaves ``route[0]`` for ``route[1]`` now; returns (next cell, arrival time)."""
        (_, a), (arr, b) = v.route[0], v.route[1]
        v.step = (a, b, self.env.now, arr)
        v.route = v.route[1:]
        self._reserve(v)
        return b, arr

    def _plan(self, v: TimedVehicle, t0: float, cell: Cell, view: TableView) -> Route | None:
        """The planner's timed route for ``v`` from ``cell`` at ``t0`` (to its task, or to
        any cell it may keep if idle), checked; or None."""
        goal = None if v.task is None else v.task.cell
        agent = AgentView(v.id, v.kind, cell, v.speed)  # type: ignore[arg-type]
        raw = self.planner.plan_timed(agent, goal, view, t0)
        if raw is None:
            return None
        route = [(float(t), tuple(int(x) for x in c)) for t, c in raw]
        why = route_error(self.grid, route, v.flies, v.speed)
        if why is None and (route[0][1] != cell or abs(route[0][0] - t0) > EPS):
            why = f"it starts at {route[0]}, not at ({t0}, {cell})"
        if why is None and goal is not None and route[-1][1] != goal:
            why = f"it ends at {route[-1][1]}, not at the goal {goal}"
        route[0] = (t0, cell)
        if why is None and view.conflicts(occupancy(route, v.speed, self.grid.cell)):
            why = "it crosses a reservation it was asked to avoid"
        if why is not None:
            raise RuntimeError(f"planner {self.planner.name!r} gave vehicle {v.id} an invalid "
                               f"timed route to {goal}: {why}")
        return route

    # --------------------------------------------------------------- the conflict rule
    def request(self, v: TimedVehicle) -> None:
        """Give ``v`` a route to its task, displacing lower-priority and idle vehicles; else
        a route around everyone; else it keeps the route it has (a one-cell route: it waits)."""
        v.last_try = self.env.now
        self._wake(v)  # it reads its route again, whatever happens here
        for steps in INERTIA_STEPS:
            if self._settle(v, steps):
                return
        t, c = self.commit_point(v)
        moved = self._make_way(v, t, c)
        route = self._plan(v, t, c, self.table.view(lambda e: e.owner != v.id, t))
        if route is not None:
            v.route = route
            self._reserve(v)
        if route is not None or moved:
            self.notify()

    def _make_way(self, v: TimedVehicle, t: float, c: Cell) -> bool:
        """Park the idle vehicles standing on ``v``'s untimed shortest path (or a step's box of
        it) somewhere off that path, each around every reservation (so nothing else changes);
        True if any moved. The last resort of :meth:`request`: an idle vehicle in a passage
        whose only way out needs ``v`` to wait for it."""
        path = self.planner.plan(AgentView(v.id, v.kind, c, v.speed),  # type: ignore[arg-type]
                                 v.task.cell)  # type: ignore[union-attr]
        if not path or len(path) < 2:
            return False
        cells = {b for a, n in zip(path, path[1:]) for b in step_box(a, n)}
        moved = False
        for b in sorted(self.vehicles.values(), key=lambda u: u.id):
            tb, cb = self.commit_point(b)
            if b is v or b.task is not None or b.arrived or cb not in cells:
                continue  # not idle, or broken down where it stands
            # it may cross the path, but must be off it before v could have driven it all
            off = tb + (len(path) + 2) * math.sqrt(3) * self.grid.cell / min(b.speed, v.speed)
            view = self.table.view(lambda e, b=b: e.owner != b.id, tb,
                                   {cell: [(off, INF)] for cell in cells})
            route = self._plan(b, tb, cb, view)
            if route is not None:
                b.route = route
                self._reserve(b)
                b.replans += 1
                self.emit(self.env.now, "replan", b.id, -1, b.cell)
                self._wake(b)
                moved = True
        return moved

    def _settle(self, v: TimedVehicle, steps: float) -> bool:
        """Plan ``v`` and, in priority order, everything it displaces; False (and nothing
        changed) if some displaced vehicle can neither move nor stay."""
        saved: dict[int, Route] = {}
        queued = {v.id}
        heap = [(self.priority(v), v.id)]
        while heap:
            _, wid = heapq.heappop(heap)
            w = self.vehicles[wid]
            t, c = self.commit_point(w)
            keep, inertia = self._keeps(w, steps)
            route = self._plan(w, t, c, self.table.view(keep, t, inertia))
            if route is None:  # no route: hold the cell (keep an existing hold as it is)
                held = len(w.route) == 1 and w.route[0][1] == c
                route = w.route if held else [(t, c)]
            victims = set()
            for cell, s, e in occupancy(route, w.speed, self.grid.cell):
                for entry in self.table.at(cell):
                    if entry.owner == wid or not overlaps(s, e, entry.start, entry.end):
                        continue
                    if keep(entry):  # only a hold can get here: w is boxed in
                        self._restore(saved)
                        return False
                    victims.add(entry.owner)
            saved.setdefault(wid, w.route)
            w.route = route
            self._reserve(w)
            for x in sorted(victims - queued):
                queued.add(x)
                heapq.heappush(heap, (self.priority(self.vehicles[x]), x))
        changed = False
        for wid, old in saved.items():
            w = self.vehicles[wid]
            changed |= w.route is not old
            if w is not v:
                w.replans += 1
                self.emit(self.env.now, "replan", w.id, -1 if w.task is None else w.task.id,
                          w.cell)
            self._wake(w)
        if changed:
            self.notify()
        return True

    def _restore(self, saved: dict[int, Route]) -> None:
        for wid, route in saved.items():
            w = self.vehicles[wid]
            w.route = route
            self._reserve(w)

    def hold(self, v: TimedVehicle) -> None:
        """``v`` broke down: it stops at its commit point (the end of the step it is executing,
        or its cell), its later reservations are released and its cell is held hard (nobody
        plans through it, nobody asks it to make way) until it is repaired."""
        t, c = self.commit_point(v)
        v.route = [(t, c)]
        v.arrived = True
        self._reserve(v)
        self._wake(v)
        self.notify()

    def _wake(self, v: TimedVehicle) -> None:
        if not v.changed.triggered:
            v.changed.succeed()

    def notify(self) -> None:
        """Tell waiting vehicles to try again: the table changed, or a vehicle became idle
        (and so displaceable)."""
        ev, self.released = self.released, self.env.event()
        ev.succeed()


# ----------------------------------------------------------------------------- timed drives


class DriveContext:
    """What the timed drives need of the run (the operator's): the task book, the fleet's
    index, the service time, the dispatcher's wake-up, a breakdown to finish later and the
    vehicle's return to idle (:meth:`dispatch.plan.operator.Operator.go_idle`)."""

    def __init__(self, book, fleet, service_time: float, notify: Callable[[], None],
                 breakdown: Callable[..., bool], go_idle: Callable[..., None]) -> None:
        self.book, self.fleet, self.service_time = book, fleet, service_time
        self.notify, self.breakdown, self.go_idle = notify, breakdown, go_idle


def _start(traffic: Traffic, ctx: DriveContext) -> None:
    for t in traffic.vehicles.values():
        t.vehicle.proc = traffic.env.process(_drive(traffic, ctx, t))


def begin_wait(traffic: Traffic, t: TimedVehicle) -> None:
    """It stands in its cell on the way to its task (until its next step starts)."""
    if t.waiting_since is None:
        now = traffic.env.now
        t.waiting_since = now
        t.waits += 1
        traffic.emit(now, "wait", t.id, t.task.id, t.cell)


def end_wait(t: TimedVehicle, now: float) -> None:
    """Its wait (if any) ends now."""
    if t.waiting_since is not None:
        t.wait_seconds += now - t.waiting_since
        t.waiting_since = None


def _finish(traffic: Traffic, ctx: DriveContext, t: TimedVehicle):
    """Serve the task at its cell (the service time), then idle."""
    env, v, task = traffic.env, t.vehicle, t.task
    if ctx.service_time > 0:
        yield env.timeout(ctx.service_time)
    t.task = None
    v.completed += 1
    v.plan.clear()
    ctx.go_idle(v, task)


def _drive(traffic: Traffic, ctx: DriveContext, t: TimedVehicle):
    """Process (one per vehicle for the whole run): follow the timed route that the traffic
    keeps for this vehicle, whatever it is for: its task (then serve it), parking out of
    someone's way while idle, or holding its cell (a one-cell route). Without a route to its
    task it waits and asks again."""
    env, cell_m, v = traffic.env, traffic.grid.cell, t.vehicle
    while True:
        if t.changed.triggered:
            t.changed = env.event()
        route, task = t.route, t.task
        if v.failed or t.breaking:  # broken down (Traffic.hold): stand until repaired
            try:
                yield t.changed
            except simpy.Interrupt:
                pass
            continue
        if len(route) == 1:
            if task is None:  # idle: stay until told to move
                yield t.changed
            elif v.loc == task.loc:
                t.arrived = True
                ctx.book.picked_up(task)
                try:
                    yield from _finish(traffic, ctx, t)
                except simpy.Interrupt:  # broke down while serving: breakdown() did the rest
                    continue
                t.arrived = False
                traffic.notify()  # idle now: it can be asked to make way
            else:  # no route to the task: hold the cell, retry on a release or a timer
                begin_wait(traffic, t)
                yield env.any_of([env.timeout(traffic.retry_after), t.changed,
                                  traffic.released])
                if t.route is route and t.last_try < env.now:  # once per instant
                    traffic.request(t)
            continue
        (_, here), (arr, nxt) = route[0], route[1]
        dep = arr - step_seconds(here, nxt, v.speed, cell_m)
        if dep > env.now + EPS:
            if task is not None:
                begin_wait(traffic, t)
            yield env.any_of([env.timeout(dep - env.now), t.changed])
            continue
        end_wait(t, env.now)
        nxt, arr = traffic.start_step(t)
        yield env.timeout(max(arr - env.now, 0.0))
        metres = step_length(v.loc, nxt) * cell_m
        v.loc = nxt
        v.drove(metres)  # to a task, or parking: never with a passenger here
        traffic.emit(env.now, "move", v.id, -1 if t.task is None else t.task.id, nxt)


def _after_step(traffic: Traffic, t: TimedVehicle, again: Callable[[], Any]):
    yield traffic.env.timeout(t.step[3] - traffic.env.now)
    t.breaking = False
    again()


class TimedExecution:
    """Reservation-based execution (voxel world, capacity 1), the operator's
    :class:`dispatch.plan.execution.Execution`: one drive process per vehicle for the whole run
    follows the timed route the traffic keeps for it; the operator hands it a task, breaks it
    down and repairs it through here."""

    def __init__(self, traffic: Traffic, op) -> None:
        self.traffic, self.op = traffic, op
        self.context = DriveContext(op.book, op.fleet, op.service_time, op.notify, op.breakdown,
                                    op.go_idle)
        _start(traffic, self.context)

    @property
    def env(self):
        return self.traffic.env

    def set_out(self, v, task, cost: float, at: tuple | None) -> None:
        """``v`` now drives to ``task`` (its plan: the task's one stop); the task's ``cost`` is
        its priority."""
        op = self.op
        op.book.assign(task, v.id, cost)
        v.plan.replace(request_stops(task, op.service_time), None, self.env.now)
        op.fleet.refresh(v)
        t = self.traffic.of(v)
        t.task, v.busy_since = task, self.env.now
        self.traffic.emit(self.env.now, "depart", v.id, task.id, v.loc)
        self.traffic.request(t)

    def holds(self, v):
        return self.traffic.of(v).task

    def breaking(self, v) -> bool:
        return self.traffic.of(v).breaking

    def halt(self, v, again: Callable[[], Any]) -> list | None:
        """``v`` breaks down: None if it is executing a step (a step is never interrupted:
        ``again`` runs on arrival in the step's cell, so it never moves while failed); else
        it stops serving, holds its cell hard, and the task it had is returned (in a list)."""
        env, t = self.env, self.traffic.of(v)
        if t.step is not None and t.step[3] > env.now + EPS:
            t.breaking = True
            env.process(_after_step(self.traffic, t, again))
            return None
        task = t.task
        if t.arrived and task is not None and v.proc is not env.active_process:
            v.proc.interrupt("breakdown")  # in service at the task's cell
        end_wait(t, env.now)
        self.traffic.hold(t)
        t.task = None
        return [] if task is None else [task]

    def repaired(self, v) -> None:
        t = self.traffic.of(v)
        t.arrived = False  # displaceable again, like any idle vehicle
        self.traffic.notify()
        if not t.changed.triggered:
            t.changed.succeed()

    def end(self, now: float) -> None:
        """The run is over: open waits end now."""
        for t in self.traffic.vehicles.values():
            end_wait(t, now)

    def counts(self, v) -> dict:
        """The ``vehicles`` table's waits, replans and wait_seconds of ``v``."""
        t = self.traffic.of(v)
        return {"waits": t.waits, "replans": t.replans, "wait_seconds": t.wait_seconds}

