"""Vehicles: each one a SimPy process that follows its path cell by cell in simulated time."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from dispatch.contracts import AgentView
from dispatch.motion import step_length
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
            self.cell = nxt
            self.distance += metres
            sim.physics.move(self.id, sim.world.grid.centre(nxt))
            sim.record_event("move", self.id, task.id, nxt)
        sim.task_arrived(task, self)
        service = sim.spec.scenario.tasks.service_time
        if service > 0:
            yield env.timeout(service)
        self.busy_seconds += env.now - self.busy_since
        self.busy, self.task = False, None
        self.completed += 1
        sim.task_completed(task, self)
