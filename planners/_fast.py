"""Compiled (numba) exact searches on implicit voxel grids: distance fields and single-pair A*.

Nothing here knows about worlds, agents or tasks: :mod:`planners.graph` prepares the arrays
(per-node legal-move masks, neighbour index deltas, step weights) and calls these kernels.

* :func:`dijkstra_field` — Dijkstra from one source over the implicit grid graph, complete or
  stopped once given target nodes are settled.
  Edge weights take only a few distinct values (1, sqrt 2, sqrt 3 cells), so the priority queue
  is one FIFO per weight class instead of a heap: keys pushed into a class's FIFO are ``d(u) + w``
  with ``d(u)`` non-decreasing over the settled nodes, so every FIFO stays sorted and the next
  node is the smallest of at most three heads (Dijkstra with K sorted queues, O(1) per
  operation). It can also record each node's parent move (one byte a node), from which
  :func:`chain_values` rebuilds any node's distance bit for bit. It is plain Dijkstra in every
  other respect — same relaxations, same float64 sums — so it returns the same distances as
  ``scipy.sparse.csgraph.dijkstra`` on the equivalent graph, bit for bit: the distances are the
  unique fixed point of ``d[v] = min over u of fl(d[u] + w(u, v))`` (``fl``: float64 rounding,
  which never lets ``d[u] + w`` fall to ``d[u]``), whatever order a correct search settles nodes in.
  A node enters each FIFO at most once (a second push into the same FIFO could not improve
  on the first), so each FIFO needs exactly ``n`` slots and nothing is ever reallocated.
  An interior node (every move legal) tries every move in a plain loop; elsewhere only the legal
  moves (the set bits of its mask) are visited. About one move in twenty improves its
  neighbour, so testing each with a branch predicts well (measured 30 % faster than the
  branch-free test of all moves it replaced); the improving ones are pushed.
* :func:`astar` — A* with a radix heap on arrays (monotone keys: the bit patterns of ``f``),
  lazy deletion, octile heuristic. Legal moves come either from a per-node mask (small grids,
  where the mask is precomputed) or are derived on the fly from a padded occupancy array (huge
  grids such as the 89-million-voxel MovingAI 3D map, where a mask would cost more than the
  search).

The kernels release the GIL (``nogil``), so :mod:`planners.graph` computes several fields on
threads. Compiled code is cached on disk (``cache=True``: the first process compiles, about
10 s, later ones load it in a fraction of a second); where no cache directory is writable
numba would refuse, so the kernels are then compiled in every process instead.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_C2 = math.sqrt(2.0) - 1.0
_C3 = math.sqrt(3.0) - math.sqrt(2.0)


def _jit(fn):
    """``numba.njit(cache=True)``, or without the disk cache when no cache dir is writable."""
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError:  # "cannot cache function ...: no locator available"
        return numba.njit(cache=False, nogil=True)(fn)


try:  # LLVM's cttz and ctlz; internal but long-standing numba intrinsics
    from numba.cpython.unsafe.numbers import leading_zeros as _clz
    from numba.cpython.unsafe.numbers import trailing_zeros as _ctz
except ImportError:  # pragma: no cover - older or newer numba

    @_jit
    def _ctz(x):
        b = 0
        while not (x >> b) & 1:
            b += 1
        return b

    @_jit
    def _clz(x):
        b = 0
        while x:
            x >>= 1
            b += 1
        return 64 - b


@numba.njit(inline="always")
def _push(qn, qk, c, v, nd, h0, h1, h2, t0, t1, t2, k0, k1, k2):  # pragma: no cover - compiled
    """Append node ``v`` with key ``nd`` to FIFO ``c`` of :func:`dijkstra_field`; returns the
    new tails and head keys (a FIFO that was empty gets ``nd`` as its head key)."""
    if c == 0:
        if h0 == t0:
            k0 = nd
        qn[0, t0] = v
        qk[0, t0] = nd
        t0 += 1
    elif c == 1:
        if h1 == t1:
            k1 = nd
        qn[1, t1] = v
        qk[1, t1] = nd
        t1 += 1
    else:
        if h2 == t2:
            k2 = nd
        qn[2, t2] = v
        qk[2, t2] = nd
        t2 += 1
    return t0, t1, t2, k0, k1, k2


#: ``parent`` codes of :func:`dijkstra_field` besides a move index: the source, unreached.
SOURCE = 254
UNREACHED = 255


@_jit
def dijkstra_field(dirs, deltas, wclass, wvalue, src, dist, qn, qk, parent,  # pragma: no cover
                   mark, targets):
    """Fill ``dist`` (float64, one per node) with the shortest distance from node ``src``.

    ``dirs[u]`` has bit ``b`` set when the step to ``u + deltas[b]`` is legal; the step weighs
    ``wvalue[wclass[b]]`` (at most three classes). Unreached nodes get ``inf``. ``src`` must be
    a valid node index. ``qn`` (int32) and ``qk`` (float64), both ``(3, n)``, are scratch.
    If ``parent`` (uint8) is not empty it receives, per node ``v``, the move ``b`` whose
    relaxation set ``dist[v]`` last (so ``dist[v] == dist[v - deltas[b]] + w_b`` exactly, the
    parent settled with its final value), :data:`SOURCE` at ``src`` and :data:`UNREACHED`
    elsewhere: one byte a node from which :func:`chain_values` gives back ``dist`` bit for bit.

    Bounded search: if ``targets > 0``, ``mark`` (uint8, one per node) is nonzero at exactly
    ``targets`` distinct nodes and the search stops as soon as all of them are settled.
    Returns the radius ``r``: the key of the last node settled, ``inf`` when the search ran to
    the end. Every node with ``dist <= r`` has its final value and (if kept) its final parent;
    the others are unknown (a later settle could still lower them).
    """
    n = dirs.size
    nb = deltas.size
    full = (np.int64(1) << nb) - 1
    inf = np.inf
    keep = parent.size > 0
    wmove = np.empty(nb, np.float64)
    for b in range(nb):
        wmove[b] = wvalue[wclass[b]]
    for i in range(n):
        dist[i] = inf
    if keep:
        for i in range(n):
            parent[i] = UNREACHED
        parent[src] = SOURCE
    h0 = 0
    h1 = 0
    h2 = 0
    t0 = 0
    t1 = 0
    t2 = 0
    left = targets
    dist[src] = 0.0
    qn[0, 0] = src
    qk[0, 0] = 0.0
    t0 = 1
    # the keys at the three FIFOs' heads (inf while a FIFO is empty), kept up to date on every
    # pop and on a push into an empty FIFO
    k0 = 0.0
    k1 = inf
    k2 = inf
    while True:
        # the next node: the smallest head of the three sorted FIFOs
        if k0 <= k1 and k0 <= k2:
            if k0 == inf:
                break
            key = k0
            u = qn[0, h0]
            h0 += 1
            k0 = qk[0, h0] if h0 < t0 else inf
        elif k1 <= k2:
            key = k1
            u = qn[1, h1]
            h1 += 1
            k1 = qk[1, h1] if h1 < t1 else inf
        else:
            key = k2
            u = qn[2, h2]
            h2 += 1
            k2 = qk[2, h2] if h2 < t2 else inf
        if key > dist[u]:
            continue  # stale: u was reached more cheaply through another FIFO
        if left > 0 and mark[u] != 0:
            left -= 1
            if left == 0:
                return key  # every target settled: nothing farther can change them
        m = np.int64(dirs[u])
        if m == full:
            # an interior node (most of them): every move, without scanning bits
            for b in range(nb):
                v = u + deltas[b]
                nd = key + wmove[b]
                if nd < dist[v]:
                    dist[v] = nd
                    if keep:
                        parent[v] = b
                    t0, t1, t2, k0, k1, k2 = _push(qn, qk, wclass[b], v, nd, h0, h1, h2,
                                                   t0, t1, t2, k0, k1, k2)
            continue
        # near obstacles and borders: the legal moves, one bit each
        while m != 0:
            b = _ctz(m)
            m &= m - 1
            v = u + deltas[b]
            nd = key + wmove[b]
            if nd < dist[v]:
                dist[v] = nd
                if keep:
                    parent[v] = b
                t0, t1, t2, k0, k1, k2 = _push(qn, qk, wclass[b], v, nd, h0, h1, h2,
                                               t0, t1, t2, k0, k1, k2)
    return inf


@_jit
def chain_values(parent, deltas, wmove, nodes, out):  # pragma: no cover
    """``out[i]``: the distance :func:`dijkstra_field` gave node ``nodes[i]``, rebuilt from its
    ``parent`` codes: the moves back to the source, then the same float64 sums in the same
    order as the search (from the source outwards), so the value is bit for bit the same.
    ``wmove[b]`` is the length of move ``b``; ``inf`` where the node was not reached."""
    stack = np.empty(64, np.uint8)
    for i in range(nodes.size):
        v = nodes[i]
        p = parent[v]
        if p == UNREACHED:
            out[i] = np.inf
            continue
        depth = 0
        while p != SOURCE:
            if depth == stack.size:
                bigger = np.empty(2 * stack.size, np.uint8)
                bigger[:depth] = stack[:depth]
                stack = bigger
            stack[depth] = p
            depth += 1
            v -= deltas[p]
            p = parent[v]
        d = 0.0
        for k in range(depth - 1, -1, -1):
            d += wmove[stack[k]]
        out[i] = d


@_jit
def flood_components(dirs, deltas, labels, stack):  # pragma: no cover - compiled
    """Label the connected components of the implicit grid graph, in place: ``labels`` holds
    ``-2`` for every node to label and ``-1`` for the others (blocked; left alone); each node
    of the first kind gets the index of its component (0, 1, ... in order of their smallest
    node), reached through the legal moves of ``dirs`` (bit ``b``: move ``deltas[b]``; the
    graph is symmetric). ``stack`` is scratch of ``labels.size`` int64 slots (each node is
    pushed once). Returns the number of components."""
    nb = deltas.size
    label = 0
    for s in range(labels.size):
        if labels[s] != -2:
            continue
        labels[s] = label
        stack[0] = s
        top = 1
        while top > 0:
            top -= 1
            u = stack[top]
            m = np.int64(dirs[u])
            for b in range(nb):
                if (m >> b) & 1:
                    v = u + deltas[b]
                    if labels[v] == -2:
                        labels[v] = label
                        stack[top] = v
                        top += 1
        label += 1
    return label


@numba.njit(inline="always")
def _octile(x, y, z):  # pragma: no cover - compiled
    """Octile distance in cells of the absolute offsets ``x, y, z``."""
    if x < y:
        x, y = y, x
    if y < z:
        y, z = z, y
        if x < y:
            x, y = y, x
    return _C3 * z + _C2 * y + x


@_jit
def astar(dirs, occ, nbr, req, deltas, dcoord, wstep, shape, pad, start, goal,  # pragma: no cover
          seen, gen, gbuf, pbuf):
    """A* from ``start`` to ``goal`` (node indices in the lattice ``shape``), in cells.

    Legal moves from ``u``: if ``dirs.size > 0``, bit ``b`` of ``dirs[u]``; otherwise the
    3x3x3 neighbourhood of ``u`` in the padded occupancy ``occ`` (``occ[u + nbr[q]]`` nonzero
    where blocked) is read into a bit set and move ``b`` is legal when every bit of ``req[b]``
    (its bounding box) is free. ``deltas[b]`` is the move's index delta, ``dcoord[b]`` the same
    move as ``(di, dj, dk)`` and ``wstep[b]`` its length.
    Scratch, one slot per node: node ``n`` has been reached in this search iff
    ``seen[n] == gen`` (uint32; a caller reuses the arrays across searches by bumping ``gen``,
    or passes lazily zeroed pages with ``gen = 1`` so that only touched nodes cost memory);
    ``gbuf`` (float64) and ``pbuf`` (uint8) need no initialization. Returns ``(length,
    path)`` with the path as an ``(n, 3)`` array of cells from start to goal (lattice
    coordinates less ``pad``), or ``(inf, empty)``.

    The open list is a radix heap on the bit patterns of ``f`` (non-negative doubles order like
    their bits): with a consistent heuristic the popped ``f`` never decreases, which is all a
    radix heap needs; a successor whose ``f`` rounds an ulp below the last popped one is filed
    with it. Entries of equal ``f`` come out last-in first-out (deeper first). Lazy deletion:
    an entry whose ``g`` is above the node's best is skipped, and a node reached more cheaply
    later is pushed again, so the search is exact even where rounding makes the heuristic
    inconsistent by an ulp. A popped node's coordinates are decoded once and its successors'
    follow from ``dcoord``, so the heuristic of a push costs no integer division.
    """
    ny = shape[1]
    nz = shape[2]
    syz = ny * nz
    gi = goal // syz
    gj = (goal % syz) // nz
    gk = goal % nz
    use_dirs = dirs.size > 0
    nb = deltas.size
    nq = nbr.size
    fbits = np.empty(1, np.float64)
    ubits = fbits.view(np.uint64)
    # entry pool: key (bits of f), node, g, next entry in the same bucket; freed entries chain
    cap = 4096
    pkey = np.empty(cap, np.uint64)
    pnode = np.empty(cap, np.int64)
    pg = np.empty(cap, np.float64)
    pnext = np.empty(cap, np.int64)
    used = 0
    free_head = -1
    head = np.full(65, -1, np.int64)
    count = 0
    # for seen nodes: gbuf[n] the best g, pbuf[n] 1 + the move that reached n (255: the start)
    seen[start] = gen
    gbuf[start] = 0.0
    pbuf[start] = 255
    fbits[0] = _octile(abs(start // syz - gi), abs((start % syz) // nz - gj),
                       abs(start % nz - gk))
    last = ubits[0]
    pkey[0] = last
    pnode[0] = start
    pg[0] = 0.0
    pnext[0] = -1
    head[0] = 0
    used = 1
    count = 1
    found = False
    while count > 0:
        if head[0] < 0:
            i = 1
            while head[i] < 0:
                i += 1
            j = head[i]
            mn = pkey[j]
            while j >= 0:
                mn = min(mn, pkey[j])
                j = pnext[j]
            last = mn
            j = head[i]
            head[i] = -1
            while j >= 0:
                nxt = pnext[j]
                x = pkey[j] ^ last
                b = 0 if x == 0 else 64 - _clz(x)
                pnext[j] = head[b]
                head[b] = j
                j = nxt
        e = head[0]
        head[0] = pnext[e]
        pnext[e] = free_head
        free_head = e
        count -= 1
        u = pnode[e]
        gu = pg[e]
        if gu > gbuf[u]:
            continue  # stale entry
        if u == goal:
            found = True
            break
        if use_dirs:
            m = np.int64(dirs[u])
        else:
            free = np.int64(0)
            for q in range(nq):
                if occ[u + nbr[q]] == 0:
                    free |= np.int64(1) << q
            m = np.int64(0)
            for b in range(nb):
                if free & req[b] == req[b]:
                    m |= np.int64(1) << b
        ui = u // syz
        uj = (u % syz) // nz
        uk = u % nz
        for b in range(nb):
            if not (m >> b) & 1:
                continue
            v = u + deltas[b]
            gv = gu + wstep[b]
            if seen[v] == gen:
                if gv >= gbuf[v]:
                    continue
            else:
                seen[v] = gen
            gbuf[v] = gv
            pbuf[v] = b + 1
            fbits[0] = gv + _octile(abs(ui + dcoord[b, 0] - gi), abs(uj + dcoord[b, 1] - gj),
                                    abs(uk + dcoord[b, 2] - gk))
            key = ubits[0]
            key = max(key, last)  # an ulp of inconsistency: file it with the current minimum
            if free_head >= 0:
                e = free_head
                free_head = pnext[e]
            else:
                if used == cap:
                    cap *= 2
                    k2 = np.empty(cap, np.uint64)
                    n2 = np.empty(cap, np.int64)
                    g2 = np.empty(cap, np.float64)
                    x2 = np.empty(cap, np.int64)
                    k2[:used] = pkey[:used]
                    n2[:used] = pnode[:used]
                    g2[:used] = pg[:used]
                    x2[:used] = pnext[:used]
                    pkey = k2
                    pnode = n2
                    pg = g2
                    pnext = x2
                e = used
                used += 1
            x = key ^ last
            bk = 0 if x == 0 else 64 - _clz(x)
            pkey[e] = key
            pnode[e] = v
            pg[e] = gv
            pnext[e] = head[bk]
            head[bk] = e
            count += 1
    if not found:
        return np.inf, np.empty((0, 3), np.int64)
    steps = 1
    n = goal
    while n != start:
        n -= deltas[pbuf[n] - 1]
        steps += 1
    path = np.empty((steps, 3), np.int64)
    n = goal
    for s in range(steps - 1, -1, -1):
        r = n % syz
        path[s, 0] = n // syz - pad
        path[s, 1] = r // nz - pad
        path[s, 2] = r % nz - pad
        if s > 0:
            n -= deltas[pbuf[n] - 1]
    return gbuf[goal], path
