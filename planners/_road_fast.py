"""Compiled (numba) exact searches on road graphs in CSR form: a contraction hierarchy and PHAST.

Nothing here knows about networks, vehicles or requests: :mod:`planners.road` hands in the CSR
arrays of the travel-time matrix and reads the fields back.

* :func:`ch_contract` — builds a contraction hierarchy (Geisberger et al. 2008) with float64
  edge weights: nodes are contracted one by one in the order of a priority (RoutingKit's
  level + added / removed edges + added / removed hops), recomputed for the neighbours of each
  contracted node and re-checked lazily when a node leaves the queue; contracting ``v`` adds the shortcut
  ``u -> w`` of weight ``w(u, v) + w(v, w)`` unless a witness search (a Dijkstra from ``u``
  avoiding ``v`` and the contracted nodes, limited to ``settle_limit`` settled nodes and to the
  shortcut's weight) finds a path at most as long. A limited search can only add shortcuts that
  were not needed, never miss one, and every edge weight is the length of a real path, so the
  hierarchy is exact: for every pair of nodes some up-then-down path in it has the shortest
  length. Only the sums' rounding order can differ from a plain Dijkstra's (a few ulps, far
  below 1e-9 s).
* :func:`phast` — PHAST (Delling et al. 2011): the complete field of up to ``K`` sources at once
  (seconds from each source to every node, or from every node to each target: the caller picks
  the direction by which adjacency it passes as "upward" and which as "sweep"). An upward
  Dijkstra in the hierarchy from each source, then one linear sweep over the nodes in
  descending rank, each taking the minimum over its edges from higher-ranked (already final)
  nodes. The upward search needs no heap (the upward graph is a DAG in rank order). The sweep
  handles the ``K`` sources together, so its inner loop is ``K`` contiguous float64
  ``min(d, d_u + w)`` (vectorized by LLVM). Same numbers as a one-to-all Dijkstra, up to
  the rounding order of sums (see above).
* :func:`dijkstra_until` — a plain binary-heap Dijkstra on CSR arrays that stops once every
  wanted node is settled (kept for the benchmark's comparison and for callers that want a few
  nodes only: its row is exact at the wanted nodes and an upper bound elsewhere).

The kernels release the GIL (``nogil``), so :mod:`planners.road` runs several PHAST blocks on
threads. They are :func:`dispatch._compiled.kernel` functions: numba is imported when one first
compiles, not with this module; :func:`descend` and :func:`astar` (a small network's paths) run
as the plain Python they are written in while the process is young (the same operations on the
same doubles: the heuristic squares by ``dx * dx``, as numba compiles ``dx ** 2``, where Python's
``**`` may round otherwise). Compiled code is cached on disk (``cache=True``); where no cache
directory is writable the kernels are compiled in every process instead.
"""

from __future__ import annotations

import numpy as np

from dispatch._compiled import inline, kernel


@inline
def _hpush(hk, hn, size, key, node):  # pragma: no cover - compiled
    """Push ``(key, node)`` onto the binary min-heap ``hk``/``hn`` of ``size`` entries."""
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= key:
            break
        hk[i] = hk[p]
        hn[i] = hn[p]
        i = p
    hk[i] = key
    hn[i] = node
    return size + 1


@inline
def _hpop(hk, hn, size):  # pragma: no cover - compiled
    """Pop the smallest entry: ``(key, node, new size)``."""
    key = hk[0]
    node = hn[0]
    size -= 1
    if size > 0:
        k = hk[size]
        v = hn[size]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= size:
                break
            if c + 1 < size and hk[c + 1] < hk[c]:
                c += 1
            if hk[c] >= k:
                break
            hk[i] = hk[c]
            hn[i] = hn[c]
            i = c
        hk[i] = k
        hn[i] = v
    return key, node, size


# ==================================================================== plain Dijkstra
@kernel(interpret=False, nogil=True)
def dijkstra_until(indptr, indices, data, source, want, n_want, dist, hk, hn):  # pragma: no cover
    """Dijkstra from ``source`` on the CSR graph into ``dist`` (length n, overwritten), stopping
    once the ``n_want`` distinct nodes flagged in ``want`` are settled (``n_want <= 0``: never,
    a complete field). Returns the number of nodes settled. ``dist`` is exact at every settled
    node (all wanted ones included), an upper bound (or ``inf``) elsewhere. ``hk``/``hn``: heap
    scratch with at least ``len(indices) + 1`` slots (lazy deletion: one push per improvement).
    """
    n = indptr.size - 1
    for i in range(n):
        dist[i] = np.inf
    dist[source] = 0.0
    size = _hpush(hk, hn, 0, 0.0, source)
    settled = 0
    left = n_want
    while size > 0:
        d, u, size = _hpop(hk, hn, size)
        if d > dist[u]:
            continue  # stale entry
        settled += 1
        if want[u]:
            left -= 1
            if left == 0:
                break
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + data[e]
            if nd < dist[v]:
                dist[v] = nd
                size = _hpush(hk, hn, size, nd, v)
    return settled


# ==================================================================== contraction hierarchy
@kernel(interpret=False, nogil=True)
def _witness(v, u, limit, settle_limit, goal, n_goal, head_out, nxt_out, ev, ew, contracted,
             wdist, touched, hk, hn):  # pragma: no cover - compiled
    """Witness search from ``u`` avoiding ``v`` and contracted nodes, into ``wdist`` (``inf``
    elsewhere on entry), until the ``n_goal`` nodes with ``goal[x] == v`` are settled, the
    distance passes ``limit`` or ``settle_limit`` nodes are settled. Returns how many entries of
    ``touched`` name the nodes it wrote (the caller resets them)."""
    nt = 0
    wdist[u] = 0.0
    touched[nt] = u
    nt += 1
    size = _hpush(hk, hn, 0, 0.0, u)
    settled = 0
    cap = hk.size
    while size > 0:
        d, x, size = _hpop(hk, hn, size)
        if d > wdist[x]:
            continue
        if d > limit:
            break
        if goal[x] == v:
            n_goal -= 1
            if n_goal == 0:
                break
        settled += 1
        if settled > settle_limit:
            break
        e = head_out[x]
        while e >= 0:
            y = ev[e]
            if y != v and not contracted[y]:
                nd = d + ew[e]
                if nd < wdist[y] and nd <= limit:
                    if wdist[y] == np.inf:
                        touched[nt] = y
                        nt += 1
                    wdist[y] = nd
                    if size < cap:
                        size = _hpush(hk, hn, size, nd, y)
            e = nxt_out[e]
    return nt


@kernel(interpret=False, nogil=True)
def _shortcuts(v, settle_limit, head_out, nxt_out, head_in, nxt_in, eu, ev, ew, eh, contracted,
               wdist, touched, goal, hk, hn, su, sw, sc, sh):  # pragma: no cover - compiled
    """The shortcuts contracting ``v`` needs now, in ``su``/``sw``/``sc``/``sh`` (from, to,
    weight, hops; arrays with room for in-degree x out-degree). Returns ``(count, removed
    edges, hops of the shortcuts, hops of the removed edges)``."""
    count = 0
    removed = 0
    hops = 0
    removed_hops = 0
    # out-neighbours of v still in the graph, and the longest edge to them
    wmax = 0.0
    e = head_out[v]
    while e >= 0:
        if not contracted[ev[e]]:
            removed += 1
            removed_hops += eh[e]
            wmax = max(wmax, ew[e])
        e = nxt_out[e]
    a = head_in[v]
    while a >= 0:
        u = eu[a]
        if not contracted[u]:
            removed += 1
            removed_hops += eh[a]
            wu = ew[a]
            n_goal = 0  # the out-neighbours other than u: the shortcut ends to witness
            b = head_out[v]
            while b >= 0:
                w = ev[b]
                if w != u and not contracted[w]:
                    goal[w] = v
                    n_goal += 1
                b = nxt_out[b]
            if n_goal == 0:
                a = nxt_in[a]
                continue
            nt = _witness(v, u, wu + wmax, settle_limit, goal, n_goal, head_out, nxt_out, ev, ew,
                          contracted, wdist, touched, hk, hn)
            b = head_out[v]
            while b >= 0:
                w = ev[b]
                if w != u and not contracted[w]:
                    through = wu + ew[b]
                    if wdist[w] > through:
                        su[count] = u
                        sw[count] = w
                        sc[count] = through
                        sh[count] = eh[a] + eh[b]
                        hops += sh[count]
                        count += 1
                b = nxt_out[b]
            for i in range(nt):
                wdist[touched[i]] = np.inf
            b = head_out[v]
            while b >= 0:
                goal[ev[b]] = -1
                b = nxt_out[b]
        a = nxt_in[a]
    return count, removed, hops, removed_hops


@inline
def _priority(level, count, removed, hops, removed_hops):  # pragma: no cover - compiled
    """RoutingKit's order: level + added / removed edges + added / removed hops."""
    p = float(level)
    if removed > 0:
        p += count / removed
    if removed_hops > 0:
        p += hops / removed_hops
    return p


@kernel(interpret=False, nogil=True)
def ch_contract(indptr, indices, data, settle_limit, simulate_neighbours):  # pragma: no cover - compiled
    """Contract every node of the CSR graph (no self-loops, no parallel edges, positive
    weights). Returns ``(rank, eu, ev, ew)``: each node's contraction rank (0 first) and the
    edges of the hierarchy (original edges and shortcuts, no two with the same ends; an
    original edge a shortcut improves carries the shortcut's weight).

    Order: the smallest priority first, RoutingKit's ``level + added / removed edges +
    added / removed hops`` (a node's level is one more than its highest contracted neighbour's),
    kept up to date for the neighbours of each contracted node and re-checked lazily when a node
    comes out of the queue."""
    n = indptr.size - 1
    m = indices.size
    cap = max(64, 3 * m)
    eu = np.empty(cap, np.int64)
    ev = np.empty(cap, np.int64)
    ew = np.empty(cap, np.float64)
    eh = np.empty(cap, np.int64)
    nxt_out = np.empty(cap, np.int64)
    nxt_in = np.empty(cap, np.int64)
    head_out = np.full(n, -1, np.int64)
    head_in = np.full(n, -1, np.int64)
    deg_in = np.zeros(n, np.int64)
    deg_out = np.zeros(n, np.int64)
    ne = 0
    for u in range(n):
        for k in range(indptr[u], indptr[u + 1]):
            v = indices[k]
            eu[ne] = u
            ev[ne] = v
            ew[ne] = data[k]
            eh[ne] = 1
            nxt_out[ne] = head_out[u]
            head_out[u] = ne
            nxt_in[ne] = head_in[v]
            head_in[v] = ne
            deg_out[u] += 1
            deg_in[v] += 1
            ne += 1

    contracted = np.zeros(n, np.bool_)
    level = np.zeros(n, np.int64)
    rank = np.full(n, -1, np.int64)
    wdist = np.full(n, np.inf)
    touched = np.empty(n, np.int64)
    goal = np.full(n, -1, np.int64)  # goal[w] == v: w ends a shortcut contracting v would add
    hk = np.empty(4 * n + 64)
    hn = np.empty(4 * n + 64, np.int64)
    nbuf = 64
    for v in range(n):
        nbuf = max(nbuf, deg_in[v] * deg_out[v])
    su = np.empty(nbuf, np.int64)
    sw = np.empty(nbuf, np.int64)
    sc = np.empty(nbuf)
    sh = np.empty(nbuf, np.int64)

    prio = np.empty(n)
    qk = np.empty(8 * n + 64)  # priority queue of nodes, lazy (stale entries skipped)
    qn = np.empty(8 * n + 64, np.int64)
    qs = 0
    for v in range(n):
        count, removed, hops, rh = _shortcuts(v, settle_limit, head_out, nxt_out, head_in, nxt_in,
                                              eu, ev, ew, eh, contracted, wdist, touched, goal, hk, hn,
                                              su, sw, sc, sh)
        prio[v] = _priority(level[v], count, removed, hops, rh)
        qs = _hpush(qk, qn, qs, prio[v], v)

    r = 0
    while qs > 0:
        p, v, qs = _hpop(qk, qn, qs)
        if contracted[v] or p != prio[v]:
            continue
        need = deg_in[v] * deg_out[v]
        if need > su.size:
            su = np.empty(2 * need, np.int64)
            sw = np.empty(2 * need, np.int64)
            sc = np.empty(2 * need)
            sh = np.empty(2 * need, np.int64)
        count, removed, hops, rh = _shortcuts(v, settle_limit, head_out, nxt_out, head_in, nxt_in,
                                              eu, ev, ew, eh, contracted, wdist, touched, goal, hk, hn,
                                              su, sw, sc, sh)
        now = _priority(level[v], count, removed, hops, rh)
        while qs > 0 and (contracted[qn[0]] or qk[0] != prio[qn[0]]):  # drop stale heads
            _, _, qs = _hpop(qk, qn, qs)
        if qs > 0 and now > qk[0]:  # lazy update: no longer the cheapest
            prio[v] = now
            if qs >= qk.size:  # compact: rebuild from the live priorities
                qs = 0
                for x in range(n):
                    if not contracted[x]:
                        qs = _hpush(qk, qn, qs, prio[x], x)
            qs = _hpush(qk, qn, qs, now, v)
            continue
        # contract v: add its shortcuts (or lower an existing edge u -> w)
        for i in range(count):
            u = su[i]
            w = sw[i]
            c = sc[i]
            e = head_out[u]
            found = False
            while e >= 0:
                if ev[e] == w:
                    if c < ew[e]:
                        ew[e] = c
                        eh[e] = sh[i]
                    found = True
                    break
                e = nxt_out[e]
            if found:
                continue
            if ne == eu.size:  # grow the edge store
                grow = 2 * eu.size
                eu2 = np.empty(grow, np.int64)
                ev2 = np.empty(grow, np.int64)
                ew2 = np.empty(grow)
                eh2 = np.empty(grow, np.int64)
                no2 = np.empty(grow, np.int64)
                ni2 = np.empty(grow, np.int64)
                eu2[:ne] = eu[:ne]
                ev2[:ne] = ev[:ne]
                ew2[:ne] = ew[:ne]
                eh2[:ne] = eh[:ne]
                no2[:ne] = nxt_out[:ne]
                ni2[:ne] = nxt_in[:ne]
                eu, ev, ew, eh, nxt_out, nxt_in = eu2, ev2, ew2, eh2, no2, ni2
            eu[ne] = u
            ev[ne] = w
            ew[ne] = c
            eh[ne] = sh[i]
            nxt_out[ne] = head_out[u]
            head_out[u] = ne
            nxt_in[ne] = head_in[w]
            head_in[w] = ne
            deg_out[u] += 1
            deg_in[w] += 1
            ne += 1
        contracted[v] = True
        rank[v] = r
        r += 1
        # drop v's edges from its neighbours' lists: the lists hold the remaining graph only
        e = head_out[v]
        while e >= 0:
            x = ev[e]
            prev = -1
            a = head_in[x]
            while a >= 0:
                nx = nxt_in[a]
                if eu[a] == v:
                    if prev < 0:
                        head_in[x] = nx
                    else:
                        nxt_in[prev] = nx
                    deg_in[x] -= 1
                else:
                    prev = a
                a = nx
            e = nxt_out[e]
        e = head_in[v]
        while e >= 0:
            x = eu[e]
            prev = -1
            a = head_out[x]
            while a >= 0:
                nx = nxt_out[a]
                if ev[a] == v:
                    if prev < 0:
                        head_out[x] = nx
                    else:
                        nxt_out[prev] = nx
                    deg_out[x] -= 1
                else:
                    prev = a
                a = nx
            e = nxt_in[e]
        # neighbours: level at least one above v's, and a fresh priority
        for side in range(2):
            e = head_out[v] if side == 0 else head_in[v]
            while e >= 0:
                x = ev[e] if side == 0 else eu[e]
                if not contracted[x]:
                    px = prio[x]
                    if level[x] < level[v] + 1:
                        px += level[v] + 1 - level[x]
                        level[x] = level[v] + 1
                    if simulate_neighbours:
                        need = deg_in[x] * deg_out[x]
                        if need > su.size:
                            su = np.empty(2 * need, np.int64)
                            sw = np.empty(2 * need, np.int64)
                            sc = np.empty(2 * need)
                            sh = np.empty(2 * need, np.int64)
                        cnt, rem, hx, rhx = _shortcuts(x, settle_limit, head_out, nxt_out,
                                                       head_in, nxt_in, eu, ev, ew, eh, contracted,
                                                       wdist, touched, goal, hk, hn, su, sw, sc,
                                                       sh)
                        px = _priority(level[x], cnt, rem, hx, rhx)
                    if px != prio[x]:
                        prio[x] = px
                        if qs >= qk.size:
                            qs = 0
                            for y in range(n):
                                if not contracted[y]:
                                    qs = _hpush(qk, qn, qs, prio[y], y)
                        else:
                            qs = _hpush(qk, qn, qs, px, x)
                e = nxt_out[e] if side == 0 else nxt_in[e]
    return rank, eu[:ne].copy(), ev[:ne].copy(), ew[:ne].copy()


# ==================================================================== PHAST
@kernel(interpret=False, nogil=True)
def phast(up_ptr, up_idx, up_w, sw_ptr, sw_idx, sw_w, sources, out, D, stack, seen):
    """Complete fields of ``sources`` (node positions: 0 = highest rank) into ``out``
    (``(len(sources), n)``, position order). ``up_*``: each node's hierarchy edges to
    higher-ranked nodes in the search direction; ``sw_*``: each node's edges from higher-ranked
    nodes in the sweep (for fields *to* targets: up = edges arriving from higher nodes, sweep =
    edges leaving to higher nodes; for fields *from* sources the other way round). Scratch:
    ``D`` ``(n, K >= len(sources))`` float64, ``stack`` ``(n,)`` int64, ``seen`` ``(n,)`` bool,
    all False (left so).

    The upward search needs no heap: upward edges always go to a smaller position, so the
    nodes it reaches (collected depth first) are relaxed in descending position order, a
    topological order of the upward graph."""  # pragma: no cover - compiled
    n = up_ptr.size - 1
    K = sources.size
    for p in range(n):
        for k in range(K):
            D[p, k] = np.inf
    for k in range(K):  # upward search from each source
        s = sources[k]
        seen[s] = True
        stack[0] = s
        top = 1
        done = 0
        while done < top:  # collect the upward search space
            u = stack[done]
            done += 1
            for e in range(up_ptr[u], up_ptr[u + 1]):
                v = up_idx[e]
                if not seen[v]:
                    seen[v] = True
                    stack[top] = v
                    top += 1
        space = np.sort(stack[:top])
        D[s, k] = 0.0
        for i in range(top - 1, -1, -1):  # lowest rank (largest position) first
            u = space[i]
            seen[u] = False
            du = D[u, k]
            for e in range(up_ptr[u], up_ptr[u + 1]):
                v = up_idx[e]
                D[v, k] = min(D[v, k], du + up_w[e])
    if K == 1:
        for p in range(n):  # downward sweep, highest rank first; branch-free minimum
            best = D[p, 0]
            for e in range(sw_ptr[p], sw_ptr[p + 1]):
                c = D[sw_idx[e], 0] + sw_w[e]
                best = min(best, c)
            D[p, 0] = best
    else:
        for p in range(n):
            for e in range(sw_ptr[p], sw_ptr[p + 1]):
                u = sw_idx[e]
                w = sw_w[e]
                for k in range(K):
                    c = D[u, k] + w
                    D[p, k] = min(D[p, k], c)
    for k in range(K):
        for p in range(n):
            out[k, p] = D[p, k]


# ==================================================================== paths from a field
@kernel(nogil=True)
def descend(indptr, indices, data, field, index, start, goal, path):  # pragma: no cover
    """A fastest path from ``start`` to ``goal`` read off ``field``, the seconds from every node
    to ``goal`` (``field[index[v]]`` for node ``v``: ``index`` maps nodes to the field's
    order). From each node it takes the out-edge minimizing edge time + field at its head (the
    first in CSR order on ties) until it reaches ``goal``. Writes the nodes into ``path``
    (length >= n) and returns their number, or -1 where no finite step exists or the walk
    exceeds ``n`` nodes (a field that is not one: the caller falls back to a search)."""
    n = indptr.size - 1
    u = start
    k = 0
    path[0] = u
    while u != goal:
        if k >= n - 1:
            return -1
        best = np.inf
        nxt = -1
        for e in range(indptr[u], indptr[u + 1]):
            c = data[e] + field[index[indices[e]]]
            if c < best:
                best = c
                nxt = indices[e]
        if nxt < 0 or not np.isfinite(best):
            return -1
        u = nxt
        k += 1
        path[k] = u
    return k + 1


@kernel(nogil=True)
def astar(indptr, indices, data, xy, inv_speed, source, goal, dist, pred, touched, hk, hn,
          path):  # pragma: no cover - compiled
    """A fastest path from ``source`` to ``goal`` by A* with the straight-line lower bound
    ``|xy[v] - xy[goal]| * inv_speed`` (``inv_speed``: 1 / the fastest straight-line speed of
    any edge, so the bound never overestimates: consistent, and the path is exact). Writes the
    path's nodes into ``path`` and returns their number (0: unreachable). Scratch: ``dist``
    (n, all ``inf``, left so), ``pred`` (n), ``touched`` (n), heap ``hk``/``hn`` (nnz + 1)."""
    gx = xy[goal, 0]
    gy = xy[goal, 1]
    dist[source] = 0.0
    touched[0] = source
    nt = 1
    dx = xy[source, 0] - gx
    dy = xy[source, 1] - gy
    h0 = np.sqrt(dx * dx + dy * dy) * inv_speed
    size = _hpush(hk, hn, 0, h0, source)
    found = False
    while size > 0:
        f, u, size = _hpop(hk, hn, size)
        du = dist[u]
        if u == goal:
            found = True
            break
        dx = xy[u, 0] - gx
        dy = xy[u, 1] - gy
        hu = np.sqrt(dx * dx + dy * dy) * inv_speed
        if f > du + hu:
            continue  # stale entry
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = du + data[e]
            if nd < dist[v]:
                if dist[v] == np.inf:
                    touched[nt] = v
                    nt += 1
                dist[v] = nd
                pred[v] = u
                dx = xy[v, 0] - gx
                dy = xy[v, 1] - gy
                hv = np.sqrt(dx * dx + dy * dy) * inv_speed
                size = _hpush(hk, hn, size, nd + hv, v)
    k = 0
    if found:
        v = goal
        while v != source:
            path[k] = v
            k += 1
            v = pred[v]
        path[k] = source
        k += 1
        for i in range(k // 2):  # goal-first -> source-first
            t = path[i]
            path[i] = path[k - 1 - i]
            path[k - 1 - i] = t
    for i in range(nt):
        dist[touched[i]] = np.inf
    return k
