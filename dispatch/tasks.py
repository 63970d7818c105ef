"""Tasks, their life cycle, and the task sources (SimPy processes).

A task is released ``open``, becomes ``assigned`` when the dispatcher hands it to a vehicle and
ends in exactly one terminal state: ``completed``, ``expired`` (its ``ttl`` ran out while it was
open), ``unreachable`` (no vehicle of the fleet can ever reach it) or ``cancelled`` (the run
ended first).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from dispatch.contracts import TaskView
from dispatch.world import Cell, Grid

if TYPE_CHECKING:
    from dispatch.sim import Simulation

log = logging.getLogger(__name__)


class TaskState(str, Enum):
    OPEN = "open"
    ASSIGNED = "assigned"
    COMPLETED = "completed"
    EXPIRED = "expired"
    UNREACHABLE = "unreachable"
    CANCELLED = "cancelled"

    @property
    def terminal(self) -> bool:
        return self in TERMINAL


TERMINAL = frozenset({TaskState.COMPLETED, TaskState.EXPIRED, TaskState.UNREACHABLE,
                      TaskState.CANCELLED})


@dataclass(eq=False)
class Task:
    """One task's record; the simulation updates it as the task moves through its states."""

    id: int
    kind: str
    cell: Cell
    released_at: float
    state: TaskState = TaskState.OPEN
    assigned_at: float = math.nan
    agent_id: int = -1
    cost: float = math.nan
    arrived_at: float = math.nan
    completed_at: float = math.nan
    closed_at: float = math.nan
    conflicted: bool = False
    offered: bool = False  # appeared in at least one allocation problem

    def view(self) -> TaskView:
        return TaskView(self.id, self.kind, self.cell, self.released_at)  # type: ignore[arg-type]


class TaskFactory:
    """Draws task cells: on the ground layer with probability ``ground_fraction``, else in the
    free cells above it. Every draw comes from the generator it is given."""

    def __init__(self, grid: Grid, ground_fraction: float, rng: np.random.Generator) -> None:
        free = grid.free_cells()
        self.ground = free[free[:, 2] == 0]
        self.air = free[free[:, 2] > 0]
        self.ground_fraction = ground_fraction
        self.rng = rng

    def draw(self) -> tuple[str, Cell]:
        on_ground = self.rng.random() < self.ground_fraction or len(self.air) == 0
        pool = self.ground if on_ground else self.air
        c = pool[self.rng.integers(len(pool))]
        return ("ground" if on_ground else "air"), (int(c[0]), int(c[1]), int(c[2]))


def static_source(sim: Simulation, count: int):
    """Release ``count`` tasks at t = 0."""
    for _ in range(count):
        sim.release(*sim.task_factory.draw())
    sim.source_done()
    yield sim.env.timeout(0)


def _generated(sim: Simulation, next_gap):
    """Release generated tasks after gaps from ``next_gap()``; skip while ``max_active`` are open."""
    cfg = sim.spec.scenario.tasks
    released = 0
    while cfg.count is None or released < cfg.count:
        yield sim.env.timeout(next_gap())
        if cfg.max_active is not None and sim.active_tasks() >= cfg.max_active:
            sim.record_event("skipped", -1, -1, None)
            continue
        sim.release(*sim.task_factory.draw())
        released += 1
    sim.source_done()


def periodic_source(sim: Simulation):
    """A task every ``interval`` seconds (the first at ``interval``)."""
    interval = sim.spec.scenario.tasks.interval
    yield from _generated(sim, lambda: interval)


def poisson_source(sim: Simulation, rng: np.random.Generator):
    """Tasks as a Poisson process of ``rate`` per second."""
    rate = sim.spec.scenario.tasks.rate
    yield from _generated(sim, lambda: float(rng.exponential(1.0 / rate)))


def trace_source(sim: Simulation):
    """Tasks at the times and positions of the trace file (a task in a blocked cell is
    released and closed as unreachable)."""
    cfg = sim.spec.scenario.tasks
    rows = cfg.trace_rows if cfg.count is None else cfg.trace_rows[: cfg.count]
    for t, x, y, z in rows:
        if t > sim.env.now:
            yield sim.env.timeout(t - sim.env.now)
        cell = sim.world.grid.cell_of((x, y, z))
        sim.release("ground" if cell[2] == 0 else "air", cell)
    sim.source_done()


def start_source(sim: Simulation, rng: np.random.Generator):
    """Start the scenario's task source as a SimPy process."""
    cfg = sim.spec.scenario.tasks
    if cfg.source == "static":
        gen = static_source(sim, sim.spec.n_static_tasks)
    elif cfg.source == "periodic":
        gen = periodic_source(sim)
    elif cfg.source == "poisson":
        gen = poisson_source(sim, rng)
    elif cfg.source == "trace":
        gen = trace_source(sim)
    else:  # the scenario parser admits only the sources above
        raise ValueError(f"unknown task source {cfg.source!r}")
    return sim.env.process(gen)
