"""Grid graphs, distance fields and a single-pair A* for the two movement models.

The movement rules are those of :mod:`dispatch.motion` (not redefined here):

* **UAV** (``flies=True``): 26-connected over every cell of the grid. Node ``n`` is the C-order
  flat index of cell ``(i, j, k)`` in ``grid.shape`` (``np.ravel_multi_index``).
* **UGV** (``flies=False``): 8-connected over the ground layer ``k = 0`` only. Node ``n`` is the
  C-order flat index of ``(i, j)`` in ``grid.shape[:2]``; the cell is ``(i, j, 0)``.

A step is an edge only if every cell of its bounding box is free (the MovingAI no-corner-cutting
rule, :func:`dispatch.motion.step_is_legal`); blocked cells have no edges at all. Edge weights
are in **metres** (step length in cells times ``grid.cell``). Both graphs are symmetric.

Everything here depends only on the immutable :class:`~dispatch.world.Grid`, so it is cached
on ``grid.cache``: the graphs (built once per grid and model, vectorized with numpy) and an LRU
of distance fields bounded both in count and in bytes.
"""

from __future__ import annotations

import heapq
import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from dispatch.motion import offsets
from dispatch.world import Cell, Grid

#: Most distance fields kept per grid (both movement models together).
FIELD_CACHE_MAX_FIELDS = 4096
#: Most bytes of distance fields kept per grid (a 50x50x30 field is 600 kB).
FIELD_CACHE_MAX_BYTES = 512 * 2**20

_GRAPH_KEY = "planners.graph.graph"
_FIELDS_KEY = "planners.graph.fields"

_C2 = math.sqrt(2.0) - 1.0
_C3 = math.sqrt(3.0) - math.sqrt(2.0)


@dataclass(frozen=True, eq=False)
class GridGraph:
    """One movement model's graph over a grid.

    ``csr`` is the symmetric ``(n, n)`` adjacency in metres. ``shape`` is the node lattice
    (``grid.shape`` for UAVs, ``grid.shape[:2]`` for UGVs); node ``n`` is the C-order flat index
    in it. ``dirs`` is a per-node bit mask of legal steps, bit ``b`` for ``offsets(flies)[b]``
    (the same legality as ``csr``, kept for the A* neighbour tables).
    """

    flies: bool
    shape: tuple[int, ...]
    cell: float
    csr: csr_matrix
    dirs: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.shape))

    def node(self, c: Cell) -> int | None:
        """The node of cell ``c``, or None if it is out of bounds or off this model's layer."""
        c = tuple(int(v) for v in c)
        if len(c) != 3:
            raise ValueError(f"a cell has three indices, got {c!r}")
        if not self.flies:
            if c[2] != 0:
                return None
            c = c[:2]
        if any(not 0 <= v < s for v, s in zip(c, self.shape)):
            return None
        return int(np.ravel_multi_index(c, self.shape))

    def cell_of(self, n: int) -> Cell:
        """The cell ``(i, j, k)`` of node ``n``."""
        idx = tuple(int(v) for v in np.unravel_index(int(n), self.shape))
        return idx if self.flies else (idx[0], idx[1], 0)  # type: ignore[return-value]


def _build(grid: Grid, flies: bool) -> GridGraph:
    occ = grid.occupied if flies else grid.occupied[:, :, :1]
    free = ~occ
    shape3 = occ.shape
    shape = shape3 if flies else shape3[:2]
    n = int(np.prod(shape3))
    flat = np.arange(n, dtype=np.int64).reshape(shape3)
    strides = np.array([shape3[1] * shape3[2], shape3[2], 1], dtype=np.int64)
    dirs = np.zeros(shape3, dtype=np.int32)
    rows, cols, weights = [], [], []
    for b, d in enumerate(offsets(flies)):
        if any(s == 1 and v != 0 for s, v in zip(shape3, d)):
            continue  # no room for this step along a flat axis
        src = tuple(
            slice(0, s - 1) if v > 0 else slice(1, s) if v < 0 else slice(None)
            for s, v in zip(shape3, d)
        )
        legal = free[src].copy()
        # every cell of the step's bounding box: a + e, e_a in {0, d_a}
        moving = [a for a in range(3) if d[a] != 0]
        for mask in range(1, 1 << len(moving)):
            sl = list(src)
            for bit, a in enumerate(moving):
                if mask >> bit & 1:
                    s = shape3[a]
                    sl[a] = slice(1, s) if d[a] > 0 else slice(0, s - 1)
            legal &= free[tuple(sl)]
        dirs[src][legal] |= np.int32(1 << b)
        a_nodes = flat[src][legal]
        rows.append(a_nodes)
        cols.append(a_nodes + int(np.dot(strides, d)))
        weights.append(np.full(a_nodes.size, grid.cell * math.sqrt(len(moving))))
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    w = np.concatenate(weights) if weights else np.zeros(0)
    csr = csr_matrix((w, (r, c)), shape=(n, n))
    csr.sort_indices()
    return GridGraph(flies=flies, shape=tuple(int(s) for s in shape), cell=float(grid.cell),
                     csr=csr, dirs=dirs.reshape(-1))


def graph(grid: Grid, flies: bool) -> GridGraph:
    """The (cached) graph of one movement model over ``grid``; see :class:`GridGraph`."""
    graphs = grid.cache.setdefault(_GRAPH_KEY, {})
    g = graphs.get(bool(flies))
    if g is None:
        g = graphs[bool(flies)] = _build(grid, bool(flies))
    return g


def distance_field(grid: Grid, goal_cell: Cell, flies: bool) -> np.ndarray:
    """Shortest-path metres from every node to ``goal_cell`` (read-only, cached).

    Shape ``grid.shape`` for UAVs (``flies=True``) and ``grid.shape[:2]`` for UGVs — the ground
    layer only, indexed ``[i, j]`` for cell ``(i, j, 0)``. ``inf`` where the goal cannot be
    reached, everywhere if the goal cell is blocked. Raises ``ValueError`` if the goal is out of
    bounds or, for UGVs, not on the ground layer. The graph is symmetric, so one Dijkstra run
    from the goal gives the distances to it. Fields are kept in an LRU on ``grid.cache``
    (at most :data:`FIELD_CACHE_MAX_FIELDS` fields and :data:`FIELD_CACHE_MAX_BYTES` bytes).
    """
    g = graph(grid, flies)
    node = g.node(goal_cell)
    if node is None:
        on_grid = grid.in_bounds(goal_cell)
        where = "off the ground layer" if not flies and on_grid else "out of bounds"
        raise ValueError(f"goal cell {tuple(goal_cell)} is {where} for a "
                         f"{'UAV' if flies else 'UGV'} distance field")
    lru: OrderedDict = grid.cache.setdefault(_FIELDS_KEY, OrderedDict())
    key = (bool(flies), node)
    field = lru.get(key)
    if field is not None:
        lru.move_to_end(key)
        return field
    if grid.occupied[g.cell_of(node)]:
        field = np.full(g.shape, np.inf)
    else:
        field = dijkstra(g.csr, directed=True, indices=node).reshape(g.shape)
    field.setflags(write=False)
    lru[key] = field
    total = sum(f.nbytes for f in lru.values())
    while len(lru) > 1 and (len(lru) > FIELD_CACHE_MAX_FIELDS or total > FIELD_CACHE_MAX_BYTES):
        _, old = lru.popitem(last=False)
        total -= old.nbytes
    return field


def _moves(grid: Grid, flies: bool) -> list:
    """Per node, a shared tuple of ``(node_delta, step_cells)`` for its legal steps (cached)."""
    key = ("planners.graph.moves", bool(flies))
    moves = grid.cache.get(key)
    if moves is None:
        g = graph(grid, flies)
        shape3 = grid.shape if flies else (grid.shape[0], grid.shape[1], 1)
        strides = (shape3[1] * shape3[2], shape3[2], 1)
        offs = offsets(flies)
        uniq, inverse = np.unique(g.dirs, return_inverse=True)
        tables = np.empty(len(uniq), dtype=object)
        for u, m in enumerate(uniq.tolist()):
            tables[u] = tuple(
                (sum(s * v for s, v in zip(strides, d)), math.sqrt(sum(map(abs, d))))
                for b, d in enumerate(offs) if m >> b & 1
            )
        moves = grid.cache[key] = tables[inverse.reshape(-1)].tolist()
    return moves


def astar(grid: Grid, start: Cell, goal: Cell, flies: bool) -> tuple[float, list[Cell] | None]:
    """A* from ``start`` to ``goal`` under one movement model: ``(metres, cells)``.

    Returns the shortest path length in metres and the path as cells from ``start`` to
    ``goal``, both included (``(0.0, [start])`` when they are equal), or ``(inf, None)`` when
    either cell is blocked, out of bounds, off the ground layer for a UGV, or no path exists.
    The heuristic is the octile distance of :func:`dispatch.motion.octile` (consistent), ties
    in ``f`` go to the larger ``g``; the path is optimal (equal to the distance field up to
    float rounding).
    """
    g = graph(grid, flies)
    s, t = g.node(start), g.node(goal)
    if s is None or t is None:
        return math.inf, None
    if grid.occupied[g.cell_of(s)] or grid.occupied[g.cell_of(t)]:
        return math.inf, None
    if s == t:
        return 0.0, [g.cell_of(s)]
    moves = _moves(grid, flies)
    _, ny, nz = grid.shape if flies else (grid.shape[0], grid.shape[1], 1)
    syz = ny * nz
    gi, gr = divmod(t, syz)
    gj, gk = divmod(gr, nz)
    c2, c3 = _C2, _C3

    def h(n: int) -> float:
        i, r = divmod(n, syz)
        j, k = divmod(r, nz)
        a, b, c = abs(i - gi), abs(j - gj), abs(k - gk)
        if a < b:
            a, b = b, a
        if b < c:
            b, c = c, b
            if a < b:
                a, b = b, a
        return c3 * c + c2 * b + a

    inf = math.inf
    best = [inf] * g.n_nodes
    parent = {s: -1}
    best[s] = 0.0
    heap = [(h(s), -0.0, s)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        _, ng, n = pop(heap)
        gn = -ng
        if gn > best[n]:
            continue  # stale entry: n was reached more cheaply since it was pushed
        if n == t:
            break
        for dn, w in moves[n]:
            m = n + dn
            gm = gn + w
            if gm < best[m]:
                best[m] = gm
                parent[m] = n
                # h(m) inlined: octile distance in cells to the goal
                i, r = divmod(m, syz)
                j, k = divmod(r, nz)
                a, b, c = abs(i - gi), abs(j - gj), abs(k - gk)
                if a < b:
                    a, b = b, a
                if b < c:
                    b, c = c, b
                    if a < b:
                        a, b = b, a
                push(heap, (gm + c3 * c + c2 * b + a, ng - w, m))
    else:
        return inf, None
    path = []
    n = t
    while n != -1:
        path.append(n)
        n = parent[n]
    path.reverse()
    cells = []
    for n in path:
        i, r = divmod(n, syz)
        j, k = divmod(r, nz)
        cells.append((i, j, k))
    return best[t] * grid.cell, cells
