"""The ``astar`` planner: exact shortest-path costs from distance fields, paths from A*.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the shortest legal path length in metres (movement
      rules of :mod:`dispatch.motion`) from ``agents[a].cell`` to ``tasks[t].cell``, divided by
      ``agents[a].speed``. It is ``inf`` for a UGV and a task that is not on the ground layer
      (``kind != "ground"`` or ``k != 0``), for an agent whose cell is blocked, out of bounds,
      or (UGV) off the ground layer, and where no path exists.
    * One distance field per (goal cell, movement model) is computed with Dijkstra from the
      goal the first time a decision needs it and kept in the grid's
      :class:`planners.graph.FieldCache`, which owns it: the planner keeps no reference, so the
      cache's byte bound (``field_cache_mb``) is the memory fields take, whatever the number
      of open tasks. A later decision (vehicles moved, tasks unchanged) reads the cached fields
      at the agents' cells in place (:func:`planners.graph.field_values`); tasks on the same
      cell share one field. A field evicted while its task is still open is computed again,
      identically. The new fields of one decision are computed a few at a time on threads.
    * Fields are float64 (600 kB per UAV field on the paper's 50x50x30 world, 9.6 MB on a
      200x200x30 one): float32 would lose the 1e-9 exactness (its spacing near 100 m is 8e-6).
    * ``plan`` is a true A* search (octile heuristic, consistent) returning an optimal path whose
      length equals the distance-field cost (up to float rounding), or None.

Statistics: ``stats.cost_queries`` counts calls to ``costs``, ``stats.plans`` calls to ``plan``;
``stats.extra`` holds ``fields_computed`` (Dijkstra runs) and ``field_reuses`` (fields read
from the cache).
"""

from __future__ import annotations

import numpy as np

from dispatch.contracts import AgentView, Planner, TaskView
from dispatch.world import Cell, World
from planners.graph import astar, field_cache, field_values


class AStarPlanner(Planner):
    """Exact grid planner: Dijkstra distance fields for costs, A* for paths.

    ``field_cache_mb`` (default :data:`planners.graph.FIELD_CACHE_MAX_BYTES`, 256 MB) bounds
    the grid's field cache, which owns every field: the planner keeps no field, only reads
    them (see module).
    """

    name = "astar"

    def __init__(self, world: World, *, field_cache_mb: float | None = None) -> None:
        super().__init__(world)
        if field_cache_mb is not None:
            mb = float(field_cache_mb)
            if not mb >= 0 or not np.isfinite(mb):
                raise ValueError(f"field_cache_mb must be a number of megabytes >= 0, "
                                 f"got {field_cache_mb!r}")
            field_cache(world.grid).resize(int(mb * 2**20))
        self.stats.extra.setdefault("fields_computed", 0)
        self.stats.extra.setdefault("field_reuses", 0)

    def _values(self, tasks, flies: bool, nodes: np.ndarray) -> np.ndarray:
        """``(len(nodes), len(tasks))`` field values: task ``t``'s field read at each node."""
        values, computed = field_values(self.world.grid, [_cell(t) for t in tasks], flies,
                                        nodes)
        self.stats.extra["fields_computed"] += computed
        self.stats.extra["field_reuses"] += len(tasks) - computed
        return values

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
            vals = self._values([tasks[t] for t in in_bounds], True, node)
            out[np.ix_(uav, in_bounds)] = vals / speed[uav, None]
        ugv = np.flatnonzero(ok & ~flies & (cells[:, 2] == 0))
        ground = [t for t in in_bounds if tasks[t].kind == "ground" and tasks[t].cell[2] == 0]
        if ugv.size and ground:
            node = safe[ugv, 0] * ny + safe[ugv, 1]
            vals = self._values([tasks[t] for t in ground], False, node)
            out[np.ix_(ugv, ground)] = vals / speed[ugv, None]
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
        """Nothing to drop: the planner keeps no field (the grid's cache evicts them)."""


def _cell(task: TaskView) -> Cell:
    c = task.cell
    return c if type(c) is tuple else tuple(int(v) for v in c)  # type: ignore[return-value]
