"""The ``rstar`` planner: R* (Likhachev & Stentz 2008, "R* search") on the grid.

The algorithm
    R* is a randomized A*. Its high-level search runs over a sparse graph Γ that it builds as
    it goes: expanding a state ``s`` generates ``k`` random states at distance ``delta`` (cells,
    Chebyshev: a random cell on the surface of the cube of radius ``delta`` around ``s``, clipped
    to the grid, free, in the start's connected component) plus the goal when it lies within
    ``delta``. An edge ``(s, s')`` first costs its heuristic ``c_low = h(s, s')``; its real path
    is found lazily, only when ``s'`` is selected for expansion, by a *local* weighted A*
    (weight ``w``, octile heuristic, the motion rules of :mod:`dispatch.api.motion`). A local search
    that needs more than ``local_expansions`` expansions is abandoned and ``s'`` is labelled
    AVOID: OPEN is ordered by ``[AVOID, g + w h(s, goal)]``, so hard-to-solve states (and states
    with ``g(s) > w h(start, s)``) are only processed once nothing easy is left, and then their
    local search runs to completion. When a local search fails or proves its edge too expensive,
    ``s'`` takes the best other predecessor (``argmin g(p) + c_low(p, s')``), as in the paper.
    The search ends when the goal is selected with its edge's path computed; the path is the
    chain of local paths (loops cut).

Guarantees (stated and tested)
    * Every path returned is legal (:func:`dispatch.api.motion.check_path`).
    * **Bound.** The paper's guarantee is w-suboptimality with respect to Γ, probabilistic with
      respect to the true optimum. We make it deterministic (``enforce_bound=True``, the
      default): the R* path is *certified* when its cost is ``<= w * h(start, goal)`` (``h`` is
      the octile distance, a lower bound of the optimum); an uncertified path is compared with
      the edge ``start -> goal`` solved to completion by the same local weighted A* (whose cost
      is ``<= w * optimal``) and the shorter is kept. So the returned length is always
      ``<= w * optimal``, and **for w = 1 it equals the optimum** (a certified path then has
      the octile length; otherwise the local search is plain A*). ``stats.extra`` counts
      ``certified`` and ``bound_fallbacks``.
    * Unreachable pairs (different connected components, computed once per grid) cost ``inf``
      without any search.

Costs and caching
    ``costs`` answers each (agent cell, task) pair with one R* query (``inf`` for a UGV and a
    task above the ground layer); results are cached per task and agent cell until
    :meth:`RStarPlanner.task_closed`, and :meth:`RStarPlanner.plan` returns the path that was
    costed. Each query has its own generator seeded by ``(seed, flies, start, goal)``: no global
    random state, and a query's answer does not depend on the order of queries.

Parameters (``[dispatch.planner_params]``): ``w`` (suboptimality bound, >= 1; 1.5), ``delta``
(cells, 8), ``k`` (successors per expansion, 8), ``local_expansions`` (500), ``seed`` (0),
``enforce_bound`` (true), ``max_expansions`` (high-level expansions per search, 100: when
spent, the best goal path known so far is kept and the bound enforced as above; without this
cap a goal whose detour exceeds ``w`` x octile is AVOID and R* first expands every easy state).

Statistics (``stats.extra``): ``searches``, ``high_expansions``, ``local_expansions``,
``avoid_labels`` (local searches abandoned at ``local_expansions``), ``certified``,
``bound_fallbacks``.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from dispatch.api.contracts import Planner
from dispatch.api.motion import octile, offsets
from dispatch.api.problem import AgentView, TaskView
from dispatch.api.voxels import Grid
from dispatch.locations import Cell
from dispatch.space.world import World
from planners.sampling import (GoalCache, components, flat_index, lattice, legal_moves, on_lattice,
                               unflat)

_C2 = math.sqrt(2.0) - 1.0
_C3 = math.sqrt(3.0) - math.sqrt(2.0)
_MOVES_KEY = "planners.rstar.moves"
_EPS = 1e-9


def move_table(grid: Grid, flies: bool) -> list:
    """Per node of the model's lattice, a shared tuple of ``(node_delta, step_cells)`` (cached)."""
    per = grid.cache.setdefault(_MOVES_KEY, {})
    table = per.get(bool(flies))
    if table is None:
        dirs = legal_moves(grid, flies)
        shape = lattice(grid, flies)
        strides = (shape[1] * shape[2], shape[2], 1)
        offs = offsets(flies)
        uniq, inverse = np.unique(dirs, return_inverse=True)
        tables = np.empty(len(uniq), dtype=object)
        for u, m in enumerate(uniq.tolist()):
            tables[u] = tuple((sum(s * v for s, v in zip(strides, d)),
                               math.sqrt(sum(map(abs, d))))
                              for b, d in enumerate(offs) if m >> b & 1)
        table = per[bool(flies)] = tables[inverse.reshape(-1)].tolist()
    return table


class _Edge:
    __slots__ = ("clow", "exp", "path")

    def __init__(self, clow: float) -> None:
        self.clow = clow
        self.path: list[int] | None = None
        self.exp = 0


class _Query:
    """One R* search from ``start`` to ``goal`` (cells) under one movement model."""

    def __init__(self, planner: RStarPlanner, start: Cell, goal: Cell, flies: bool) -> None:
        self.pl = planner
        grid = planner.world.grid
        self.grid, self.flies = grid, flies
        self.shape = lattice(grid, flies)
        self.moves = move_table(grid, flies)
        self.labels = components(grid, flies)
        self.w = planner.w
        self.start = flat_index(self.shape, start)
        self.goal = flat_index(self.shape, goal)
        self.start_cell, self.goal_cell = start, goal
        seq = np.random.SeedSequence(entropy=planner.seed, spawn_key=(
            int(flies), *(int(v) for v in start), *(int(v) for v in goal)))
        self.rng = np.random.default_rng(seq)
        self.local_expanded = 0

    # ------------------------------------------------------------------ local search
    def local(self, s: int, t: int, limit: int | None) -> tuple[float, list[int] | None, int]:
        """Weighted A* (weight w) from node ``s`` to node ``t``.

        Returns ``(cost, path, expansions)``: the path's cost in cells when found; else
        ``path`` is None and ``cost`` a lower bound of the edge's cost (``inf`` when ``t`` is
        unreachable), the search having stopped after ``limit`` expansions.
        """
        w, moves = self.w, self.moves
        _, ny, nz = self.shape
        syz = ny * nz
        ti, tr = divmod(t, syz)
        tj, tk = divmod(tr, nz)
        c2, c3 = _C2, _C3

        def h(n: int) -> float:
            i, r = divmod(n, syz)
            j, k = divmod(r, nz)
            a, b, c = abs(i - ti), abs(j - tj), abs(k - tk)
            if a < b:
                a, b = b, a
            if b < c:
                b, c = c, b
                if a < b:
                    a, b = b, a
            return c3 * c + c2 * b + a

        g = {s: 0.0}
        parent = {s: -1}
        heap = [(w * h(s), -0.0, s)]
        pop, push = heapq.heappop, heapq.heappush
        exp = 0
        inf = math.inf
        found = False
        while heap:
            _, ng, n = heap[0]
            gn = -ng
            if gn > g[n]:
                pop(heap)
                continue
            if n == t:
                found = True
                break
            if limit is not None and exp >= limit:
                break
            pop(heap)
            exp += 1
            for dn, c in moves[n]:
                m = n + dn
                gm = gn + c
                if gm < g.get(m, inf):
                    g[m] = gm
                    parent[m] = n
                    push(heap, (gm + w * h(m), -gm, m))
        self.local_expanded += exp
        if found:
            path = []
            n = t
            while n != -1:
                path.append(n)
                n = parent[n]
            path.reverse()
            return g[t], path, exp
        if not heap:
            return inf, None, exp
        # min over OPEN of g + h bounds the optimal cost from below (h consistent)
        lower = min(-ng + h(n) for _, ng, n in heap if -ng <= g[n])
        return max(lower, h(s)), None, exp

    # ------------------------------------------------------------------ high level
    def h(self, a: int, b: int) -> float:
        return octile(unflat(self.shape, a), unflat(self.shape, b))

    def successors(self, s: int) -> list[int]:
        pl, rng, shape = self.pl, self.rng, self.shape
        c = unflat(shape, s)
        delta, k = pl.delta, pl.k
        axes = 3 if self.flies else 2
        label = self.labels[self.start]
        occ = self.grid.occupied
        out: list[int] = []
        seen = {s}
        for _ in range(3 * k):
            if len(out) == k:
                break
            off = rng.integers(-delta, delta + 1, size=3)
            a = int(rng.integers(axes))
            off[a] = delta if rng.random() < 0.5 else -delta
            if not self.flies:
                off[2] = 0
            cell = tuple(int(min(max(c[i] + off[i], 0), shape[i] - 1)) for i in range(3))
            if occ[cell]:
                continue
            n = flat_index(shape, cell)
            if n in seen or self.labels[n] != label:
                continue
            seen.add(n)
            out.append(n)
        g = unflat(shape, self.goal)
        if self.goal not in seen and max(abs(g[i] - c[i]) for i in range(3)) <= delta:
            out.append(self.goal)
        return out

    def run(self) -> tuple[float, list[Cell]] | None:
        """Cost (cells) and path of the R* search, with the bound enforced (see module)."""
        start, goal, w = self.start, self.goal, self.w
        if start == goal:
            return 0.0, [self.start_cell]
        thresh = self.pl.local_expansions
        max_high = self.pl.max_expansions
        g = {start: 0.0}
        bp: dict[int, int] = {}
        edges: dict[tuple[int, int], _Edge] = {}
        preds: dict[int, list[int]] = {}
        closed: set[int] = set()
        heap: list = []
        current: dict[int, tuple] = {}
        counter = 0

        def key(s: int) -> tuple[int, float]:
            avoid = 0
            if s != start:
                if g[s] > w * self.h(start, s) + _EPS:
                    avoid = 1
                else:
                    e = edges[(bp[s], s)]
                    if e.path is None and e.exp >= thresh:
                        avoid = 1
            return avoid, g[s] + w * self.h(s, goal)

        def update(s: int) -> None:
            nonlocal counter
            k = key(s)
            current[s] = k
            counter += 1
            heapq.heappush(heap, (k[0], k[1], counter, s))

        update(start)
        found = False
        high = avoided = 0
        while heap:
            avoid, f, _, s = heapq.heappop(heap)
            if current.get(s) != (avoid, f) or s in closed:
                continue
            del current[s]
            if s != start and edges[(bp[s], s)].path is None:
                u = bp[s]
                e = edges[(u, s)]
                limit = thresh if e.exp < thresh else None
                cost, path, exp = self.local(u, s, limit)
                e.exp, e.clow = e.exp + exp, cost
                if path is not None:
                    e.path = path
                elif limit is not None and math.isfinite(cost):
                    avoided += 1  # hard to solve: s is labelled AVOID
                if e.path is None or g[u] + e.clow > w * self.h(start, s) + _EPS:
                    best, best_q = None, math.inf
                    for p in preds[s]:
                        q = g[p] + edges[(p, s)].clow
                        if q < best_q:
                            best, best_q = p, q
                    if best is not None:
                        bp[s], g[s] = best, best_q
                        update(s)
                else:
                    g[s] = g[u] + e.clow
                    update(s)
                continue
            if s == goal:
                found = True
                break
            if high >= max_high:
                break  # expansion budget spent: best path known so far, bound enforced below
            closed.add(s)
            high += 1
            for t in self.successors(s):
                if t in closed:
                    continue
                e = edges.get((s, t))
                if e is None:
                    e = edges[(s, t)] = _Edge(self.h(s, t))
                    preds.setdefault(t, []).append(s)
                if t not in bp or g[s] + e.clow < g[t]:
                    bp[t], g[t] = s, g[s] + e.clow
                    update(t)
        stats = self.pl.stats.extra
        stats["high_expansions"] += high
        stats["avoid_labels"] += avoided
        result: tuple[float, list[int]] | None = None
        if not found and goal in bp and edges[(bp[goal], goal)].path is not None:
            found = True  # the goal's path is known (it was waiting in OPEN)
        if found:
            chain = [goal]
            while chain[-1] != start:
                chain.append(bp[chain[-1]])
            chain.reverse()
            nodes: list[int] = [start]
            for a, b in zip(chain, chain[1:]):
                nodes.extend(edges[(a, b)].path[1:])
            nodes = _cut_loops(nodes)
            result = (_nodes_length(self.shape, nodes), nodes)
        certified = result is not None and result[0] <= w * self.h(start, goal) + _EPS
        stats["certified"] += int(certified)
        if result is None or (self.pl.enforce_bound and not certified):
            # the edge start -> goal solved to completion: also the answer when Γ ran dry
            stats["bound_fallbacks"] += 1
            cost, path, _ = self.local(start, goal, None)
            if path is not None and (result is None or cost < result[0]):
                result = (_nodes_length(self.shape, path), path)
        stats["local_expansions"] += self.local_expanded
        if result is None:
            return None
        return result[0], [unflat(self.shape, n) for n in result[1]]


def _cut_loops(nodes: list[int]) -> list[int]:
    out: list[int] = []
    where: dict[int, int] = {}
    for n in nodes:
        i = where.get(n)
        if i is not None:
            for dropped in out[i + 1:]:
                where.pop(dropped, None)
            del out[i + 1:]
            continue
        where[n] = len(out)
        out.append(n)
    return out


def _nodes_length(shape, nodes: list[int]) -> float:
    total = 0.0
    prev = unflat(shape, nodes[0])
    for n in nodes[1:]:
        c = unflat(shape, n)
        total += math.sqrt(abs(c[0] - prev[0]) + abs(c[1] - prev[1]) + abs(c[2] - prev[2]))
        prev = c
    return total


class RStarPlanner(Planner):
    """R* (randomized A*, Likhachev & Stentz 2008) on the grid, bounded by ``w`` x optimal."""

    name = "rstar"
    spaces = ("voxel",)

    def __init__(self, world: World, *, w: float = 1.5, delta: int = 8, k: int = 8,
                 local_expansions: int = 500, max_expansions: int = 100, seed: int = 0,
                 enforce_bound: bool = True) -> None:
        super().__init__(world)
        if not w >= 1.0:
            raise ValueError(f"w (the suboptimality bound) must be >= 1, got {w!r}")
        if min(int(delta), int(k), int(local_expansions), int(max_expansions)) < 1:
            raise ValueError("delta, k, local_expansions and max_expansions must be >= 1")
        self.w = float(w)
        self.delta = int(delta)
        self.k = int(k)
        self.local_expansions = int(local_expansions)
        self.max_expansions = int(max_expansions)
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
            raise ValueError(f"seed must be an integer in [0, 2^63), got {seed!r}")
        self.seed = int(seed)
        self.enforce_bound = bool(enforce_bound)
        # (flies, goal) -> {start cell: (metres, cells) or None}
        self._cache = GoalCache(lambda key: {})
        for name in ("searches", "high_expansions", "local_expansions", "avoid_labels",
                     "certified", "bound_fallbacks"):
            self.stats.extra.setdefault(name, 0)

    def _answer(self, start: Cell, goal: Cell, flies: bool, task_id: int | None):
        per_goal = self._cache.get((flies, goal), task_id)
        if start not in per_goal:
            grid = self.world.grid
            shape = lattice(grid, flies)
            if not (on_lattice(grid, start, flies) and on_lattice(grid, goal, flies)):
                per_goal[start] = None
            else:
                labels = components(grid, flies)
                if labels[flat_index(shape, start)] != labels[flat_index(shape, goal)]:
                    per_goal[start] = None
                else:
                    self.stats.extra["searches"] += 1
                    res = _Query(self, start, goal, flies).run()
                    per_goal[start] = None if res is None else (res[0] * grid.cell, res[1])
        return per_goal[start]

    def costs(self, agents: tuple[AgentView, ...], tasks: tuple[TaskView, ...]) -> np.ndarray:
        """``(len(agents), len(tasks))`` travel seconds along R* paths (see module)."""
        self.stats.cost_queries += 1
        grid = self.world.grid
        out = np.full((len(agents), len(tasks)), np.inf)
        for t, task in enumerate(tasks):
            goal = tuple(int(v) for v in task.cell)
            for a, agent in enumerate(agents):
                flies = agent.flies
                if not flies and (task.kind != "ground" or goal[2] != 0):
                    continue
                if not (on_lattice(grid, agent.cell, flies) and on_lattice(grid, goal, flies)):
                    continue
                hit = self._answer(tuple(int(v) for v in agent.cell), goal, flies, task.id)
                if hit is not None:
                    out[a, t] = hit[0] / agent.speed
        return out

    def plan(self, agent: AgentView, goal: Cell) -> list[Cell] | None:
        """The R* path from ``agent.cell`` to ``goal`` (the one costed, if any), or None."""
        self.stats.plans += 1
        grid, flies = self.world.grid, agent.flies
        goal = tuple(int(v) for v in goal)
        start = tuple(int(v) for v in agent.cell)
        if not (on_lattice(grid, start, flies) and on_lattice(grid, goal, flies)):
            return None
        hit = self._answer(start, goal, flies, None)
        return None if hit is None else list(hit[1])

    def task_closed(self, task_id: int) -> None:
        """Forget the task's cached answers unless another open task shares its goal cell."""
        self._cache.task_closed(task_id)
