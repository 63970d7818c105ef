"""The road-network space: a directed graph with travel times, where taxis drive.

A location is a node index (``int``, ``0 .. n-1``) or, for a vehicle, a :class:`RoadPoint`: on a
node, or part-way along an edge it must finish (vehicles never turn round mid-edge). So the
travel time from a point to a node is ``point.remaining`` plus the shortest time from
``point.node``; every query here keeps to that rule.

Networks come from a generated grid (:func:`manhattan`: tests, toy studies) or from a file
(GraphML, node-link JSON, TNTP; the Chicago Regional and Manhattan OSMnx networks ship with the
package): :mod:`dispatch.files.roads` reads those into a :class:`~dispatch.files.roads.RoadGraph`,
:meth:`RoadNetwork.from_graph` builds the space from it, and :func:`load_network` picks by the
name a scenario gives (files read once per modification time).

Every network keeps only the largest strongly connected component, so every node reaches every
other and travel times between nodes are finite. Shortest paths are
:func:`scipy.sparse.csgraph.dijkstra` on the ``time`` matrix (forward) or its transpose
(backward, one run per target).

The point and leg types (:class:`~dispatch.api.legs.RoadPoint`, :class:`~dispatch.api.legs.Leg`) are
:mod:`dispatch.api.legs`'s, below this module, where the road space's parts (drivers, congestion,
vehicles) read them.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy.sparse import csr_matrix

from dispatch.api.legs import Leg, RoadPoint
from dispatch.api.legs import as_point as _as_point
from dispatch.api.space import Space
from dispatch.errors import ScenarioError
from dispatch.files.roads import RoadGraph, locate, read_graph
from dispatch.locations import Position
from dispatch.space.road_edges import EdgeTable, largest_component, straight_line

log = logging.getLogger(__name__)

#: Rows of a ``(sources, nodes)`` Dijkstra block: bounds the scratch memory of a query
#: (512 x 11,180 float64 = 46 MB on Chicago).
DIJKSTRA_BLOCK = 512


class RoadNetwork(Space):
    """A directed road graph: node positions in metres and per-edge travel seconds and metres.

    Nodes are indices ``0 .. n-1``; ``ids[i]`` is node ``i``'s id in the source (Manhattan: the
    index; TNTP: the node number; GraphML: the node key, a string). ``time`` and ``length`` are
    ``n x n`` CSR matrices with the same sparsity pattern (sorted indices, no explicit zeros:
    every edge time is positive). Immutable once built: arrays are read-only, so planners and
    the loaders' cache may share one network.
    """

    kind: ClassVar[str] = "road"
    default_planner: ClassVar[str] = "dijkstra"
    features: ClassVar[frozenset[str]] = frozenset(
        {"pooling", "reassign", "snap", "energy", "reposition", "rl", "pricing", "depots"})
    start_nodes: ClassVar[bool] = True

    def __init__(self, name: str, xy: np.ndarray, ids: Any, time: csr_matrix, length: csr_matrix,
                 crs: str | None = None) -> None:
        """Wrap already-clean arrays (use :meth:`from_edges` to build from raw edge lists)."""
        self.name = name
        self.xy = np.ascontiguousarray(xy, dtype=np.float64)
        self.n = int(self.xy.shape[0])
        self.ids = ids
        self.time = time
        self.length = length
        self.crs = crs
        for a in (self.xy, time.data, time.indices, time.indptr, length.data):
            a.setflags(write=False)
        self._edges = EdgeTable(name, self.n, time, length)

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_edges(cls, name: str, xy: np.ndarray, ids: Any, u: np.ndarray, v: np.ndarray, *,
                   seconds: np.ndarray, metres: np.ndarray, crs: str | None = None) -> RoadNetwork:
        """Build a network from directed edges ``u[k] -> v[k]`` (node indices into ``xy``).

        Self-loops are dropped (they never shorten a path); of parallel edges the fastest is
        kept, with its own length. Then only the largest strongly connected component is kept
        (nodes renumbered in their original order), logging how many nodes were dropped.
        Callers guarantee positive, finite ``seconds`` and non-negative ``metres``.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n = xy.shape[0]
        u, v = np.asarray(u, dtype=np.int64), np.asarray(v, dtype=np.int64)
        seconds = np.asarray(seconds, dtype=np.float64)
        metres = np.asarray(metres, dtype=np.float64)
        keep = u != v
        u, v, seconds, metres = u[keep], v[keep], seconds[keep], metres[keep]
        # sort by (u, v, seconds): the first of each (u, v) run is the fastest parallel edge
        order = np.lexsort((seconds, v, u))
        u, v, seconds, metres = u[order], v[order], seconds[order], metres[order]
        first = np.ones(u.size, dtype=bool)
        first[1:] = (u[1:] != u[:-1]) | (v[1:] != v[:-1])
        u, v, seconds, metres = u[first], v[first], seconds[first], metres[first]

        time = _csr(u, v, seconds, n)
        inside = largest_component(time)
        dropped = n - int(inside.sum())
        if dropped:
            log.info("road network %s: kept the largest strongly connected component, %d of %d "
                     "nodes (dropped %d)", name, n - dropped, n, dropped)
        new = np.cumsum(inside) - 1
        ek = inside[u] & inside[v]
        u, v, seconds, metres = new[u[ek]], new[v[ek]], seconds[ek], metres[ek]
        m = int(inside.sum())
        ids = ids[inside] if isinstance(ids, np.ndarray) else [i for i, k in zip(ids, inside) if k]
        return cls(name, xy[inside], ids, _csr(u, v, seconds, m), _csr(u, v, metres, m), crs)

    @classmethod
    def from_graph(cls, graph: RoadGraph) -> RoadNetwork:
        """The network of a file's graph (see :meth:`from_edges`)."""
        return cls.from_edges(graph.name, graph.xy, graph.ids, graph.u, graph.v,
                              seconds=graph.seconds, metres=graph.metres, crs=graph.crs)

    # ---------------------------------------------------------------- ids and positions
    @property
    def n_edges(self) -> int:
        """Number of directed edges."""
        return int(self.time.nnz)

    @cached_property
    def _index(self) -> dict[str, int]:
        ids = self.ids.tolist() if isinstance(self.ids, np.ndarray) else self.ids
        return {str(i): k for k, i in enumerate(ids)}

    def index_of(self, node_id: Any) -> int:
        """The node index of a source id (``12`` and ``"12"`` name the same node); ValueError
        naming the id when the network has no such node (or dropped it: not strongly connected)."""
        key = node_id.strip() if isinstance(node_id, str) else str(node_id)
        if isinstance(node_id, (float, np.floating)) and float(node_id).is_integer():
            key = str(int(node_id))
        try:
            return self._index[key]
        except KeyError:
            raise ValueError(f"road network {self.name!r} has no node {node_id!r}") from None

    @cached_property
    def node_positions(self) -> list[Position]:
        """``(x, y, 0.0)`` of every node as Python floats (events are placed one by one):
        ``position(i)`` of node ``i`` is ``node_positions[i]``."""
        return [(float(x), float(y), 0.0) for x, y in self.xy.tolist()]

    @cached_property
    def _straight_line(self) -> tuple[float | None, tuple[tuple[float, float], ...]]:
        """``(top_speed, speed_slacks)``: :func:`dispatch.space.road_edges.straight_line`."""
        return straight_line(self.xy, self.time)

    @property
    def top_speed(self) -> float | None:
        """See :attr:`_straight_line`; None for a network without edges or whose nodes all
        stand on one point."""
        return self._straight_line[0]

    @property
    def speed_slacks(self) -> tuple[tuple[float, float], ...]:
        """See :attr:`_straight_line`."""
        return self._straight_line[1]

    def position(self, loc: RoadPoint | int) -> Position:
        """``(x, y, 0.0)`` metres: the node's, or for a point part-way along ``prev -> node``
        the straight-segment position at the fraction of the edge's time already driven."""
        if type(loc) is int and 0 <= loc < self.n:  # the common case: a node
            return self.node_positions[loc]
        p = self.positions([loc])[0]
        return float(p[0]), float(p[1]), 0.0

    @cached_property
    def _xyz(self) -> np.ndarray:
        """``(n, 3)`` node positions, z = 0."""
        out = np.zeros((self.n, 3))
        out[:, :2] = self.xy
        out.setflags(write=False)
        return out

    def positions(self, locs: Sequence[RoadPoint | int] | np.ndarray) -> np.ndarray:
        """``(len(locs), 3)`` positions (see :meth:`position`); vectorized for integer arrays."""
        if isinstance(locs, np.ndarray) and locs.dtype.kind in "iu":
            return self._xyz[locs.reshape(-1)]
        if isinstance(locs, (list, tuple)) and locs and type(locs[0]) is not RoadPoint:
            try:  # node indices, as a decision's open requests are (thousands when overloaded)
                return self._xyz[np.fromiter(locs, np.int64, len(locs))]
            except (TypeError, ValueError):  # a road point among them
                pass
        if isinstance(locs, (list, tuple)) and len(locs) <= _FEW_POINTS:
            # one point at a time (a decision asks for each vehicle part-way along an edge
            # alone): the same float operations as below, without a dozen numpy calls each
            return np.array([self._position_of(loc) for loc in locs]).reshape(-1, 3)
        node, prev, rem, _ = _point_arrays(locs)
        out = np.zeros((node.size, 3))
        out[:, :2] = self.xy[node]
        mid = np.flatnonzero((prev >= 0) & (rem > 0))
        if mid.size:
            full = self.time.data[self._edges.index(prev[mid], node[mid])]
            frac = np.minimum(rem[mid] / full, 1.0)[:, None]  # share of the edge still ahead
            out[mid, :2] -= frac * (self.xy[node[mid]] - self.xy[prev[mid]])
        return out

    @cached_property
    def _xy_rows(self) -> list[tuple[float, float]]:
        """Node coordinates as Python floats (for :meth:`_position_of`)."""
        return [(float(x), float(y)) for x, y in self.xy[:, :2].tolist()]

    def _position_of(self, loc: RoadPoint | int) -> tuple[float, float, float]:
        """``(x, y, 0)`` of one location, computed exactly as :meth:`positions` does for an
        array of them (bit for bit: the same IEEE operations in the same order)."""
        p = _as_point(loc)
        x, y = self._xy_rows[p.node]
        rem = max(p.remaining, 0.0)
        if p.prev >= 0 and rem > 0:
            k = self._edges.edge_of.get(p.prev * self.n + p.node)
            if k is None or not 0 <= p.prev < self.n:
                raise ValueError(f"road network {self.name!r}: no edge {p.prev} -> {p.node}")
            frac = min(rem / self._edges.edge_lists[0][k], 1.0)  # share of the edge still ahead
            px, py = self._xy_rows[p.prev]
            x, y = x - frac * (x - px), y - frac * (y - py)
        return x, y, 0.0

    # ---------------------------------------------------------------- edges and legs
    def edge(self, u: int, v: int) -> tuple[float, float]:
        """``(seconds, metres)`` of the edge ``u -> v``; ValueError if there is none."""
        return self._edges.edge(u, v)

    def leg(self, start: RoadPoint | int, nodes: Sequence[int] | np.ndarray) -> Leg:
        """The drive from ``start`` along ``nodes`` (``nodes[0]`` must be the start's node; each
        step must be an edge): cumulative seconds and metres, starting at the start's remaining
        seconds and metres. ValueError otherwise."""
        return self._edges.leg(start, nodes)

    # ---------------------------------------------------------------- shortest paths
    @cached_property
    def _time_t(self) -> csr_matrix:
        """The transposed time matrix: Dijkstra on it from ``t`` gives times *to* ``t``."""
        return self.time.T.tocsr()

    def route(self, start: RoadPoint | int, goal: int) -> Leg | None:
        """The fastest leg from ``start`` to node ``goal`` (via the start's node), or None if
        ``goal`` is unreachable (never, within one strongly connected network, for valid nodes)."""
        p = _as_point(start)
        goal = int(goal)
        if p.node == goal:
            return self.leg(p, [goal])
        from scipy.sparse.csgraph import dijkstra

        dist, pred = dijkstra(self.time, indices=p.node, return_predecessors=True)
        if not np.isfinite(dist[goal]):
            return None
        path = [goal]
        while path[-1] != p.node:
            path.append(int(pred[path[-1]]))
        return self.leg(p, path[::-1])

    def _fields(self, graph: csr_matrix, sources: np.ndarray) -> np.ndarray:
        """``(len(sources), n)`` Dijkstra times from each source on ``graph``, in blocks."""
        from scipy.sparse.csgraph import dijkstra

        out = np.empty((sources.size, self.n))
        for s in range(0, sources.size, DIJKSTRA_BLOCK):
            out[s:s + DIJKSTRA_BLOCK] = dijkstra(graph, indices=sources[s:s + DIJKSTRA_BLOCK])
        return out

    def distance_to(self, target: int) -> np.ndarray:
        """Seconds from every node to node ``target`` (``inf`` where it cannot be reached)."""
        from scipy.sparse.csgraph import dijkstra

        return dijkstra(self._time_t, indices=int(target))

    def distances_to(self, targets: Sequence[int] | np.ndarray) -> np.ndarray:
        """``(len(targets), n)``: row ``j`` is :meth:`distance_to` ``(targets[j])``."""
        return self._fields(self._time_t, np.asarray(targets, dtype=np.int64).reshape(-1))

    def distances_from(self, sources: Sequence[int] | np.ndarray) -> np.ndarray:
        """``(len(sources), n)``: row ``i`` is the seconds from node ``sources[i]`` to each node."""
        return self._fields(self.time, np.asarray(sources, dtype=np.int64).reshape(-1))

    def travel_times(self, sources: Sequence[RoadPoint | int],
                     targets: Sequence[int]) -> np.ndarray:
        """``(len(sources), len(targets))`` exact seconds, ``inf`` where unreachable:
        ``source.remaining`` plus the shortest time from ``source.node``. One Dijkstra per
        distinct node on the smaller side (forward from sources or backward from targets)."""
        node, _, rem, _ = _point_arrays(sources)
        tgt = np.asarray(targets, dtype=np.int64).reshape(-1)
        if node.size == 0 or tgt.size == 0:
            return np.empty((node.size, tgt.size))
        src_u, src_inv = np.unique(node, return_inverse=True)
        tgt_u, tgt_inv = np.unique(tgt, return_inverse=True)
        if src_u.size <= tgt_u.size:
            block = self.distances_from(src_u)[:, tgt_u]
        else:
            block = self.distances_to(tgt_u)[:, src_u].T
        return block[np.ix_(src_inv, tgt_inv)] + rem[:, None]

    def path_metres(self, start: RoadPoint | int, goal: int) -> float:
        """Metres of the fastest leg from ``start`` to ``goal`` (``inf`` if unreachable)."""
        leg = self.route(start, goal)
        return float("inf") if leg is None else leg.length

    # ---------------------------------------------------------------- geometry
    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.xy)

    def nearest(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point (``(k, 2)`` metres): the nearest node's index and its distance in metres."""
        dist, idx = self._tree.query(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return np.asarray(idx, dtype=np.int64), np.asarray(dist, dtype=np.float64)

    @cached_property
    def _lonlat(self):
        """(transformer WGS84 lon/lat -> crs, metres per crs unit)."""
        from pyproj import CRS, Transformer

        crs = CRS.from_user_input(self.crs)
        unit = crs.axis_info[0].unit_conversion_factor if crs.axis_info else 1.0
        return Transformer.from_crs("EPSG:4326", crs, always_xy=True), float(unit)

    def lonlat_to_xy(self, lon: Any, lat: Any) -> np.ndarray:
        """``(k, 2)`` metres in this network's frame of WGS84 longitudes / latitudes (degrees).
        ValueError when the network has no CRS (e.g. Manhattan)."""
        if self.crs is None:
            raise ValueError(f"road network {self.name!r} has no CRS: cannot place lon/lat points")
        transformer, unit = self._lonlat
        x, y = transformer.transform(np.asarray(lon, dtype=np.float64).reshape(-1),
                                     np.asarray(lat, dtype=np.float64).reshape(-1))
        return np.column_stack([x, y]) * unit

    def describe(self) -> dict[str, str]:
        """``dispatch.*`` metadata: space kind, network name, node and edge counts, CRS."""
        return {"dispatch.space": self.kind, "dispatch.network": self.name,
                "dispatch.nodes": str(self.n), "dispatch.edges": str(self.n_edges),
                "dispatch.crs": self.crs or "none"}

    def shared_tables(self) -> dict[str, dict[str, np.ndarray]]:
        """``nodes`` (``x``, ``y`` metres, in node order) and ``edges`` (``u``, ``v`` node
        indices, ``seconds`` free-flow, ``metres``; in CSR order: by ``u``, then ``v``), kept
        once per results folder (see :meth:`Space.shared_tables`)."""
        t = self.time
        u = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(t.indptr))
        return {"nodes": {"x": self.xy[:, 0], "y": self.xy[:, 1]},
                "edges": {"u": u, "v": t.indices.astype(np.int64),
                          "seconds": np.asarray(t.data, np.float64),
                          "metres": np.asarray(self.length.data, np.float64)}}

    def __repr__(self) -> str:
        return f"RoadNetwork({self.name!r}, nodes={self.n}, edges={self.n_edges}, crs={self.crs!r})"

    # ------------------------------------------------- the space contract: configuration
    @classmethod
    def load(cls, cfg, seed: int = 0, scenario_path=None) -> RoadNetwork:
        """The network of ``cfg.roads`` (the seed does not matter; loading is cached)."""
        return network_for(cfg.roads, scenario_path)

    @classmethod
    def label(cls, cfg) -> str:
        return f"road network {cfg.roads.network!r}"

    @classmethod
    def check_size(cls, cfg, limits, refuse) -> None:
        r = cfg.roads
        if r.network == "manhattan" and r.blocks[0] * r.blocks[1] > limits.road_nodes:
            raise refuse("world.blocks", f"a grid of {r.blocks[0] * r.blocks[1]:,} "
                                         f"intersections (more than {limits.road_nodes:,})")

    @classmethod
    def check_runs(cls, sc, planners) -> None:
        """The network loads and a trace names only nodes it has."""
        net = network_for(sc.world.roads, sc.path)
        if sc.tasks.trips is not None:
            from dispatch.plan.demand import trace_nodes_ok

            trace_nodes_ok(net, sc.tasks.trips)

    @classmethod
    def small(cls, seed: int = 0) -> RoadNetwork:
        """A 6 x 5 Manhattan grid, 100 m blocks, 10 m/s."""
        return manhattan(6, 5, 100.0, 10.0)

    # ------------------------------------------------- the space contract: a run's
    def driver(self, planner, bus, cfg, clock):
        from dispatch.space.congestion import road_driver

        return road_driver(self, planner, bus, cfg, clock)

    def reaches(self, path, start, goal) -> bool:
        try:
            return int(path[-1]) == int(goal)
        except (TypeError, ValueError):  # not a node
            return False

    def stands(self, loc: RoadPoint | int) -> tuple[int, float, bool]:
        """A node (any integer type, not a bool) stands on itself; a road point on its
        ``node``, with ``remaining`` seconds (>= 0) unless it is on it."""
        if isinstance(loc, (int, np.integer)) and not isinstance(loc, bool):
            return loc, 0.0, False
        on = loc.on_node
        return loc.node, (0.0 if on else max(loc.remaining, 0.0)), not on


def network_for(cfg, scenario_path=None) -> RoadNetwork:
    """The road network of a ``[world]`` road configuration (loading is cached by the loader);
    a file that cannot be loaded is a ScenarioError naming the scenario file and
    ``world.network``."""
    try:
        return load_network(cfg.network, base=cfg.base, blocks=cfg.blocks, block=cfg.block,
                            speed=cfg.speed)
    except (ValueError, OSError) as e:
        raise ScenarioError(scenario_path or cfg.base, "world.network", str(e)) from None
    except Exception as e:  # noqa: BLE001 - a malformed file raises whatever its parser raises
        raise ScenarioError(scenario_path or cfg.base, "world.network",
                            f"{cfg.network} cannot be read ({type(e).__name__}: {e})") from None


def _csr(u: np.ndarray, v: np.ndarray, w: np.ndarray, n: int) -> csr_matrix:
    """An ``n x n`` CSR matrix from unique ``(u, v)`` entries sorted by ``(u, v)``, built
    directly (no summing, so explicit entries are never merged or dropped)."""
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(u, minlength=n), out=indptr[1:])
    m = csr_matrix((np.asarray(w, dtype=np.float64), np.asarray(v, dtype=np.int32),
                    indptr.astype(np.int32)), shape=(n, n))
    m.has_sorted_indices = True
    return m


#: :meth:`RoadNetwork.positions` computes lists up to this long point by point
_FEW_POINTS = 8


def _point_arrays(locs: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(node, prev, remaining, remaining_m)`` arrays of a sequence of ints and points."""
    if isinstance(locs, np.ndarray) and locs.dtype.kind in "iu":
        node = locs.astype(np.int64).reshape(-1)
        z = np.zeros(node.size)
        return node, np.full(node.size, -1, dtype=np.int64), z, z
    if all(type(loc) is int for loc in locs):  # the common case: everyone stands on a node
        node = np.fromiter(locs, np.int64, len(locs))
        z = np.zeros(node.size)
        return node, np.full(node.size, -1, dtype=np.int64), z, z
    pts = [_as_point(loc) for loc in locs]
    node = np.fromiter((p.node for p in pts), np.int64, len(pts))
    prev = np.fromiter((p.prev for p in pts), np.int64, len(pts))
    rem = np.fromiter((max(p.remaining, 0.0) for p in pts), np.float64, len(pts))
    rem_m = np.fromiter((max(p.remaining_m, 0.0) for p in pts), np.float64, len(pts))
    return node, prev, rem, rem_m


# ==================================================================== a generated grid
def manhattan(columns: int, rows: int, block: float = 200.0, speed: float = 10.0) -> RoadNetwork:
    """A grid of ``columns x rows`` intersections: node ``row * columns + column`` at
    ``(column * block, row * block)`` metres, two-way streets of ``block`` metres between
    4-neighbours, each driven in ``block / speed`` seconds."""
    if columns < 1 or rows < 1:
        raise ValueError(f"manhattan: need at least 1 x 1 intersections, got {columns} x {rows}")
    if not (np.isfinite(block) and block > 0 and np.isfinite(speed) and speed > 0):
        raise ValueError(f"manhattan: block and speed must be positive, got {block!r}, {speed!r}")
    idx = np.arange(columns * rows, dtype=np.int64).reshape(rows, columns)
    xy = np.column_stack([(idx % columns).ravel() * block, (idx // columns).ravel() * block])
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    u, v = np.concatenate([a, b]), np.concatenate([b, a])
    seconds, metres = np.full(u.size, block / speed), np.full(u.size, float(block))
    return RoadNetwork.from_edges(f"manhattan-{columns}x{rows}", xy, np.arange(columns * rows),
                                  u, v, seconds=seconds, metres=metres)


#: generated grids, kept as files' networks are (validation and the run share one; immutable)
_grid = functools.lru_cache(maxsize=4)(manhattan)


# ==================================================================== load by name
@functools.lru_cache(maxsize=4)
def _load_file(path: str, mtimes: tuple[int, int], name: str | None) -> RoadNetwork:
    """One network per (file, modification times): edited files are read again."""
    return RoadNetwork.from_graph(read_graph(Path(path), name))


def load_network(source: str, *, base: Path, blocks: Sequence[int] = (20, 20), block: float = 200.0,
                 speed: float = 10.0) -> RoadNetwork:
    """The network a scenario names: ``"manhattan"`` (``blocks = [columns, rows]`` intersections,
    ``block`` metres apart, driven at ``speed`` m/s), a network shipped with the package
    (``"chicago"``: Chicago Regional; ``"manhattan_osm"``: Manhattan's OSMnx street network), or
    a file relative to ``base`` (see :func:`dispatch.files.roads.locate`). Files are read once
    per (resolved path, modification time), up to four kept; grids likewise built once. ValueError with a one-line message
    naming the file for a missing file or an unknown suffix."""
    if source == "manhattan":
        columns, rows = (int(b) for b in blocks)
        return _grid(columns, rows, block, speed)
    path, name, mtimes = locate(source, base)
    return _load_file(str(path), mtimes, name)
