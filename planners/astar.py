"""The ``astar`` planner: exact shortest-path costs from distance fields, paths from A*.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the shortest legal path length in metres (movement
      rules of :mod:`dispatch.api.motion`) from ``agents[a].cell`` to ``tasks[t].cell``, divided by
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

    * Lazy costs (``[dispatch] lazy_costs``, :mod:`dispatch.decide.lazy`): ``bounds`` gives lower
      bounds without any UAV field (the obstacle-free 26-connected lattice distance, scaled by
      ``1 - 1e-12`` so that rounding never lifts it above the exact length; ``inf`` across
      connected components of free space, computed once per grid), ``exact`` computes single
      pairs by A* and remembers them per task and vehicle cell until the task closes.

Statistics: ``stats.cost_queries`` counts calls to ``costs`` and ``bounds``, ``stats.plans`` calls
to ``plan``;
``stats.extra`` holds ``fields_computed`` (Dijkstra runs) and ``field_reuses`` (fields read
from the cache), ``astar_pairs`` (pairs ``exact`` searched) and ``pair_reuses`` (remembered
pairs ``bounds`` gave as exact).
"""

from __future__ import annotations

import numpy as np

from dispatch.api.contracts import Planner
from dispatch.api.problem import AgentView, TaskView
from dispatch.locations import Cell
from dispatch.space.world import World
from planners.graph import astar, components, field_cache, field_values, lattice_bound


class AStarPlanner(Planner):
    """Exact grid planner: Dijkstra distance fields for costs, A* for paths.

    ``field_cache_mb`` (default :data:`planners.graph.FIELD_CACHE_MAX_BYTES`, 256 MB) bounds
    the grid's field cache, which owns every field: the planner keeps no field, only reads
    them (see module).
    """

    name = "astar"
    spaces = ("voxel",)
    lower_bounds = True

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
        self.stats.extra.setdefault("astar_pairs", 0)
        self.stats.extra.setdefault("pair_reuses", 0)
        #: task id -> {vehicle node: metres}: the pairs :meth:`exact` computed (lazy costs)
        self._pairs: dict[int, dict[int, float]] = {}

    def _values(self, tasks, flies: bool, nodes: np.ndarray) -> np.ndarray:
        """``(len(nodes), len(tasks))`` field values: task ``t``'s field read at each node."""
        values, computed = field_values(self.world.grid, [_cell(t) for t in tasks], flies,
                                        nodes)
        self.stats.extra["fields_computed"] += computed
        self.stats.extra["field_reuses"] += len(tasks) - computed
        return values

    def _split(self, agents, tasks):
        """What both cost paths need: ``(cells, speed, uav rows, uav nodes, in-bounds task
        columns, ugv rows, ugv nodes, ground task columns)``; rows are agents whose cell is
        free and in bounds (UGVs: on the ground layer), nodes their flat lattice indices."""
        grid = self.world.grid
        nx, ny, nz = grid.shape
        views = list(agents)  # one pass: each view of a lazy sequence is built on access
        cells = np.array([a.loc for a in views], dtype=np.int64).reshape(-1, 3)
        speed = np.array([a.speed for a in views], dtype=float)
        flies = np.array([a.kind == "uav" for a in views], dtype=bool)
        inside = ((cells >= 0) & (cells < (nx, ny, nz))).all(axis=1)
        safe = np.where(inside[:, None], cells, 0)
        ok = inside & ~grid.occupied[safe[:, 0], safe[:, 1], safe[:, 2]]
        in_bounds = [t for t, task in enumerate(tasks) if grid.in_bounds(task.cell)]
        uav = np.flatnonzero(ok & flies)
        uav_node = (safe[uav, 0] * ny + safe[uav, 1]) * nz + safe[uav, 2]
        ugv = np.flatnonzero(ok & ~flies & (cells[:, 2] == 0))
        ugv_node = safe[ugv, 0] * ny + safe[ugv, 1]
        ground = [t for t in in_bounds if tasks[t].kind == "ground" and tasks[t].cell[2] == 0]
        return cells, speed, uav, uav_node, in_bounds, ugv, ugv_node, ground

    def costs(self, agents: tuple[AgentView, ...], tasks: tuple[TaskView, ...]) -> np.ndarray:
        """Return the ``(len(agents), len(tasks))`` array of exact travel seconds (see module)."""
        self.stats.cost_queries += 1
        out = np.full((len(agents), len(tasks)), np.inf)
        if not agents or not tasks:
            return out
        _, speed, uav, uav_node, in_bounds, ugv, ugv_node, ground = self._split(agents, tasks)
        if uav.size and in_bounds:
            vals = self._values([tasks[t] for t in in_bounds], True, uav_node)
            out[np.ix_(uav, in_bounds)] = vals / speed[uav, None]
        if ugv.size and ground:
            vals = self._values([tasks[t] for t in ground], False, ugv_node)
            out[np.ix_(ugv, ground)] = vals / speed[ugv, None]
        return out

    def bounds(self, agents, tasks: tuple[TaskView, ...]) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, exact)`` (see :meth:`dispatch.api.contracts.Planner.bounds`) without any UAV
        distance field: a UAV pair's bound is the obstacle-free lattice distance
        (:func:`planners.graph.lattice_bound`) over the speed, ``inf`` (exact) across
        connected components of free space (:func:`planners.graph.components`); it is exact
        where the pair was computed before (:meth:`exact` remembers pairs per task and
        vehicle cell) or the task's complete Dijkstra tree is in the field cache. UGV pairs
        are exact (ground fields: 2,500 nodes on the paper's world, cheap)."""
        self.stats.cost_queries += 1
        n, m = len(agents), len(tasks)
        out = np.full((n, m), np.inf)
        exact = np.ones((n, m), dtype=bool)
        if not agents or not tasks:
            return out, exact
        cells, speed, uav, uav_node, in_bounds, ugv, ugv_node, ground = self._split(agents,
                                                                                    tasks)
        grid = self.world.grid
        if uav.size and in_bounds:
            tcells = np.array([tasks[t].cell for t in in_bounds], dtype=np.int64).reshape(-1, 3)
            _, ny, nz = grid.shape
            tnode = (tcells[:, 0] * ny + tcells[:, 1]) * nz + tcells[:, 2]
            labels = components(grid, True)
            la, lt = labels[uav_node], labels[tnode]
            same = (la[:, None] == lt[None, :]) & (la[:, None] >= 0)
            metres = np.where(same, lattice_bound(cells[uav], tcells, grid.cell), np.inf)
            known = ~same | (metres == 0.0)  # inf across components; a vehicle on the cell
            cache = field_cache(grid)
            whole = [c for c, node in enumerate(tnode.tolist())
                     if (tree := cache.peek(("tree", True, node))) is not None
                     and tree.radius == np.inf]
            if whole:  # a complete tree is cached: those columns exactly, from it
                metres[:, whole] = self._values([tasks[in_bounds[c]] for c in whole], True,
                                                uav_node)
                known[:, whole] = True
            rows_of: dict[int, list[int]] = {}
            for r, node in enumerate(uav_node.tolist()):
                rows_of.setdefault(node, []).append(r)
            hits = 0
            for c, t in enumerate(in_bounds):
                memo = self._pairs.get(tasks[t].id)
                if not memo:
                    continue
                for node, d in memo.items():
                    for r in rows_of.get(node, ()):
                        metres[r, c] = d
                        known[r, c] = True
                        hits += 1
            self.stats.extra["pair_reuses"] += hits
            out[np.ix_(uav, in_bounds)] = metres / speed[uav, None]
            exact[np.ix_(uav, in_bounds)] = known
        if ugv.size and ground:
            vals = self._values([tasks[t] for t in ground], False, ugv_node)
            out[np.ix_(ugv, ground)] = vals / speed[ugv, None]
        return out, exact

    def exact(self, agents, tasks: tuple[TaskView, ...], rows: np.ndarray,
              cols: np.ndarray) -> np.ndarray:
        """``costs(agents, tasks)[rows, cols]``: a UAV pair by one A* search from the vehicle's
        cell to the task's (remembered for the task while it is open, per vehicle cell; equal
        to the distance field's value up to float rounding, ~1e-15 relative); any other pair
        through :meth:`costs`."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        cols = np.asarray(cols, dtype=np.int64).reshape(-1)
        out = np.empty(rows.size)
        grid = self.world.grid
        _, ny, nz = grid.shape
        for k, (r, c) in enumerate(zip(rows.tolist(), cols.tolist())):
            agent, task = agents[r], tasks[c]
            cell = tuple(int(v) for v in agent.cell)
            if not (agent.flies and grid.in_bounds(cell) and grid.in_bounds(task.cell)
                    and not grid.occupied[cell]):
                out[k] = self.costs((agent,), (task,))[0, 0]
                continue
            node = (cell[0] * ny + cell[1]) * nz + cell[2]
            memo = self._pairs.setdefault(task.id, {})
            d = memo.get(node)
            if d is None:
                d = memo[node] = astar(grid, cell, _cell(task), True, path=False)[0]
                self.stats.extra["astar_pairs"] += 1
            out[k] = d / agent.speed
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
        """Drop the pairs :meth:`exact` remembered for the task (the planner keeps no field:
        the grid's cache evicts them)."""
        self._pairs.pop(task_id, None)


def _cell(task: TaskView) -> Cell:
    c = task.cell
    return c if type(c) is tuple else tuple(int(v) for v in c)  # type: ignore[return-value]
