"""Grid graphs, distance fields and a single-pair A* for the two movement models.

The movement rules are those of :mod:`dispatch.api.motion` (not redefined here):

* **UAV** (``flies=True``): 26-connected over every cell of the grid. Node ``n`` is the C-order
  flat index of cell ``(i, j, k)`` in ``grid.shape`` (``np.ravel_multi_index``).
* **UGV** (``flies=False``): 8-connected over the ground layer ``k = 0`` only. Node ``n`` is the
  C-order flat index of ``(i, j)`` in ``grid.shape[:2]``; the cell is ``(i, j, 0)``.

A step is an edge only if every cell of its bounding box is free (the MovingAI no-corner-cutting
rule, :func:`dispatch.api.motion.step_is_legal`); blocked cells have no edges at all. Edge weights
are in **metres** (step length in cells times ``grid.cell``). Both graphs are symmetric.

The graph is implicit: a per-node bit mask of legal steps (``GridGraph.dirs``, vectorized with
numpy) plus the index delta and weight of each step. The searches are compiled
(:mod:`planners._fast`, numba): distance fields by an exact Dijkstra with one FIFO per step
length (several fields at once on threads), single pairs by A* with a radix heap. An explicit
``scipy.sparse`` adjacency (``GridGraph.csr``) is built only on request, for references and
other tools.

Everything here depends only on the immutable :class:`~dispatch.api.voxels.Grid`, so it is cached
on ``grid.cache``: the graphs (built once per grid and model) and a :class:`FieldCache` of
distance fields that owns them, bounded in bytes (the cost path reads fields in place and
never keeps one, see :func:`field_values`).
"""

from __future__ import annotations

import math
import os
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache, cached_property, partial

import numpy as np
from scipy.sparse import csr_matrix

from dispatch.api.motion import offsets
from dispatch.api.voxels import Grid
from dispatch.locations import Cell
from planners import _fast

#: Most distance fields kept per grid (both movement models together).
FIELD_CACHE_MAX_FIELDS = 4096
#: Default bound of a grid's field cache in bytes (a 50x50x30 field is 600 kB, a 200x200x30
#: one 9.6 MB); the ``astar`` planner's ``field_cache_mb`` sets it per run.
FIELD_CACHE_MAX_BYTES = 256 * 2**20
#: Largest node lattice for which :func:`astar` builds (and caches) the per-node move masks;
#: beyond it (e.g. the 89-million-voxel MovingAI 3D maps) A* reads moves from the occupancy.
MASK_MAX_NODES = 1 << 23
#: Largest lattice whose A* scratch arrays (13 bytes a node) are kept between searches.
SCRATCH_MAX_NODES = 1 << 22
#: Threads that compute several distance fields at once (1: never in parallel).
FIELD_THREADS = max(1, min(4, os.cpu_count() or 1))
#: Smallest lattice whose fields are worth a thread each (a 50x50 ground layer is not).
PARALLEL_MIN_NODES = 20_000

_GRAPH_KEY = "planners.graph.graph"
_FIELDS_KEY = "planners.graph.fields"
_PADDED_KEY = "planners.graph.padded"
_SCRATCH_KEY = "planners.graph.astar_scratch"
_LABELS_KEY = "planners.graph.components"
#: Lattice bounds are scaled by this so that float rounding never lifts one above the exact
#: shortest-path length (a path's float sum is within ~1e-14 relative of its real length).
BOUND_SCALE = 1.0 - 1e-12


def _lattice(grid: Grid, flies: bool) -> tuple[int, int, int]:
    nx, ny, nz = grid.shape
    return (nx, ny, nz) if flies else (nx, ny, 1)


def _steps(shape3: tuple[int, int, int], flies: bool):
    """Per move ``b`` of ``offsets(flies)``: index delta in ``shape3``, number of axes moved."""
    strides = (shape3[1] * shape3[2], shape3[2], 1)
    offs = offsets(flies)
    deltas = np.array([sum(s * v for s, v in zip(strides, d)) for d in offs], dtype=np.int64)
    axes = np.array([sum(map(abs, d)) for d in offs], dtype=np.int64)
    return deltas, axes


@dataclass(frozen=True, eq=False)
class GridGraph:
    """One movement model's graph over a grid.

    ``shape`` is the node lattice (``grid.shape`` for UAVs, ``grid.shape[:2]`` for UGVs); node
    ``n`` is the C-order flat index in it. ``dirs`` is a per-node bit mask of legal steps, bit
    ``b`` for ``offsets(flies)[b]``; ``deltas[b]`` is that step's node-index delta and
    ``weights[b]`` its length in metres. ``csr`` is the same graph as a symmetric ``(n, n)``
    scipy adjacency in metres, built on first use.
    """

    flies: bool
    shape: tuple[int, ...]
    cell: float
    dirs: np.ndarray
    deltas: np.ndarray
    axes: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(np.prod(self.shape))

    @cached_property
    def steps(self) -> np.ndarray:
        """Length of each move in cells (1, sqrt 2 or sqrt 3)."""
        return np.sqrt(self.axes.astype(np.float64))

    @property
    def weights(self) -> np.ndarray:
        """Length of each move in metres."""
        return self.cell * self.steps

    @cached_property
    def csr(self) -> csr_matrix:
        rows, cols, weights = [], [], []
        for b, delta in enumerate(self.deltas.tolist()):
            nodes = np.flatnonzero(self.dirs & np.int32(1 << b))
            rows.append(nodes)
            cols.append(nodes + delta)
            weights.append(np.full(nodes.size, self.cell * math.sqrt(int(self.axes[b]))))
        n = self.n_nodes
        m = csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n, n))
        m.sort_indices()
        return m

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
    dirs = np.zeros(shape3, dtype=np.int32)
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
    deltas, axes = _steps(shape3, flies)
    dirs = dirs.reshape(-1)
    dirs.setflags(write=False)
    shape = shape3 if flies else shape3[:2]
    return GridGraph(flies=flies, shape=tuple(int(s) for s in shape), cell=float(grid.cell),
                     dirs=dirs, deltas=deltas, axes=axes)


def graph(grid: Grid, flies: bool) -> GridGraph:
    """The (cached) graph of one movement model over ``grid``; see :class:`GridGraph`."""
    graphs = grid.cache.setdefault(_GRAPH_KEY, {})
    g = graphs.get(bool(flies))
    if g is None:
        g = graphs[bool(flies)] = _build(grid, bool(flies))
    return g


def components(grid: Grid, flies: bool) -> np.ndarray:
    """Per node of the model's lattice (flat, see :class:`GridGraph`), the label of its
    connected component of the movement graph (int64, read-only); ``-1`` for blocked nodes.
    Two free nodes are joined by a legal path iff their labels are equal (the graph is
    symmetric). Computed once per grid and model by a compiled flood fill over the move masks
    (:func:`planners._fast.flood_components`: no adjacency matrix is built), cached."""
    per = grid.cache.setdefault(_LABELS_KEY, {})
    labels = per.get(bool(flies))
    if labels is None:
        g = graph(grid, flies)
        occ = grid.occupied if flies else grid.occupied[:, :, :1]
        labels = np.where(occ.reshape(-1), -1, -2).astype(np.int64)
        _fast.flood_components(g.dirs, g.deltas, labels, np.empty(labels.size, np.int64))
        labels.setflags(write=False)
        per[bool(flies)] = labels
    return labels


def lattice_bound(a: np.ndarray, b: np.ndarray, cell: float) -> np.ndarray:
    """``out[i, j]``: a lower bound in metres of the shortest 26-connected path from cell
    ``a[i]`` to cell ``b[j]`` (``(N, 3)`` and ``(M, 3)`` integer arrays): the obstacle-free
    lattice distance (sorted absolute offsets ``p >= q >= r``: ``sqrt3 r + sqrt2 (q - r) +
    (p - q)`` cells) times ``cell`` times :data:`BOUND_SCALE`. It is never above the exact
    length (every legal path is a lattice path), and 0 only for equal cells."""
    d = np.abs(a[:, None, :].astype(np.int64) - b[None, :, :].astype(np.int64))
    d.sort(axis=2)
    r, q, p = d[..., 0], d[..., 1], d[..., 2]
    return (math.sqrt(3) * r + math.sqrt(2) * (q - r) + (p - q)) * (cell * BOUND_SCALE)


_SCRATCH = threading.local()
_NO_U8 = np.zeros(0, dtype=np.uint8)
_POOL: dict = {}  # pid -> ThreadPoolExecutor (a forked child must not reuse its parent's)
_POOL_LOCK = threading.Lock()


def _wmove(g: GridGraph) -> np.ndarray:
    """Length of each move in metres, exactly as the Dijkstra kernel adds it."""
    wvalue = g.cell * np.sqrt(np.arange(1.0, 4.0))  # weight classes: moves along 1, 2, 3 axes
    return wvalue[g.axes - 1]


def _field(g: GridGraph, node: int, parents: bool = False, targets: np.ndarray | None = None):
    """A Dijkstra field (metres, flat) from ``node`` over ``g``, compiled; with ``parents``,
    ``(field, parent codes, radius)`` (see :func:`planners._fast.dijkstra_field`). With
    ``targets`` (distinct node indices) the search stops once they are all settled: only
    values ``<= radius`` are then final."""
    n = g.n_nodes
    scratch = getattr(_SCRATCH, "queues", None)
    if scratch is None or scratch[0].shape[1] < n:
        scratch = _SCRATCH.queues = (np.empty((3, n), np.int32), np.empty((3, n)),
                                     np.zeros(n, np.uint8))
    qn, qk, mark = scratch
    wvalue = g.cell * np.sqrt(np.arange(1.0, 4.0))
    dist = np.empty(n)
    parent = np.empty(n, np.uint8) if parents else _NO_U8
    k = 0 if targets is None else targets.size
    if k:
        mark[targets] = 1
    try:
        radius = _fast.dijkstra_field(g.dirs, g.deltas, g.axes - 1, wvalue, node, dist, qn, qk,
                                      parent, mark, k)
    finally:
        if k:
            mark[targets] = 0
    return (dist, parent, radius) if parents else dist


def _pool() -> ThreadPoolExecutor | None:
    if FIELD_THREADS < 2:
        return None
    with _POOL_LOCK:
        pool = _POOL.get(os.getpid())
        if pool is None:
            _POOL.clear()
            pool = _POOL[os.getpid()] = ThreadPoolExecutor(FIELD_THREADS,
                                                           thread_name_prefix="fields")
        return pool


class FieldCache:
    """The distance fields of one grid, owned here and bounded in bytes.

    Promises: the fields it holds never take more than ``max_bytes`` together (a field larger
    than the bound is not kept at all); the least recently used field goes first; nothing
    outside this module keeps a reference to a field it holds, except the arrays that
    :func:`distance_field` / :func:`distance_fields` hand to their callers (read-only), which
    live as long as the caller keeps them. The cost path (:func:`field_values`) never hands a
    field out: it reads the values it needs and lets go, so with it the bound holds for the
    whole process. An evicted field is recomputed on the next request, identically (Dijkstra's
    float64 distances are the unique fixed point of the relaxations, whatever the order).
    """

    def __init__(self, max_bytes: int) -> None:
        self._lru: OrderedDict = OrderedDict()
        self.nbytes = 0
        self.max_bytes = int(max_bytes)
        self.hits = 0
        self.misses = 0
        self.evictions = 0

    def __len__(self) -> int:
        return len(self._lru)

    def __contains__(self, key) -> bool:
        return key in self._lru

    def lru_keys(self) -> list:
        """The keys, least recently used first."""
        return list(self._lru)

    def peek(self, key):
        """The entry under ``key`` or None, without counting a hit or a miss or making it
        the most recently used."""
        return self._lru.get(key)

    def get(self, key) -> np.ndarray | None:
        """The field under ``key`` (made the most recently used), or None."""
        f = self._lru.get(key)
        if f is None:
            self.misses += 1
            return None
        self._lru.move_to_end(key)
        self.hits += 1
        return f

    def put(self, key, field: np.ndarray) -> None:
        """Keep ``field`` under ``key``, evicting the least recently used fields first so that
        the bound holds; a field larger than the bound is not kept."""
        old = self._lru.pop(key, None)
        if old is not None:
            self.nbytes -= old.nbytes
        if field.nbytes > self.max_bytes:
            return
        self._shrink(self.max_bytes - field.nbytes, FIELD_CACHE_MAX_FIELDS - 1)
        self._lru[key] = field
        self.nbytes += field.nbytes

    def resize(self, max_bytes: int) -> None:
        """Set a new bound, evicting at once what no longer fits."""
        self.max_bytes = int(max_bytes)
        self._shrink(self.max_bytes, FIELD_CACHE_MAX_FIELDS)

    def _shrink(self, room: int, slots: int) -> None:
        """Evict until the fields take at most ``room`` bytes in at most ``slots`` entries."""
        while self._lru and (self.nbytes > room or len(self._lru) > slots):
            _, old = self._lru.popitem(last=False)
            self.nbytes -= old.nbytes
            self.evictions += 1


def field_cache(grid: Grid) -> FieldCache:
    """The grid's field cache (created with :data:`FIELD_CACHE_MAX_BYTES` on first use)."""
    cache = grid.cache.get(_FIELDS_KEY)
    if cache is None:
        cache = grid.cache[_FIELDS_KEY] = FieldCache(FIELD_CACHE_MAX_BYTES)
    return cache


def _goal_nodes(grid: Grid, g: GridGraph, goal_cells, flies: bool) -> list[int]:
    nodes = []
    for c in goal_cells:
        node = g.node(c)
        if node is None:
            on_grid = grid.in_bounds(c)
            where = "off the ground layer" if not flies and on_grid else "out of bounds"
            raise ValueError(f"goal cell {tuple(c)} is {where} for a "
                             f"{'UAV' if flies else 'UGV'} distance field")
        nodes.append(node)
    return nodes


def _compute(grid: Grid, g: GridGraph, nodes: list[int], parents: bool = False,
             targets: np.ndarray | None = None) -> list:
    """Fresh fields (flat, float64) from ``nodes``, on threads when they pay; with
    ``parents``, ``(field, parent codes, radius)`` triples (bounded by ``targets``)."""
    todo = [n for n in nodes if not grid.occupied[g.cell_of(n)]]
    pool = _pool() if len(todo) > 1 and g.n_nodes >= PARALLEL_MIN_NODES else None
    compute = partial(_field, g, parents=parents, targets=targets)
    done = dict(zip(todo, pool.map(compute, todo) if pool else map(compute, todo)))
    out = []
    for n in nodes:
        if n in done:
            out.append(done[n])
        else:  # a blocked goal: nothing reaches it
            inf = np.full(g.n_nodes, np.inf)
            tree = np.full(g.n_nodes, _fast.UNREACHED, np.uint8)
            out.append((inf, tree, math.inf) if parents else inf)
    return out


def distance_fields(grid: Grid, goal_cells, flies: bool) -> list[np.ndarray]:
    """:func:`distance_field` for several goals at once: ``[field of each goal]``.

    The fields not cached yet are computed together, on up to :data:`FIELD_THREADS` threads
    (the compiled kernel releases the GIL) when the lattice is large enough to pay for it.
    The returned arrays are the cached ones when they fit the cache's bound (see
    :class:`FieldCache`); a caller that keeps them keeps their memory.
    """
    flies = bool(flies)
    g = graph(grid, flies)
    nodes = _goal_nodes(grid, g, goal_cells, flies)
    cache = field_cache(grid)
    have = {n: cache.get(("field", flies, n)) for n in dict.fromkeys(nodes)}
    missing = [n for n, f in have.items() if f is None]
    for n, field in zip(missing, _compute(grid, g, missing)):
        field = field.reshape(g.shape)
        field.setflags(write=False)
        have[n] = field
        cache.put(("field", flies, n), field)
    return [have[n] for n in nodes]


@dataclass(frozen=True, eq=False)
class _Tree:
    """A goal's Dijkstra tree as :func:`field_values` caches it: parent codes (one byte a
    node) of a search that stopped at ``radius`` (``inf``: complete); values above it are
    unknown."""

    parent: np.ndarray
    radius: float

    @property
    def nbytes(self) -> int:
        return self.parent.nbytes


def field_values(grid: Grid, goal_cells, flies: bool, at: np.ndarray,
                 bounded: bool = False) -> tuple[np.ndarray, int]:
    """``out[a, t]``: the distance field of ``goal_cells[t]`` read at node ``at[a]`` (metres).

    Nodes are flat indices in the model's lattice (:class:`GridGraph`). Bit for bit
    ``distance_field(grid, goal_cells[t], flies).reshape(-1)[at]``, but no field leaves the
    cache, and what the cache keeps of a goal is its Dijkstra tree, one byte a node (the parent
    move of each node, an eighth of a float64 field): a value is rebuilt by summing the moves
    from the goal out along the tree, the very additions Dijkstra made
    (:func:`planners._fast.chain_values`). With ``bounded``, a new tree's search stops once
    every node of ``at`` is settled (a few idle vehicles near a task need a small part of the
    grid); a later call that needs a node beyond where it stopped searches again, to the end.
    Off by default: with 200 vehicles at 5 tasks/s on the paper's world the idle vehicles are
    spread everywhere (99.5 % of the grid settled anyway) and the searches repeated for
    vehicles that turned idle beyond the radius cost more (5141 searches against 4690).
    Missing trees are
    computed a few at a time (:data:`FIELD_THREADS` together), read, and handed to the cache,
    so the memory held stays within the cache's bound plus one batch of fields. Returns
    ``(values, computed)``: the array and how many Dijkstra searches ran.
    """
    flies = bool(flies)
    g = graph(grid, flies)
    at = np.asarray(at, dtype=np.int64).reshape(-1)
    nodes = _goal_nodes(grid, g, goal_cells, flies)
    out = np.empty((at.size, len(nodes)))
    cache = field_cache(grid)
    cols: dict[int, list[int]] = {}
    for t, n in enumerate(nodes):
        cols.setdefault(n, []).append(t)
    fresh, extend = [], []
    wmove = None
    col = np.empty(at.size)
    for n, ts in cols.items():
        tree = cache.get(("tree", flies, n))
        if tree is None:
            fresh.append(n)
            continue
        if wmove is None:
            wmove = _wmove(g)
        _fast.chain_values(tree.parent, g.deltas, wmove, at, col)
        if tree.radius == math.inf or (col <= tree.radius).all():
            out[:, ts] = col[:, None]
        else:
            extend.append(n)
    batch = max(1, FIELD_THREADS)
    # a new goal's search stops at the nodes asked for; one asked beyond that gets a complete
    # tree (so no goal is searched more than twice while its tree stays cached)
    for missing, targets in ((fresh, np.unique(at) if bounded else None), (extend, None)):
        for i in range(0, len(missing), batch):
            chunk = missing[i : i + batch]
            for n, (field, parent, radius) in zip(chunk, _compute(grid, g, chunk, True, targets)):
                out[:, cols[n]] = field[at][:, None]
                parent.setflags(write=False)
                cache.put(("tree", flies, n), _Tree(parent, float(radius)))
    return out, len(fresh) + len(extend)


def distance_field(grid: Grid, goal_cell: Cell, flies: bool) -> np.ndarray:
    """Shortest-path metres from every node to ``goal_cell`` (read-only, cached).

    Shape ``grid.shape`` for UAVs (``flies=True``) and ``grid.shape[:2]`` for UGVs — the ground
    layer only, indexed ``[i, j]`` for cell ``(i, j, 0)``. ``inf`` where the goal cannot be
    reached, everywhere if the goal cell is blocked. Raises ``ValueError`` if the goal is out of
    bounds or, for UGVs, not on the ground layer. The graph is symmetric, so one Dijkstra run
    from the goal gives the distances to it (exact: the same float64 relaxations as
    ``scipy.sparse.csgraph.dijkstra`` on :attr:`GridGraph.csr`, bit for bit: both reach the
    unique fixed point of ``d[v] = min over u of fl(d[u] + w(u, v))``). Fields are kept in the
    grid's :class:`FieldCache` (a byte bound, least recently used evicted first).
    """
    return distance_fields(grid, (goal_cell,), flies)[0]


# ----------------------------------------------------------------------------- A*

_NO_DIRS = np.zeros(0, dtype=np.int32)
_NO_DIRS.setflags(write=False)  # the same kernel signature as a cached (read-only) mask
_NO_OCC = np.zeros(0, dtype=np.uint8)
_NO_I64 = np.zeros(0, dtype=np.int64)


def _padded(grid: Grid, flies: bool):
    """Tables for A* without move masks: the occupancy padded by one blocked cell on each side
    (uint8, the UGV's ground layer alone in the middle of three layers), its shape, the move
    deltas, the neighbourhood offsets and, per move, the neighbourhood bits it needs free."""
    per = grid.cache.setdefault(_PADDED_KEY, {})
    hit = per.get(bool(flies))
    if hit is not None:
        return hit
    nx, ny, nz = _lattice(grid, flies)
    occ = np.ones((nx + 2, ny + 2, nz + 2), dtype=np.uint8)
    occ[1:-1, 1:-1, 1:-1] = grid.occupied[:, :, :nz]
    shape3 = occ.shape
    strides = (shape3[1] * shape3[2], shape3[2], 1)
    deltas, axes = _steps(shape3, flies)
    hood = [d for d in offsets(flies)]  # the neighbourhood cells a move may cover
    bit = {d: q for q, d in enumerate(hood)}
    nbr = np.array([sum(s * v for s, v in zip(strides, d)) for d in hood], dtype=np.int64)
    req = np.zeros(len(deltas), dtype=np.int64)
    for b, d in enumerate(offsets(flies)):
        moving = [a for a in range(3) if d[a] != 0]
        for mask in range(1, 1 << len(moving)):
            e = [0, 0, 0]
            for t, a in enumerate(moving):
                if mask >> t & 1:
                    e[a] = d[a]
            req[b] |= 1 << bit[tuple(e)]
    wstep = np.sqrt(axes.astype(np.float64))
    hit = per[bool(flies)] = (occ.reshape(-1), shape3, deltas, wstep, nbr, req)
    return hit


def _scratch(grid: Grid, flies: bool, n: int):
    """A* scratch ``(seen, gen, g, parent)`` for ``n`` nodes. Up to :data:`SCRATCH_MAX_NODES`
    the arrays are kept per grid, model and thread and reused with a new generation number
    (no allocation, no zeroing, no page faults); beyond, fresh lazily zeroed arrays."""
    if n > SCRATCH_MAX_NODES:
        return (np.zeros(n, np.uint32), np.uint32(1), np.zeros(n, np.float64),
                np.zeros(n, np.uint8))
    per = grid.cache.setdefault(_SCRATCH_KEY, {})
    key = (bool(flies), threading.get_ident())
    hit = per.get(key)
    if hit is None or hit[1] == 0xFFFFFFFF:
        hit = [np.zeros(n, np.uint32), 0, np.empty(n, np.float64), np.empty(n, np.uint8)]
        per[key] = hit
    hit[1] += 1
    return hit[0], np.uint32(hit[1]), hit[2], hit[3]


def astar(grid: Grid, start: Cell, goal: Cell, flies: bool,
          path: bool = True) -> tuple[float, list[Cell] | None]:
    """A* from ``start`` to ``goal`` under one movement model: ``(metres, cells)``.

    Returns the shortest path length in metres and the path as cells from ``start`` to
    ``goal``, both included (``(0.0, [start])`` when they are equal), or ``(inf, None)`` when
    either cell is blocked, out of bounds, off the ground layer for a UGV, or no path exists.
    The heuristic is the octile distance of :func:`dispatch.api.motion.octile` (consistent), ties
    in ``f`` go to the larger ``g``; the path is optimal (equal to the distance field up to
    float rounding). Compiled (:func:`planners._fast.astar`); on lattices larger than
    :data:`MASK_MAX_NODES` whose move masks are not cached yet, moves are read from a padded
    copy of the occupancy instead of building the masks. With ``path=False`` only the length
    is wanted: the cells are not returned (None).
    """
    nx, ny, nz = _lattice(grid, flies)
    s3 = tuple(int(v) for v in start)
    t3 = tuple(int(v) for v in goal)
    if len(s3) != 3 or len(t3) != 3:
        raise ValueError(f"a cell has three indices, got {start!r} and {goal!r}")
    occupied = grid.occupied
    for i, j, k in (s3, t3):
        if not (0 <= i < nx and 0 <= j < ny and 0 <= k < nz) or occupied[i, j, k]:
            return math.inf, None
    if s3 == t3:
        return 0.0, [s3]
    g = grid.cache.get(_GRAPH_KEY, {}).get(bool(flies))
    if g is not None or nx * ny * nz <= MASK_MAX_NODES:
        g = g or graph(grid, flies)
        dirs, occ, nbr, req, deltas, wstep = g.dirs, _NO_OCC, _NO_I64, _NO_I64, g.deltas, g.steps
        pad = 0
    else:
        occ, (nx, ny, nz), deltas, wstep, nbr, req = _padded(grid, flies)
        dirs, pad = _NO_DIRS, 1
    shape3 = np.array((nx, ny, nz), dtype=np.int64)
    sn = ((s3[0] + pad) * ny + s3[1] + pad) * nz + s3[2] + pad
    tn = ((t3[0] + pad) * ny + t3[1] + pad) * nz + t3[2] + pad
    seen, gen, gbuf, pbuf = _scratch(grid, flies, nx * ny * nz)
    length, cells = _fast.astar(dirs, occ, nbr, req, deltas, _move_coords(flies), wstep, shape3,
                                pad, sn, tn, seen, gen, gbuf, pbuf)
    if cells.shape[0] == 0:
        return math.inf, None
    return float(length) * grid.cell, list(map(tuple, cells.tolist())) if path else None


@cache
def _move_coords(flies: bool) -> np.ndarray:
    """``(di, dj, dk)`` of each move of ``offsets(flies)``, aligned with the move deltas."""
    out = np.array(offsets(flies), dtype=np.int64).reshape(-1, 3)
    out.setflags(write=False)
    return out


def _warm_up() -> None:
    """Load (or, the first time on a machine, compile) the kernels now, at import, with the
    argument types of real calls: a run's first decision must not pay for numba."""
    grid = Grid(np.zeros((3, 3, 2), dtype=bool), 1.0)
    distance_field(grid, (0, 0, 0), True)
    for _ in range(2):  # a Dijkstra tree, then values rebuilt from it
        field_values(grid, [(0, 0, 0)], True, np.array([17]))
    grid.cache.clear()
    astar(grid, (0, 0, 0), (2, 2, 1), True)
    components(grid, True)


_warm_up()
