"""The ``astar`` planner: exact shortest-path costs from distance fields, paths from A*.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the shortest legal path length in metres (movement
      rules of :mod:`dispatch.motion`) from ``agents[a].cell`` to ``tasks[t].cell``, divided by
      ``agents[a].speed``. It is ``inf`` for a UGV and a task that is not on the ground layer
      (``kind != "ground"`` or ``k != 0``), for an agent whose cell is blocked, out of bounds,
      or (UGV) off the ground layer, and where no path exists.
    * One distance field per (task, movement model) is computed with Dijkstra from the task's
      cell the first time a decision needs it and reused at later decisions until
      :meth:`AStarPlanner.task_closed` is called for that task. The new fields of one decision
      are computed together (compiled, on threads: :func:`planners.graph.distance_fields`).
      Fields are also shared through the grid-level LRU of :mod:`planners.graph`, so tasks on
      the same cell cost one Dijkstra run. A later decision (vehicles moved, tasks unchanged)
      only reads the cached fields at the agents' cells: a few vectorized gathers.
    * Fields are float64 (600 kB per task and UAV field on the paper's 50x50x30 world): float32
      would lose the 1e-9 exactness (its spacing near 100 m is 8e-6).
    * ``plan`` is a true A* search (octile heuristic, consistent) returning an optimal path whose
      length equals the distance-field cost (up to float rounding), or None.

Statistics: ``stats.cost_queries`` counts calls to ``costs``, ``stats.plans`` calls to ``plan``;
``stats.extra`` holds ``fields_computed`` (fields fetched for a task the first time) and
``field_reuses`` (fields found in the per-task cache).
"""

from __future__ import annotations

import numpy as np

from dispatch.contracts import AgentView, Planner, TaskView
from dispatch.world import Cell, World
from planners.graph import astar, distance_fields


class AStarPlanner(Planner):
    """Exact grid planner: Dijkstra distance fields for costs, A* for paths."""

    name = "astar"

    def __init__(self, world: World) -> None:
        super().__init__(world)
        # task id -> {flies: (task cell, flat field)}
        self._fields: dict[int, dict[bool, tuple[Cell, np.ndarray]]] = {}
        self.stats.extra.setdefault("fields_computed", 0)
        self.stats.extra.setdefault("field_reuses", 0)

    def _columns(self, tasks, flies: bool) -> list[np.ndarray]:
        """The flat field of each task under one movement model; new ones computed together."""
        out: list = [None] * len(tasks)
        new = []
        for t, task in enumerate(tasks):
            hit = self._fields.get(task.id, {}).get(flies)
            if hit is not None and hit[0] == _cell(task):
                out[t] = hit[1]
            else:
                new.append(t)
        self.stats.extra["field_reuses"] += len(tasks) - len(new)
        if new:
            cells = [_cell(tasks[t]) for t in new]
            for t, cell, field in zip(new, cells, distance_fields(self.world.grid, cells, flies)):
                out[t] = field.reshape(-1)
                self._fields.setdefault(tasks[t].id, {})[flies] = (cell, out[t])
            self.stats.extra["fields_computed"] += len(new)
        return out

    def costs(self, agents: tuple[AgentView, ...], tasks: tuple[TaskView, ...]) -> np.ndarray:
        """Return the ``(len(agents), len(tasks))`` array of exact travel seconds (see module)."""
        self.stats.cost_queries += 1
        grid = self.world.grid
        nx, ny, nz = grid.shape
        out = np.full((len(agents), len(tasks)), np.inf)
        if not agents or not tasks:
            return out
        cells = np.array([a.cell for a in agents], dtype=np.int64).reshape(-1, 3)
        speed = np.array([a.speed for a in agents], dtype=float)
        flies = np.array([a.flies for a in agents], dtype=bool)
        inside = ((cells >= 0) & (cells < (nx, ny, nz))).all(axis=1)
        safe = np.where(inside[:, None], cells, 0)
        ok = inside & ~grid.occupied[safe[:, 0], safe[:, 1], safe[:, 2]]
        in_bounds = [t for t, task in enumerate(tasks) if grid.in_bounds(task.cell)]
        uav = np.flatnonzero(ok & flies)
        if uav.size and in_bounds:
            node = (safe[uav, 0] * ny + safe[uav, 1]) * nz + safe[uav, 2]
            cols = self._columns([tasks[t] for t in in_bounds], True)
            out[np.ix_(uav, in_bounds)] = _gather(cols, node) / speed[uav, None]
        ugv = np.flatnonzero(ok & ~flies & (cells[:, 2] == 0))
        ground = [t for t in in_bounds if tasks[t].kind == "ground" and tasks[t].cell[2] == 0]
        if ugv.size and ground:
            node = safe[ugv, 0] * ny + safe[ugv, 1]
            cols = self._columns([tasks[t] for t in ground], False)
            out[np.ix_(ugv, ground)] = _gather(cols, node) / speed[ugv, None]
        return out

    def plan(self, agent: AgentView, goal: Cell) -> list[Cell] | None:
        """A shortest path of cells from ``agent.cell`` to ``goal`` (both included), or None.

        ``[agent.cell]`` when the agent is already there; None when either cell is blocked,
        out of bounds, off the ground layer for a UGV, or no path exists.
        """
        self.stats.plans += 1
        _, path = astar(self.world.grid, agent.cell, goal, agent.flies)
        return path

    def task_closed(self, task_id: int) -> None:
        """Drop this planner's fields for the task (the grid-level LRU may still hold them)."""
        self._fields.pop(task_id, None)



def _cell(task: TaskView) -> Cell:
    c = task.cell
    return c if type(c) is tuple else tuple(int(v) for v in c)  # type: ignore[return-value]


def _gather(fields: list[np.ndarray], nodes: np.ndarray) -> np.ndarray:
    """``(len(nodes), len(fields))``: each flat field read at the agents' nodes."""
    out = np.empty((nodes.size, len(fields)))
    for t, f in enumerate(fields):
        out[:, t] = f[nodes]
    return out
