"""Reservation-based execution's traffic: the timed vehicles, the run's reservation table and
the paper's conflict rule.

Used only when the run's planner is reservation-aware (``Planner.reservation_aware``; the
``reservation`` planner). With any other planner vehicles follow their untimed paths as before.
Routes are timed and hold cells as :func:`dispatch.api.motion.occupancy` defines (the time
model); the table is :class:`dispatch.plan.reservation_table.ReservationTable`; the drives
that follow the routes are :mod:`dispatch.plan.timed_drives`.

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

Every displacement is a ``replan`` event (and every wait a ``wait`` event of the drives); the
``vehicles`` table counts ``waits``, ``replans`` and ``wait_seconds``.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import simpy

from dispatch.api.motion import EPS, Route, occupancy, overlaps, step_box
from dispatch.api.problem import AgentView
from dispatch.locations import Cell
from dispatch.plan.reservation_table import Entry, ReservationTable, TableView, route_error

if TYPE_CHECKING:
    from dispatch.api.contracts import Planner
    from dispatch.api.voxels import Grid

INF = math.inf
#: A request displaces vehicles leaving each one's cell free for this many of its straight
#: steps; if that fails, for the next (more time to get out of the way).
INERTIA_STEPS = (1.0, 4.0)


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
    """The run's reservation table, its timed vehicles and the conflict rule (see the module
    docstring).

    Each vehicle's drive process (:mod:`dispatch.plan.timed_drives`, one per vehicle for the
    whole run) follows its :class:`TimedVehicle` record's ``route`` and calls
    :meth:`start_step` when it commits to a step; :meth:`request` is called when a vehicle is
    given a task and when a waiting vehicle tries again. A record's ``changed`` fires when a
    request changed that vehicle's route, and :attr:`released` whenever a request changed the
    table or a vehicle became idle (:meth:`notify`).
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
        v.arrived = True
        self.stop(v)

    def stop(self, v: TimedVehicle) -> None:
        """``v`` stops at its commit point (the end of the step it is executing, or its cell)
        and holds it; its later reservations are released."""
        t, c = self.commit_point(v)
        v.route = [(t, c)]
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
