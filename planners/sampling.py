"""Helpers shared by the randomized planners (``rrt_star``, ``rstar``).

* :func:`legal_moves` — per cell, a bit mask of the legal steps of one movement model (the rule
  of :func:`dispatch.api.motion.step_is_legal`, vectorized), cached on ``grid.cache``.
* :func:`components` — connected components of the free cells under one movement model, cached:
  a query whose two cells lie in different components is answered ``inf`` without searching.
* :func:`segment_cells` — the cells a straight segment passes through (a 3-D supercover walk,
  consecutive cells share a face).
* :func:`snap_polyline` — a continuous path (metres) turned into a legal grid path: supercover
  walk of every segment, loops cut, runs of face steps merged into diagonal steps where the
  motion rules allow, and any illegal step repaired by a short local A*
  (:func:`planners.graph.astar`). The result always passes :func:`dispatch.api.motion.check_path`.
* :class:`RayWorld` — a private PyBullet DIRECT client holding the obstacle boxes inflated by a
  clearance, answering batched segment visibility queries with ``p.rayTestBatch``.

Everything here depends only on the immutable grid (and the world's boxes), never on a random
generator: the planners own their generators.
"""

from __future__ import annotations

import math
import weakref
from collections import OrderedDict

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from dispatch.api.motion import offsets
from dispatch.api.voxels import Box, Grid
from dispatch.locations import Cell
from dispatch.space.world import World

_MOVES_KEY = "planners.sampling.moves"
_COMPONENTS_KEY = "planners.sampling.components"
_BOXES_KEY = "planners.sampling.boxes"

#: Most rays one ``rayTestBatch`` call accepts (PyBullet's MAX_RAY_INTERSECTION_BATCH_SIZE).
RAY_BATCH = 16384


# ----------------------------------------------------------------------------- grid structure


def lattice(grid: Grid, flies: bool) -> tuple[int, int, int]:
    """The node lattice of a movement model: ``grid.shape``, or the ground layer ``(nx, ny, 1)``."""
    nx, ny, nz = grid.shape
    return (nx, ny, nz) if flies else (nx, ny, 1)


def legal_moves(grid: Grid, flies: bool) -> np.ndarray:
    """Per node of :func:`lattice` (C-order flat index), the bit mask of legal steps.

    Bit ``b`` is set when the step ``offsets(flies)[b]`` is legal from that cell (every cell of
    the step's bounding box free, both ends in bounds; see :mod:`dispatch.api.motion`). Blocked
    cells
    have no legal steps. Read-only, cached on ``grid.cache``.
    """
    per = grid.cache.setdefault(_MOVES_KEY, {})
    dirs = per.get(bool(flies))
    if dirs is not None:
        return dirs
    shape = lattice(grid, flies)
    free = ~(grid.occupied if flies else grid.occupied[:, :, :1])
    dirs = np.zeros(shape, dtype=np.int32)
    for b, d in enumerate(offsets(flies)):
        if any(s == 1 and v != 0 for s, v in zip(shape, d)):
            continue
        src = tuple(slice(0, s - 1) if v > 0 else slice(1, s) if v < 0 else slice(None)
                    for s, v in zip(shape, d))
        legal = free[src].copy()
        moving = [a for a in range(3) if d[a]]
        for mask in range(1, 1 << len(moving)):  # every other corner of the bounding box
            sl = list(src)
            for bit, a in enumerate(moving):
                if mask >> bit & 1:
                    sl[a] = slice(1, shape[a]) if d[a] > 0 else slice(0, shape[a] - 1)
            legal &= free[tuple(sl)]
        dirs[src][legal] |= np.int32(1 << b)
    dirs = dirs.reshape(-1)
    dirs.setflags(write=False)
    per[bool(flies)] = dirs
    return dirs


def flat_index(shape: tuple[int, int, int], c) -> int:
    return (int(c[0]) * shape[1] + int(c[1])) * shape[2] + int(c[2])


def unflat(shape: tuple[int, int, int], n: int) -> Cell:
    i, r = divmod(int(n), shape[1] * shape[2])
    j, k = divmod(r, shape[2])
    return (i, j, k)


def on_lattice(grid: Grid, c, flies: bool) -> bool:
    """In bounds, free, and (UGV) on the ground layer."""
    c = tuple(int(v) for v in c)
    return len(c) == 3 and grid.is_free(c) and (flies or c[2] == 0)


def components(grid: Grid, flies: bool) -> np.ndarray:
    """Component label per node of :func:`lattice` (C order); blocked cells get -1. Cached."""
    per = grid.cache.setdefault(_COMPONENTS_KEY, {})
    labels = per.get(bool(flies))
    if labels is not None:
        return labels
    shape = lattice(grid, flies)
    dirs = legal_moves(grid, flies)
    n = dirs.size
    strides = (shape[1] * shape[2], shape[2], 1)
    rows, cols = [], []
    for b, d in enumerate(offsets(flies)):
        src = np.flatnonzero(dirs & (1 << b))
        rows.append(src)
        cols.append(src + sum(s * v for s, v in zip(strides, d)))
    r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    adj = csr_matrix((np.ones(r.size, dtype=np.int8), (r, c)), shape=(n, n))
    _, labels = connected_components(adj, directed=False)
    labels = labels.astype(np.int64)
    blocked = (grid.occupied if flies else grid.occupied[:, :, :1]).reshape(-1)
    labels[blocked] = -1
    labels.setflags(write=False)
    per[bool(flies)] = labels
    return labels


def connected(grid: Grid, a, b, flies: bool) -> bool:
    """Whether a legal path joins cells ``a`` and ``b`` (both free and on the model's lattice)."""
    if not (on_lattice(grid, a, flies) and on_lattice(grid, b, flies)):
        return False
    labels = components(grid, flies)
    shape = lattice(grid, flies)
    return bool(labels[flat_index(shape, a)] == labels[flat_index(shape, b)])


# ----------------------------------------------------------------------------- snapping


def segment_cells(p, q) -> np.ndarray:
    """Cells (``(k, 3)`` int) a segment from ``p`` to ``q`` (in cell units) passes through.

    A supercover walk: the segment's boundary crossings sorted by their parameter, one axis per
    step (ties at edges and corners broken x, then y, then z), so consecutive cells share a face
    and every cell listed is touched by the closed segment.
    """
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    c0 = np.floor(p).astype(np.int64)
    c1 = np.floor(q).astype(np.int64)
    ts, axes, signs = [], [], []
    for a in range(3):
        if c1[a] > c0[a]:
            b = np.arange(c0[a] + 1, c1[a] + 1, dtype=float)
            sign = 1
        elif c1[a] < c0[a]:
            b = np.arange(c0[a], c1[a], -1, dtype=float)
            sign = -1
        else:
            continue
        ts.append((b - p[a]) / (q[a] - p[a]))
        axes.append(np.full(b.size, a))
        signs.append(np.full(b.size, sign))
    if not ts:
        return c0[None, :]
    t = np.concatenate(ts)
    ax = np.concatenate(axes)
    sg = np.concatenate(signs)
    order = np.lexsort((ax, t))
    moves = np.zeros((t.size + 1, 3), dtype=np.int64)
    moves[0] = c0
    moves[np.arange(1, t.size + 1), ax[order]] = sg[order]
    return np.cumsum(moves, axis=0)


def _remove_loops(cells: list[Cell]) -> list[Cell]:
    out: list[Cell] = []
    where: dict[Cell, int] = {}
    for c in cells:
        i = where.get(c)
        if i is not None:
            for dropped in out[i + 1:]:
                where.pop(dropped, None)
            del out[i + 1:]
            continue
        where[c] = len(out)
        out.append(c)
    return out


def snap_polyline(grid: Grid, points, flies: bool, stats: dict | None = None) -> list[Cell] | None:
    """A legal grid path along a polyline given in metres (see the module docstring).

    The first and last points' cells are the path's ends. Returns None only if those cells
    cannot be joined (blocked, off the model's lattice, or in different components).
    ``stats``, when given, counts local A* repairs under ``"snap_repairs"``.
    """
    from planners.graph import astar  # read-only use of the exact planner for repairs

    pts = np.asarray(points, dtype=float) / grid.cell
    if not flies:
        pts = pts.copy()
        pts[:, 2] = 0.5
    raw: list[Cell] = []
    for a, b in zip(pts[:-1], pts[1:]):
        seg = [tuple(int(v) for v in c) for c in segment_cells(a, b)]
        if raw and raw[-1] == seg[0]:
            seg = seg[1:]
        raw.extend(seg)
    if not raw:
        raw = [tuple(int(v) for v in np.floor(pts[0]))]
    start, goal = raw[0], raw[-1]
    if not connected(grid, start, goal, flies):
        return None
    cells = _remove_loops(raw)
    shape = lattice(grid, flies)
    dirs = legal_moves(grid, flies)
    bit = {d: 1 << b for b, d in enumerate(offsets(flies))}
    nx, ny, nz = shape
    occ = grid.occupied

    def legal(a: Cell, b: Cell) -> bool:
        d = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        m = bit.get(d)
        return m is not None and bool(dirs[(a[0] * ny + a[1]) * nz + a[2]] & m)

    def usable(c: Cell) -> bool:
        return (0 <= c[0] < nx and 0 <= c[1] < ny and 0 <= c[2] < nz and not occ[c])

    out = [start]
    i, n = 0, len(cells)
    while i < n - 1:
        a = cells[i]
        nxt = None
        for j in (i + 3, i + 2, i + 1):
            if j < n and legal(a, cells[j]):
                nxt = j
                break
        if nxt is not None:
            out.append(cells[nxt])
            i = nxt
            continue
        # repair: join a to the next usable cell of the walk with a local A*
        k = i + 1
        while k < n - 1 and not usable(cells[k]):
            k += 1
        if stats is not None:
            stats["snap_repairs"] = stats.get("snap_repairs", 0) + 1
        _, piece = astar(grid, a, cells[k], flies)
        if piece is None:  # cannot happen within one component; be safe: join to the goal
            _, piece = astar(grid, a, goal, flies)
            k = n - 1
            if piece is None:
                return None
        out.extend(piece[1:])
        i = k
    return _remove_loops(out) if len(set(out)) != len(out) else out


# ----------------------------------------------------------------------------- collision


def collision_boxes(world: World) -> tuple[Box, ...]:
    """The obstacle boxes to test rays against, in metres.

    ``world.boxes`` when they rasterize exactly to the grid's occupancy (worlds built by
    :func:`dispatch.space.world.build_world`); otherwise (a grid made by hand, boxes missing) boxes
    are rebuilt from the occupied voxels by a greedy merge (runs along z, then y, then x), so
    the collision geometry always equals the grid. Cached on ``grid.cache``.
    """
    grid = world.grid
    hit = grid.cache.get(_BOXES_KEY)
    if hit is not None and hit[0] == world.boxes:
        return hit[1]
    c = grid.cell
    raster = np.zeros(grid.shape, dtype=bool)
    for b in world.boxes:
        i0, j0, k0 = (int(round(v / c)) for v in (b.x0, b.y0, b.z0))
        i1, j1, k1 = (int(round(v / c)) for v in (b.x1, b.y1, b.z1))
        raster[max(i0, 0):i1, max(j0, 0):j1, max(k0, 0):k1] = True
    if np.array_equal(raster, grid.occupied):
        boxes = tuple(world.boxes)
    else:
        boxes = tuple(Box(i0 * c, j0 * c, k0 * c, i1 * c, j1 * c, k1 * c)
                      for i0, j0, k0, i1, j1, k1 in _voxel_boxes(grid.occupied))
    grid.cache[_BOXES_KEY] = (world.boxes, boxes)
    return boxes


def _voxel_boxes(occ: np.ndarray) -> list[tuple[int, int, int, int, int, int]]:
    """Cover the occupied voxels exactly with disjoint boxes (greedy; exclusive upper ends)."""
    left = occ.copy()
    nx, ny, nz = occ.shape
    out = []
    for i, j, k in np.argwhere(occ):
        if not left[i, j, k]:
            continue
        k1 = k + 1
        while k1 < nz and left[i, j, k1]:
            k1 += 1
        j1 = j + 1
        while j1 < ny and left[i, j1, k:k1].all():
            j1 += 1
        i1 = i + 1
        while i1 < nx and left[i1, j:j1, k:k1].all():
            i1 += 1
        left[i:i1, j:j1, k:k1] = False
        out.append((int(i), int(j), int(k), int(i1), int(j1), int(k1)))
    return out


def _disconnect(p, client: int) -> None:
    try:
        p.disconnect(physicsClientId=client)
    except Exception:  # noqa: BLE001 - interpreter shutdown, client already gone
        pass


class RayWorld:
    """Obstacle boxes inflated by ``clearance`` metres in a private PyBullet DIRECT client.

    :meth:`visible` answers many segment queries with one ``p.rayTestBatch`` call (chunked at
    :data:`RAY_BATCH` rays). :meth:`free` tests points against the same inflated boxes with
    numpy (a ray that starts inside a box reports no hit in Bullet, so segment ends are checked
    as points). Any clearance > 0 makes the cells a collision-free segment passes through free
    (boxes are unions of cells), which is what :func:`snap_polyline` relies on.
    """

    def __init__(self, world: World, clearance: float) -> None:
        from dispatch.space.physics import connect_direct, import_pybullet

        self.p = p = import_pybullet()
        self.client = connect_direct(p)
        self._finalizer = weakref.finalize(self, _disconnect, p, self.client)
        boxes = collision_boxes(world)
        r = float(clearance)
        self.lo = np.array([[b.x0 - r, b.y0 - r, b.z0 - r] for b in boxes]).reshape(-1, 3)
        self.hi = np.array([[b.x1 + r, b.y1 + r, b.z1 + r] for b in boxes]).reshape(-1, 3)
        self.rays = 0
        self.batches = 0
        for lo, hi in zip(self.lo, self.hi):
            he = tuple(float(v) for v in (hi - lo) / 2)
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=he, physicsClientId=self.client)
            p.createMultiBody(0, col, -1, basePosition=tuple(float(v) for v in (hi + lo) / 2),
                              physicsClientId=self.client)

    def free(self, points) -> np.ndarray:
        """Boolean per point (``(k, 3)`` metres): outside every inflated box."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if not len(self.lo):
            return np.ones(len(pts), dtype=bool)
        inside = ((pts[:, None, :] > self.lo[None]) & (pts[:, None, :] < self.hi[None])).all(2)
        return ~inside.any(axis=1)

    def visible(self, frm, to) -> np.ndarray:
        """Boolean per segment ``frm[i] -> to[i]`` (metres): no inflated box crossed."""
        frm = np.asarray(frm, dtype=float).reshape(-1, 3)
        to = np.asarray(to, dtype=float).reshape(-1, 3)
        out = np.ones(len(frm), dtype=bool)
        if not len(self.lo) or not len(frm):
            return out
        for s in range(0, len(frm), RAY_BATCH):
            hits = self.p.rayTestBatch(frm[s:s + RAY_BATCH], to[s:s + RAY_BATCH],
                                       numThreads=1, physicsClientId=self.client)
            out[s:s + len(hits)] = [h[0] < 0 for h in hits]
            self.batches += 1
        self.rays += len(frm)
        return out

    def close(self) -> None:
        self._finalizer()


def polyline_length(points) -> float:
    pts = np.asarray(points, dtype=float)
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()) if len(pts) > 1 else 0.0


def unit_ball_volume(d: int) -> float:
    return math.pi ** (d / 2) / math.gamma(d / 2 + 1)


class GoalCache:
    """Per-goal planner caches that live as long as some open task uses the goal.

    ``get(key, task_id)`` returns the cache entry of ``key`` (created by ``factory``), noting that
    ``task_id`` uses it; entries asked for without a task (a direct ``plan`` call) are kept in a
    small LRU of ``loose`` entries instead. ``task_closed`` drops a task's entries once no other
    open task shares them.
    """

    def __init__(self, factory, max_loose: int = 64) -> None:
        self.factory = factory
        self.max_loose = max_loose
        self.entries: dict = {}
        self._users: dict = {}
        self._task_keys: dict[int, set] = {}
        self._loose: OrderedDict = OrderedDict()

    def get(self, key, task_id: int | None):
        entry = self.entries.get(key)
        if entry is None:
            entry = self.entries[key] = self.factory(key)
        if task_id is not None:
            self._users.setdefault(key, set()).add(task_id)
            self._task_keys.setdefault(task_id, set()).add(key)
            self._loose.pop(key, None)
        elif not self._users.get(key):
            self._loose[key] = None
            self._loose.move_to_end(key)
            while len(self._loose) > self.max_loose:
                old, _ = self._loose.popitem(last=False)
                self.entries.pop(old, None)
        return entry

    def task_closed(self, task_id: int) -> None:
        for key in self._task_keys.pop(task_id, set()):
            users = self._users.get(key)
            if users is not None:
                users.discard(task_id)
                if not users:
                    self._users.pop(key, None)
                    self.entries.pop(key, None)

    def __len__(self) -> int:
        return len(self.entries)
