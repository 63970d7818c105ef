"""The ``astar`` planner: exact shortest-path costs from distance fields, paths from A*.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the shortest legal path length in metres (movement
      rules of :mod:`dispatch.motion`) from ``agents[a].cell`` to ``tasks[t].cell``, divided by
      ``agents[a].speed``. It is ``inf`` for a UGV and a task that is not on the ground layer
      (``kind != "ground"`` or ``k != 0``), for an agent whose cell is blocked, out of bounds,
      or (UGV) off the ground layer, and where no path exists.
    * One distance field per (task, movement model) is computed with Dijkstra from the task's
      cell the first time a decision needs it and reused at later decisions until
      :meth:`AStarPlanner.task_closed` is called for that task. Fields are also shared through
      the grid-level LRU of :func:`planners.graph.distance_field`, so tasks on the same cell
      cost one Dijkstra run.
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
from planners.graph import astar, distance_field


class AStarPlanner(Planner):
    """Exact grid planner: Dijkstra distance fields for costs, A* for paths."""

    name = "astar"

    def __init__(self, world: World) -> None:
        super().__init__(world)
        # task id -> {flies: (task cell, field)}
        self._fields: dict[int, dict[bool, tuple[Cell, np.ndarray]]] = {}
        self.stats.extra.setdefault("fields_computed", 0)
        self.stats.extra.setdefault("field_reuses", 0)

    def _field(self, task: TaskView, flies: bool) -> np.ndarray:
        per_task = self._fields.setdefault(task.id, {})
        cell = tuple(int(v) for v in task.cell)
        hit = per_task.get(flies)
        if hit is not None and hit[0] == cell:
            self.stats.extra["field_reuses"] += 1
            return hit[1]
        field = distance_field(self.world.grid, cell, flies)
        per_task[flies] = (cell, field)
        self.stats.extra["fields_computed"] += 1
        return field

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
        inside = ((cells >= 0) & (cells < np.array([nx, ny, nz]))).all(axis=1)
        safe = np.where(inside[:, None], cells, 0)
        ok = inside & ~grid.occupied[safe[:, 0], safe[:, 1], safe[:, 2]]
        uav = np.flatnonzero(ok & flies)
        ugv = np.flatnonzero(ok & ~flies & (cells[:, 2] == 0))
        for t, task in enumerate(tasks):
            in_bounds = grid.in_bounds(task.cell)
            if uav.size and in_bounds:
                f = self._field(task, True)
                out[uav, t] = f[cells[uav, 0], cells[uav, 1], cells[uav, 2]] / speed[uav]
            if ugv.size and in_bounds and task.kind == "ground" and task.cell[2] == 0:
                f = self._field(task, False)
                out[ugv, t] = f[cells[ugv, 0], cells[ugv, 1]] / speed[ugv]
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
