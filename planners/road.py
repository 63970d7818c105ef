"""The ``dijkstra`` planner: exact travel times and fastest paths on a road network.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the fastest driving time in seconds from
      ``agents[a].loc`` to the node ``tasks[t].loc`` under the network's edge times:
      ``loc.remaining`` plus the shortest time from ``loc.node`` for a vehicle part-way along an
      edge (it finishes the edge first), the shortest time from the node for an ``int``.
      The network's times are the vehicles' times (``agent.speed`` is not used: a road's time
      already says how fast it is driven). ``inf`` only where no path exists (never inside one
      network from :mod:`dispatch.space.roads`, which keeps a strongly connected component).
      "Exact" means equal to ``scipy.sparse.csgraph.dijkstra`` on the network's ``time`` matrix
      up to the rounding order of the float64 sums (a few ulps; tests hold it to 1e-9 s).
    * A task's column comes from the field "seconds from every node to the task's node",
      computed the first time a decision needs it and kept until :meth:`RoadPlanner.task_closed`;
      tasks on one node share one field. A later decision only gathers at the agents' nodes.
    * Fields are computed by PHAST on a contraction hierarchy of the network
      (:mod:`planners._road_fast`): built once per network object and process (about 4-7 s on
      Chicago's 11,180 nodes, kept while the network lives; its contraction is cached on disk,
      so later processes on the machine read it in milliseconds: :func:`hierarchy_cache`),
      then each field is an upward search
      plus one linear sweep, ``PHAST_BLOCK`` fields per sweep, blocks on ``FIELD_THREADS``
      threads. On Chicago a field costs about 70 us against about 1.3 ms for a scipy Dijkstra.
      Networks below ``CH_MIN_NODES`` nodes use scipy's Dijkstra (the hierarchy would not pay).
    * When a decision has many more uncached task nodes than distinct agent nodes
      (``FORWARD_RATIO`` times as many), one forward field per agent node answers those
      tasks instead (same numbers, nothing cached): e.g. 5 taxis and 500 fresh requests cost 5
      fields, not 500.
    * ``plan`` returns a fastest node path whose time equals the cost, or None: it walks down
      the goal's field (cached for an open task's pickup; else one PHAST field, or on small
      networks a compiled A*), taking at each node the edge that keeps to a fastest path
      (ties: the lowest node index). Among equally fast paths it may pick another one than
      scipy's predecessors would.

Statistics: ``stats.cost_queries``, ``stats.plans``; ``stats.extra`` holds ``fields_computed``
(backward fields), ``field_reuses`` (task columns read from the cache) and
``forward_searches``.
"""

from __future__ import annotations

import hashlib
import heapq
import logging
import math
import os
import tempfile
import threading
import time
import weakref
from collections import OrderedDict
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from dispatch._compiled import charge, interpreting
from dispatch.api.contracts import Planner
from dispatch.api.legs import RoadPoint
from dispatch.space.roads import RoadNetwork
from planners import _road_fast

log = logging.getLogger(__name__)

#: Forward searches (one per distinct agent node, nothing cached) replace backward fields when
#: the uncached task nodes outnumber the agent nodes by at least this factor. One search costs
#: the same either way (1.2-1.3 ms on Chicago, each direction); a field is reused at every later
#: decision the task stays open, so fields win unless the uncached side is clearly larger.
FORWARD_RATIO = 4
#: Bytes of fields kept after their last task closed (least recently used first out): a later
#: task on the same node, or a drop-off there (networks with a hierarchy), reads the kept field
#: instead of another search. Taxi demand comes back to the same nodes all day.
RETIRED_FIELD_BYTES = 128 * 2**20
#: Bytes of forward fields (from a request's pickup or drop-off, for shared-ride insertions)
#: kept, least recently used first out.
FORWARD_FIELD_BYTES = 64 * 2**20
#: Fields computed together by one PHAST sweep (its inner loop runs over them).
PHAST_BLOCK = 8
#: Threads running PHAST blocks at once (1: never in parallel).
FIELD_THREADS = max(1, min(4, os.cpu_count() or 1))
#: Smallest network that gets a contraction hierarchy; smaller ones use scipy's Dijkstra.
CH_MIN_NODES = 1000
#: Witness searches of the hierarchy's construction stop after this many settled nodes.
CH_SETTLE_LIMIT = 100


class Hierarchy:
    """A contraction hierarchy of a network's time matrix, arranged for PHAST.

    Nodes are renumbered by *position*: 0 the highest rank (contracted last). ``up_out`` holds,
    per position, the hierarchy edges leaving to higher-ranked nodes; ``up_in`` the edges
    arriving from higher-ranked nodes (both CSR triples ``(indptr, indices, weights)`` in
    positions). Fields come back in position order: ``field[pos[node]]``.
    """

    def __init__(self, net: RoadNetwork, contracted=None) -> None:
        """The hierarchy of ``net``: contracted now, or from ``contracted``, the
        ``(rank, eu, ev, ew)`` arrays an earlier contraction of the same network gave (see
        :func:`hierarchy`'s disk cache)."""
        if contracted is None:
            contracted = contract(net)
        rank, eu, ev, ew = contracted
        self.contracted = contracted
        n = net.n
        self.n = n
        self.pos = (n - 1 - rank).astype(np.int64)
        self.n_edges = int(eu.size)
        up = rank[ev] > rank[eu]
        self.up_out = _csr3(self.pos[eu[up]], self.pos[ev[up]], ew[up], n)
        self.up_in = _csr3(self.pos[ev[~up]], self.pos[eu[~up]], ew[~up], n)
        self._local = threading.local()

    def _scratch(self, k: int):
        sc = getattr(self._local, "scratch", None)
        if sc is None or sc[0].shape[1] < k:
            sc = self._local.scratch = (np.empty((self.n, max(k, PHAST_BLOCK))),
                                        np.empty(self.n, np.int64), np.zeros(self.n, np.bool_))
        return sc

    def _block(self, positions: np.ndarray, to: bool) -> np.ndarray:
        D, stack, seen = self._scratch(positions.size)
        out = np.empty((positions.size, self.n))
        up, sweep = (self.up_in, self.up_out) if to else (self.up_out, self.up_in)
        _road_fast.phast(*up, *sweep, positions, out, D[:, :positions.size], stack, seen)
        out.setflags(write=False)
        return out

    def fields(self, nodes: np.ndarray, to: bool) -> list[np.ndarray]:
        """Per node, its field in position order: seconds from every node to it (``to``) or
        from it to every node. Rows of blocks of ``PHAST_BLOCK`` (a field keeps its block's
        memory, ``PHAST_BLOCK`` fields, alive), blocks on threads."""
        positions = self.pos[np.asarray(nodes, dtype=np.int64)]
        chunks = [positions[i:i + PHAST_BLOCK] for i in range(0, positions.size, PHAST_BLOCK)]
        pool = _pool() if len(chunks) > 1 else None
        blocks = [self._block(c, to) for c in chunks] if pool is None else list(
            pool.map(self._block, chunks, [to] * len(chunks)))
        return [row for b in blocks for row in b]


_HIERARCHIES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_H_LOCK = threading.Lock()
_POOL: dict = {}  # pid -> ThreadPoolExecutor (a forked child must not reuse its parent's)


def contract(net: RoadNetwork) -> tuple[np.ndarray, ...]:
    """``(rank, eu, ev, ew)``: each node's rank and the hierarchy's edges ``eu -> ev`` of
    weight ``ew`` (:func:`planners._road_fast.ch_contract`; deterministic: the same network
    gives the same arrays)."""
    t = net.time
    return _road_fast.ch_contract(t.indptr.astype(np.int64), t.indices.astype(np.int64),
                                  np.ascontiguousarray(t.data, dtype=np.float64),
                                  CH_SETTLE_LIMIT, True)


def hierarchy(net: RoadNetwork) -> Hierarchy | None:
    """The network's :class:`Hierarchy` (kept while the network lives), or None below
    ``CH_MIN_NODES`` nodes. Its contraction (about 7 CPU seconds on Chicago: the whole cold
    start of a run there) is read from the disk cache when an earlier process wrote it for the
    same network (see :func:`hierarchy_cache`), else computed and written there."""
    if net.n < CH_MIN_NODES:
        return None
    with _H_LOCK:
        h = _HIERARCHIES.get(net)
        if h is None:
            path = hierarchy_cache(net)
            contracted = _read_contracted(path, net.n) if path is not None else None
            h = _HIERARCHIES[net] = Hierarchy(net, contracted)
            if path is not None and contracted is None:
                _write_contracted(path, h.contracted)
        return h


#: Bumped whenever :func:`contract` would give other arrays for the same network (the
#: contraction's rules or parameters): cached hierarchies of another version are not read.
CH_FORMAT = 1


def hierarchy_cache(net: RoadNetwork) -> Path | None:
    """Where the contraction of ``net`` is cached: a file named by a hash of the network's
    travel-time graph and of the contraction's version and parameters, in the folder
    ``$DISPATCH_CACHE_DIR`` (``off``, or empty: no cache), else ``$XDG_CACHE_HOME/dispatch``,
    else ``~/.cache/dispatch``. A file is only ever written whole (temporary name, then a
    rename) and read back checked, so processes may share the folder; one that cannot be read
    is computed again."""
    folder = os.environ.get("DISPATCH_CACHE_DIR")
    if folder is not None and folder.strip().lower() in ("", "off", "0", "none"):
        return None
    if folder is None:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        folder = os.path.join(base, "dispatch")
    t = net.time
    digest = hashlib.sha256()
    digest.update(f"ch{CH_FORMAT}/{CH_SETTLE_LIMIT}/{net.n}/".encode())
    for a in (t.indptr.astype(np.int64), t.indices.astype(np.int64),
              np.ascontiguousarray(t.data, dtype=np.float64)):
        digest.update(np.ascontiguousarray(a).tobytes())
    return Path(folder) / "hierarchies" / f"{digest.hexdigest()[:32]}.npz"


def _read_contracted(path: Path, n: int) -> tuple[np.ndarray, ...] | None:
    """The cached ``(rank, eu, ev, ew)`` at ``path``, or None (absent, unreadable, not one)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            rank, eu, ev, ew = (z[k] for k in ("rank", "eu", "ev", "ew"))
    except FileNotFoundError:
        return None
    except Exception as e:  # noqa: BLE001 - a damaged file: computed again, and replaced
        log.warning("ignoring the cached road hierarchy %s (%s: %s)", path, type(e).__name__, e)
        return None
    m = eu.size
    if not (rank.shape == (n,) and ev.shape == (m,) and ew.shape == (m,)
            and rank.dtype.kind == eu.dtype.kind == ev.dtype.kind == "i" and ew.dtype.kind == "f"
            and np.array_equal(np.sort(rank), np.arange(n))
            and (m == 0 or (min(eu.min(), ev.min()) >= 0 and max(eu.max(), ev.max()) < n))):
        log.warning("ignoring the cached road hierarchy %s (not one of %d nodes)", path, n)
        return None
    return rank, eu, ev, ew


def _write_contracted(path: Path, contracted) -> None:
    """Write ``(rank, eu, ev, ew)`` to ``path`` atomically; a folder that cannot be written
    only costs the next process the contraction (logged)."""
    rank, eu, ev, ew = contracted
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, rank=rank, eu=eu, ev=ev, ew=ew)
            os.chmod(tmp, 0o644)  # (mkstemp makes it private; a cache others may read)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as e:
        log.info("road hierarchy not cached (%s: %s)", type(e).__name__, e)


def _pool() -> ThreadPoolExecutor | None:
    if FIELD_THREADS < 2:
        return None
    with _H_LOCK:
        pool = _POOL.get(os.getpid())
        if pool is None:
            _POOL.clear()
            pool = _POOL[os.getpid()] = ThreadPoolExecutor(FIELD_THREADS,
                                                           thread_name_prefix="road-fields")
        return pool


def _csr3(rows: np.ndarray, cols: np.ndarray, w: np.ndarray, n: int):
    """CSR ``(indptr, indices, weights)`` of the entries, each row's by column."""
    order = np.lexsort((cols, rows))
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, cols[order].astype(np.int64), np.ascontiguousarray(w[order], dtype=np.float64)


class RoadPlanner(Planner):
    """Exact road planner: cached Dijkstra fields per task node, fastest paths by Dijkstra."""

    name = "dijkstra"
    spaces = ("road",)
    travel_times = True
    drive_floor = 1.0  # costs are the network's times: no faster than its top speed

    def __init__(self, space: RoadNetwork) -> None:
        if not isinstance(space, RoadNetwork):
            raise TypeError(f"planner {self.name!r} serves road networks, not "
                            f"{type(space).__name__} (space kind {getattr(space, 'kind', None)!r})")
        super().__init__(space)
        self.space = space
        self._node_of: dict[Any, int] = {}  # task id -> its node
        # node -> seconds from every node to it (indexed by self._index: position order with a
        # hierarchy, node order without)
        self._fields: dict[int, np.ndarray] = {}
        self._hierarchy = hierarchy(space)
        self._index = None if self._hierarchy is None else self._hierarchy.pos
        self._users: dict[int, int] = {}  # node -> number of cached tasks on it
        #: node -> field whose tasks all closed, least recently used first (bounded: see
        #: RETIRED_FIELD_BYTES); the same numbers a new search would give
        self._retired: OrderedDict[int, np.ndarray] = OrderedDict()
        self._retired_bytes = 0
        #: node -> seconds from it to every node (forward fields of :meth:`between`), LRU
        self._fwd: OrderedDict[int, np.ndarray] = OrderedDict()
        self._fwd_bytes = 0
        t = space.time
        #: CSR triples (int64 / float64) of the time matrix and of its transpose
        self._graph = (t.indptr.astype(np.int64), t.indices.astype(np.int64),
                       np.ascontiguousarray(t.data, dtype=np.float64))
        tt = t.T.tocsr()
        tt.sort_indices()
        self._graph_t = (tt.indptr.astype(np.int64), tt.indices.astype(np.int64),
                         np.ascontiguousarray(tt.data, dtype=np.float64))
        self._order = np.arange(space.n, dtype=np.int64) if self._index is None else self._index
        self._scratch = (np.zeros(space.n, dtype=np.bool_), np.empty(t.nnz + 1),
                         np.empty(t.nnz + 1, dtype=np.int64), np.empty(space.n, dtype=np.int64))
        # A*'s bound: straight-line metres over the fastest straight-line speed of any edge
        rows = np.repeat(np.arange(space.n), np.diff(t.indptr))
        straight = np.hypot(*(space.xy[t.indices] - space.xy[rows]).T) / t.data
        fastest = float(straight.max()) if straight.size else 0.0
        self._inv_speed = 1.0 / fastest if fastest > 0 and np.isfinite(fastest) else 0.0
        #: a writable copy of the nodes' coordinates for A* (numba calls with read-only
        #: arrays cost more; nothing writes to it)
        self._xy = np.array(space.xy, dtype=np.float64)
        self._astar = (np.full(space.n, np.inf), np.empty(space.n, dtype=np.int64),
                       np.empty(space.n, dtype=np.int64))
        self.stats.extra.setdefault("fields_computed", 0)
        self.stats.extra.setdefault("field_reuses", 0)
        self.stats.extra.setdefault("forward_searches", 0)

    @cached_property
    def _lists(self) -> tuple[list, list, list]:
        """:attr:`_graph` as Python lists (for :func:`_plain_field`)."""
        return tuple(a.tolist() for a in self._graph)

    @cached_property
    def _lists_t(self) -> tuple[list, list, list]:
        """:attr:`_graph_t` as Python lists (for :func:`_plain_field`)."""
        return tuple(a.tolist() for a in self._graph_t)

    def _remember(self, task_id: Any, node: int) -> None:
        old = self._node_of.get(task_id)
        if old == node:
            return
        if old is not None:
            self.task_closed(task_id)
        self._node_of[task_id] = node
        self._users[node] = self._users.get(node, 0) + 1

    def costs(self, agents: Sequence[Any], tasks: Sequence[Any]) -> np.ndarray:
        """Return the ``(len(agents), len(tasks))`` array of exact travel seconds (see module)."""
        self.stats.cost_queries += 1
        if len(tasks) == 1 and getattr(agents, "nodes", None) is not None and len(agents):
            return self._column(agents, tasks[0])
        shape = (len(agents), len(tasks))
        if not shape[0] or not shape[1]:
            return np.full(shape, np.inf)
        out = None  # (made below; not filled first where every task has a field)
        node, rem = _agent_arrays(agents)
        tnode = np.fromiter((int(t.loc) for t in tasks), np.int64, len(tasks))
        cached = np.fromiter((int(n) in self._fields for n in tnode), bool, len(tasks))
        fresh = np.unique(tnode[~cached])
        forward = False
        if fresh.size >= FORWARD_RATIO:  # else fewer than FORWARD_RATIO x any agent count
            agent_nodes, agent_inv = np.unique(node, return_inverse=True)
            forward = fresh.size >= FORWARD_RATIO * agent_nodes.size

        h, index = self._hierarchy, self._index
        reused = int(cached.sum())
        if forward:
            # a few agents, many new tasks: search forward from the agents, cache nothing
            self.stats.extra["forward_searches"] += int(agent_nodes.size)
            cols = np.flatnonzero(~cached)
            if h is None:
                fwd = np.stack(self._dijkstra(agent_nodes, to=False))[:, tnode[cols]]
            else:
                at = index[tnode[cols]]
                fwd = np.stack([f[at] for f in h.fields(agent_nodes, to=False)])
            out = np.full(shape, np.inf)
            out[:, cols] = fwd[agent_inv]
        elif fresh.size:
            if self._retired:  # (after the choice above: forward sums may round otherwise)
                fresh = np.array([n for n in fresh.tolist() if self._revive(n) is None],
                                 dtype=np.int64)
            if fresh.size:
                fields = (self._dijkstra(fresh, to=True) if h is None
                          else h.fields(fresh, to=True))
                self._fields.update(zip(fresh.tolist(), fields))
                self.stats.extra["fields_computed"] += int(fresh.size)
            cached[:] = True
        self.stats.extra["field_reuses"] += reused

        hits = np.flatnonzero(cached).tolist()
        at = node if index is None else index[node]
        if len(hits) == len(tasks):  # every column from a field (a batch's usual case)
            fields = [self._fields[n] for n in tnode.tolist()]
            if fields[0].size <= len(at):
                # more agents than nodes (a small grid, a big fleet): the fields side by side,
                # their rows at the agents' nodes gathered at once
                out = np.stack(fields, axis=1).take(at, axis=0)
            else:  # a big network: gather each field at the agents, then lay them side by side
                out = np.stack([f.take(at) for f in fields], axis=1)
        else:
            if out is None:
                out = np.full(shape, np.inf)
            for t in hits:
                out[:, t] = self._fields[int(tnode[t])][at]
        for t in hits:  # after reading: re-homing a task may drop a field
            self._remember(tasks[t].id, int(tnode[t]))
        if getattr(agents, "nodes", None) is not None and not agents.points.size:
            return out  # everyone on a node: nothing left to drive first
        return out + rem[:, None]

    def _column(self, agents: Any, task: Any) -> np.ndarray:
        """:meth:`costs` of one task (an immediate decision's usual problem) for agents that
        carry their node arrays: the same numbers and statistics as the general path, with a
        handful of numpy calls instead of a few dozen."""
        goal = int(task.loc)
        field = self._fields.get(goal)
        if field is None:
            field = self._revive(goal)
        if field is None:  # one new node: a field (the forward search needs 4 or more)
            goals = np.array([goal], dtype=np.int64)
            h = self._hierarchy
            field = (self._dijkstra(goals, to=True) if h is None else h.fields(goals, to=True))[0]
            self._fields[goal] = field
            self.stats.extra["fields_computed"] += 1
        else:
            self.stats.extra["field_reuses"] += 1
        nodes = agents.nodes
        # (take: the same gather as field[nodes], about twice as fast)
        out = field.take(nodes if self._index is None else self._index.take(nodes))[:, None]
        self._remember(task.id, goal)
        if not agents.points.size:
            return out  # everyone on a node: nothing left to drive first
        return out + agents.remaining[:, None]

    def between(self, sources: Sequence[Any], targets: Sequence[Any],
                pairwise: bool = False) -> np.ndarray:
        """Exact travel seconds from ``sources`` (nodes or road points) to ``targets`` (nodes),
        plus what a source part-way along an edge has left of it. With fewer distinct
        sources than targets (a new request against the stops of a fleet's plans) one forward
        field per source node is gathered at the targets; otherwise each target's field (an
        open task's, a kept one, or a new one, then kept with the retired fields: drop-offs
        and stops come back) is gathered at the sources."""
        if pairwise and len(targets) <= 8 and len(sources) == len(targets):
            # a few pairs (an immediate decision's new trip): no arrays to build
            index, out = self._index, np.empty(len(targets))
            for k, (src, t) in enumerate(zip(sources, targets)):
                point = isinstance(src, RoadPoint)
                n = src.node if point else int(src)
                out[k] = self._to(int(t))[n if index is None else index[n]] + (
                    max(src.remaining, 0.0) if point else 0.0)
            return out
        node, rem = _loc_arrays(sources)
        tnode = _loc_arrays(targets)[0]
        if pairwise and node.size != tnode.size:
            raise ValueError("pairwise travel times need as many sources as targets")
        index = self._index
        # only the smaller side is made distinct (the other may be a whole fleet's stops)
        if not pairwise and node.size < tnode.size:
            # (one source: itself, distinct)
            snodes, sinv = (node, None) if node.size == 1 else _distinct(node)
            fwd = self._forward(snodes)  # (distinct sources, n)
            at = tnode if index is None else index[tnode]
            # (the targets' columns first, then a row per source: the same elements as
            # ``fwd[sinv][:, at]``, without copying whole fields or a two-axis fancy index)
            out = fwd.take(at, axis=1)
            if node.size > 1:  # (one source: its one row)
                out = out.take(sinv, axis=0)
            return out if rem is None else out + rem[:, None]
        at = node if index is None else index[node]
        if not pairwise and tnode.size == 1:  # one target (a new request): its field's column
            out = self._to(int(tnode[0])).take(at)[:, None]
            return out if rem is None else out + rem[:, None]
        tnodes, tinv = _distinct(tnode)
        fields = [self._to(n) for n in tnodes.tolist()]
        if pairwise:
            out = np.fromiter((fields[k][a] for k, a in zip(tinv.tolist(), at.tolist())),
                              np.float64, tnode.size)
            return out if rem is None else out + rem
        out = np.empty((node.size, tnode.size))
        for p, k in enumerate(tinv.tolist()):
            out[:, p] = fields[k][at]
        return out if rem is None else out + rem[:, None]

    def _to(self, n: int) -> np.ndarray:
        """The field of seconds to node ``n``: an open task's, a kept one, or a new one (kept)."""
        f = self._fields.get(n)
        if f is not None:
            return f
        f = self._retired.get(n)
        if f is not None:
            self._retired.move_to_end(n)
            return f
        h = self._hierarchy
        nodes = np.array([n], dtype=np.int64)
        f = (self._dijkstra(nodes, to=True) if h is None else h.fields(nodes, to=True))[0]
        self.stats.extra["fields_computed"] += 1
        self._retire(n, f)
        return self._retired[n]

    def _forward(self, nodes: np.ndarray) -> np.ndarray:
        """Fields of seconds from each of ``nodes`` (rows; indexed like the backward fields),
        the most recently used kept within :data:`FORWARD_FIELD_BYTES` (a request's pickup and
        drop-off are asked about at every decision it stays open)."""
        kept = self._fwd
        fresh = [n for n in nodes.tolist() if n not in kept]
        if fresh:
            h = self._hierarchy
            arr = np.array(fresh, dtype=np.int64)
            self.stats.extra["forward_searches"] += len(fresh)
            new = self._dijkstra(arr, to=False) if h is None else h.fields(arr, to=False)
            for n, f in zip(fresh, new):
                if f.base is not None and f.base.nbytes > f.nbytes:
                    f = f.copy()  # a row of a PHAST block: keep the row, not the block
                kept[n] = f
                self._fwd_bytes += f.nbytes
        rows = []
        for n in nodes.tolist():
            kept.move_to_end(n)
            rows.append(kept[n])
        while self._fwd_bytes > FORWARD_FIELD_BYTES and len(kept) > nodes.size:
            self._fwd_bytes -= kept.popitem(last=False)[1].nbytes
        # (one field: a view as a row, no copy; a caller gathers from it, never writes)
        return rows[0][None, :] if len(rows) == 1 else np.stack(rows)

    def _revive(self, node: int) -> np.ndarray | None:
        """The kept field of ``node`` back among the open tasks' fields, or None."""
        field = self._retired.pop(node, None)
        if field is not None:
            self._retired_bytes -= field.nbytes
            self._fields[node] = field
            self.stats.extra["fields_revived"] = self.stats.extra.get("fields_revived", 0) + 1
        return field

    def _retire(self, node: int, field: np.ndarray) -> None:
        """Keep ``node``'s field (most recently used) within :data:`RETIRED_FIELD_BYTES`."""
        old = self._retired.pop(node, None)
        if old is not None:
            self._retired_bytes -= old.nbytes
        if field.base is not None and field.base.nbytes > field.nbytes:
            field = field.copy()  # a row of a PHAST block: keep the row, not the block
            field.setflags(write=False)
        self._retired[node] = field
        self._retired_bytes += field.nbytes
        while self._retired_bytes > RETIRED_FIELD_BYTES and self._retired:
            self._retired_bytes -= self._retired.popitem(last=False)[1].nbytes

    def _dijkstra(self, nodes: np.ndarray, to: bool) -> list[np.ndarray]:
        """Complete fields by the compiled Dijkstra (networks without a hierarchy), node
        order: seconds to (``to``) or from each node; one read-only row each. While the
        process runs its compiled searches as plain Python (:func:`dispatch._compiled.
        interpreting`: a short run need not load numba) a plain Python Dijkstra gives them
        (:func:`_plain_field`)."""
        if interpreting():
            started = time.thread_time()
            lists = self._lists_t if to else self._lists
            out = []
            for s in np.asarray(nodes, dtype=np.int64).tolist():
                d = np.array(_plain_field(*lists, s))
                d.setflags(write=False)
                out.append(d)
            charge(time.thread_time() - started)
            return out
        want, hk, hn, _ = self._scratch
        graph = self._graph_t if to else self._graph
        out = []
        for s in np.asarray(nodes, dtype=np.int64).tolist():
            d = np.empty(self.space.n)
            _road_fast.dijkstra_until(*graph, s, want, 0, d, hk, hn)
            d.setflags(write=False)
            out.append(d)
        return out

    def plan(self, agent: Any, goal: int) -> list[int] | None:
        """A fastest node path from the agent's node (``agent.loc.node``, or ``agent.loc``) to
        ``goal``, both included (``[goal]`` when already there), or None if unreachable.

        Where ``goal`` has a cached field (an open task's pickup) it walks down the field,
        from each node along the edge that keeps to a fastest path (ties: the lowest node
        index). Elsewhere (a drop-off) it walks down a PHAST field computed for the goal
        (networks with a hierarchy), or a compiled A* with the straight-line bound finds it
        (small networks)."""
        self.stats.plans += 1
        loc = agent.loc
        start = loc.node if isinstance(loc, RoadPoint) else int(loc)
        goal = int(goal)
        if start == goal:
            return [goal]
        field = self._fields.get(goal)
        path = self._scratch[3]
        if field is None and self._hierarchy is not None:
            # one PHAST field to the goal, walked down: on Chicago several times cheaper than
            # A*, whose straight-line bound is weak there (its fastest edge, in straight-line
            # terms, is 194 m/s: a coordinate quirk); kept with the retired fields (the same
            # numbers: the walk is the same whichever copy it reads)
            field = self._retired.get(goal)
            if field is None:
                field = self._hierarchy.fields(np.array([goal]), to=True)[0]
            self._retire(goal, field)
        if field is None:
            _, hk, hn, _ = self._scratch
            k = _road_fast.astar(*self._graph, self._xy, self._inv_speed, start, goal,
                                 *self._astar, hk, hn, path)
            return path[:k].tolist() if k else None
        k = _road_fast.descend(*self._graph, field, self._order, start, goal, path)
        if k < 0:  # no finite field value at the start: unreachable (or a broken field)
            leg = self.space.route(start, goal)
            return None if leg is None else leg.nodes.tolist()
        return path[:k].tolist()

    def task_closed(self, task_id: Any) -> None:
        """Forget the task; its node's field goes once no other cached task stands on it."""
        node = self._node_of.pop(task_id, None)
        if node is None:
            return
        left = self._users.get(node, 1) - 1
        if left > 0:
            self._users[node] = left
        else:
            self._users.pop(node, None)
            field = self._fields.pop(node, None)
            if field is not None:
                self._retire(node, field)


def _plain_field(indptr: list, indices: list, data: list, source: int) -> list[float]:
    """Seconds from ``source`` to every node of the CSR graph (``inf`` where unreachable), by
    a binary-heap Dijkstra in plain Python: the same floats, bit for bit, as the compiled
    :func:`planners._road_fast.dijkstra_until`'s complete field. (Each node's time is the
    least, over its in-edges from nodes settled before it, of that node's time plus the edge,
    added once; with positive edges that least sum does not depend on the order in which a
    search settles nodes of equal time. Tests compare the two.)"""
    dist = [math.inf] * (len(indptr) - 1)
    dist[source] = 0.0
    heap = [(0.0, source)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        d, u = pop(heap)
        if d > dist[u]:
            continue  # stale entry
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + data[e]
            if nd < dist[v]:
                dist[v] = nd
                push(heap, (nd, v))
    return dist


def _distinct(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(nodes, return_inverse=True)``; a few nodes (a decision's new requests)
    without numpy's sort, whose fixed cost is most of the work at that size."""
    if nodes.size > 64:
        return np.unique(nodes, return_inverse=True)
    values = nodes.tolist()
    distinct = sorted(set(values))
    at = {x: k for k, x in enumerate(distinct)}
    return np.array(distinct, dtype=np.int64), np.array([at[x] for x in values], dtype=np.int64)


def _loc_arrays(locs: Sequence[Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """``(node, remaining seconds)`` of locations (node ints or road points); the seconds
    None where every location is a node (nothing left to drive first: nothing to add)."""
    if isinstance(locs, np.ndarray) and locs.dtype.kind in "iu":  # a plan table's nodes
        return locs.astype(np.int64, copy=False).reshape(-1), None
    try:  # nodes only (a plan's stops): nothing to unpack
        return np.array(locs, dtype=np.int64), None
    except TypeError:  # road points among them
        pass
    node = np.empty(len(locs), dtype=np.int64)
    rem = np.zeros(len(locs))
    for i, loc in enumerate(locs):
        if isinstance(loc, RoadPoint):
            node[i], rem[i] = loc.node, max(loc.remaining, 0.0)
        else:
            node[i] = int(loc)
    return node, rem


def _agent_arrays(agents: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """``(node, remaining seconds)`` of the agents' locations (points or node ints): read from
    the arrays of a :class:`dispatch.api.problem.AgentViews` where it has them (no view built)."""
    nodes = getattr(agents, "nodes", None)
    if nodes is not None:
        return nodes, agents.remaining
    node, rem = _loc_arrays([a.loc for a in agents])
    return node, np.zeros(node.size) if rem is None else rem
