"""Vehicles: each one a SimPy process that follows its path cell by cell in simulated time.

With a reservation-aware planner a vehicle follows a *timed* route that the run's
:class:`dispatch.reservations.Traffic` keeps conflict-free: it may stand in a cell before a step
(a ``wait``), its route may be replaced by a higher-priority vehicle's request (a ``replan``),
without any route it holds its cell and retries, and an idle vehicle may move out of the way
(its ``move`` events have task id -1). Otherwise it follows its untimed path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from dispatch.contracts import AgentView
from dispatch.motion import step_length
from dispatch.reservations import EPS, step_seconds
from dispatch.world import Cell

if TYPE_CHECKING:
    from dispatch.sim import Simulation
    from dispatch.tasks import Task


@dataclass(eq=False)
class Vehicle:
    """A UAV or UGV. ``cell`` is where it is now; it moves only along a planned path."""

    id: int
    kind: str
    speed: float
    start: Cell
    cell: Cell = field(init=False)
    busy: bool = False
    task: Task | None = None
    distance: float = 0.0  # metres travelled
    busy_seconds: float = 0.0
    busy_since: float = 0.0
    completed: int = 0
    # ---- execution with reservations (see dispatch.reservations)
    #: timed route ``[(t, cell), ...]``; ``route[0]`` is the cell it stands in (or is stepping
    #: into, with the step's arrival time); a one-cell route holds that cell indefinitely
    route: list[tuple[float, Cell]] = field(default_factory=list, repr=False)
    #: the step being executed: (from cell, to cell, departure, arrival)
    step: tuple[Cell, Cell, float, float] | None = field(default=None, repr=False)
    arrived: bool = False  # serving its task at the task's cell: its reservations are hard
    changed: Any = field(default=None, repr=False)  # SimPy event: its route was replaced
    last_try: float = -math.inf  # when it last asked for a route
    waits: int = 0
    replans: int = 0
    wait_seconds: float = 0.0
    waiting_since: float | None = None

    def __post_init__(self) -> None:
        self.cell = self.start

    @property
    def flies(self) -> bool:
        return self.kind == "uav"

    def view(self) -> AgentView:
        return AgentView(self.id, self.kind, self.cell, self.speed)  # type: ignore[arg-type]

    def serve(self, sim: Simulation, task: Task, path: list[Cell]):
        """Process: travel ``path`` to the task, serve it, become idle again."""
        env, cell_m = sim.env, sim.world.cell
        self.busy, self.task = True, task
        self.busy_since = env.now
        sim.record_event("depart", self.id, task.id, self.cell)
        for nxt in path[1:]:
            metres = step_length(self.cell, nxt) * cell_m
            yield env.timeout(metres / self.speed)
            self._enter(sim, task, nxt, metres)
        yield from self._serve_at(sim, task)

    def drive(self, sim: Simulation):
        """Process (with reservations, one per vehicle for the whole run): follow the timed
        route that ``sim.traffic`` keeps for this vehicle, whatever it is for: its task (then
        serve it), parking out of someone's way while idle, or holding its cell (a one-cell
        route). Without a route to its task it waits and asks again (see
        :class:`dispatch.reservations.Traffic`)."""
        env, traffic, cell_m = sim.env, sim.traffic, sim.world.cell
        assert traffic is not None
        while True:
            if self.changed.triggered:
                self.changed = env.event()
            route, task = self.route, self.task
            if len(route) == 1:
                if task is None:  # idle: stay until told to move
                    yield self.changed
                elif self.cell == task.cell:
                    self.arrived = True
                    yield from self._serve_at(sim, task)
                    self.arrived = False
                    traffic.notify()  # idle now: it can be asked to make way
                else:  # no route to the task: hold the cell, retry on a release or a timer
                    self.begin_wait(sim)
                    yield env.any_of([env.timeout(traffic.retry_after), self.changed,
                                      traffic.released])
                    if self.route is route and self.last_try < env.now:  # once per instant
                        traffic.request(self)
                continue
            (_, here), (arr, nxt) = route[0], route[1]
            dep = arr - step_seconds(here, nxt, self.speed, cell_m)
            if dep > env.now + EPS:
                if task is not None:
                    self.begin_wait(sim)
                yield env.any_of([env.timeout(dep - env.now), self.changed])
                continue
            self.end_wait(env.now)
            nxt, arr = traffic.start_step(self)
            yield env.timeout(max(arr - env.now, 0.0))
            self._enter(sim, self.task, nxt, step_length(self.cell, nxt) * cell_m)

    def _enter(self, sim: Simulation, task: Task | None, nxt: Cell, metres: float) -> None:
        self.cell = nxt
        self.distance += metres
        sim.physics.move(self.id, sim.world.grid.centre(nxt))
        sim.record_event("move", self.id, -1 if task is None else task.id, nxt)

    def _serve_at(self, sim: Simulation, task: Task):
        env = sim.env
        sim.task_arrived(task, self)
        service = sim.spec.scenario.tasks.service_time
        if service > 0:
            yield env.timeout(service)
        self.busy_seconds += env.now - self.busy_since
        self.busy, self.task = False, None
        self.completed += 1
        sim.task_completed(task, self)

    def begin_wait(self, sim: Simulation) -> None:
        """It stands in its cell on the way to its task (until its next step starts)."""
        if self.waiting_since is None:
            self.waiting_since = sim.env.now
            self.waits += 1
            sim.record_event("wait", self.id, self.task.id, self.cell)  # type: ignore[union-attr]

    def end_wait(self, now: float) -> None:
        """Its wait (if any) ends now."""
        if self.waiting_since is not None:
            self.wait_seconds += now - self.waiting_since
            self.waiting_since = None
