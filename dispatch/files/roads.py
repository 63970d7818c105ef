"""Road network files: the formats a road network comes in, read into a :class:`RoadGraph`
(the file's nodes and directed edges, as the file gives them), which
:meth:`dispatch.space.roads.RoadNetwork.from_graph` turns into the road space.

* :func:`read_graphml` and :func:`read_node_link`: a graph as OSMnx users have it, GraphML
  (``ox.save_graphml``) or networkx node-link JSON (``nx.node_link_data``; ``.gz`` too), with
  ``x``/``y`` per node and per edge ``length`` metres plus ``travel_time`` seconds or a speed
  (``speed_kph`` / ``speed_kmph`` km/h, ``speed`` m/s). An unprojected graph (``crs``
  EPSG:4326, x = longitude, y = latitude) is projected to its local UTM zone; a projected one
  keeps its CRS. The Manhattan street network of OSMnx ships with the package
  (``manhattan_osm``, see ``dispatch/data/nyc_manhattan/README.md``, BSD);
* :func:`read_tntp`: the TNTP format of the Transportation Networks for Research project; the
  Chicago Regional network ships with the package (``chicago``, see
  ``dispatch/data/chicago_regional/NOTICE.md`` for its academic-only licence).

:func:`locate` finds the file a scenario's ``world.network`` names (a shipped network or a
path) and :func:`read_graph` reads it by its suffix. Every malformed input is a ValueError
naming the file (and the node, edge or attribute). Nothing here imports ``dispatch``.
"""

from __future__ import annotations

import difflib

import importlib.resources
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

#: Metres per unit of the source formats.
MILE = 1609.344
MPH = 0.44704
US_SURVEY_FOOT = 1200.0 / 3937.0
#: The CRS of the Chicago Regional node coordinates (NAD27 / Illinois East, US survey feet).
CHICAGO_CRS = "EPSG:26771"

_CHICAGO_DIR = "data/chicago_regional"
_CHICAGO_NET = "ChicagoRegional_net.tntp"
_NYC_DIR = "data/nyc_manhattan"
_NYC_NET = "manhattan_osm_network.json.gz"
#: a graph file's suffixes (lower case) and its reader; ``.gz``: gzip-compressed
GRAPH_SUFFIXES = (".graphml", ".graphml.gz", ".json", ".json.gz")
#: km/h per m/s
KPH = 1 / 3.6
#: OSMnx rounds ``travel_time`` to 0.1 s: a 0 there is accepted where length / speed is below
#: half of that (the unrounded time is used instead)
OSMNX_TIME_PRECISION = 0.1


@dataclass(frozen=True, eq=False)
class RoadGraph:
    """A road network as a file gives it: node positions ``xy`` (``(n, 2)`` metres, in the
    ``crs`` frame, None: plain metres) and source ids ``ids`` (an int64 array or a list of
    strings), and directed edges ``u[k] -> v[k]`` (node indices) of ``seconds`` and ``metres``
    (positive, finite seconds; non-negative metres). Self-loops, parallel edges and nodes
    outside the largest strongly connected component are still there:
    :meth:`dispatch.space.roads.RoadNetwork.from_graph` drops them."""

    name: str
    xy: np.ndarray
    ids: Any
    u: np.ndarray
    v: np.ndarray
    seconds: np.ndarray
    metres: np.ndarray
    crs: str | None = None

def _positive(file: Path, what: str, attr: str, value: Any, zero_ok: bool = False) -> float:
    """``value`` as a finite float, > 0 (or >= 0 with ``zero_ok``); ValueError naming it."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{file}: {what}: attribute {attr!r} is not a number: {value!r}") from None
    if not np.isfinite(x) or x < 0 or (x == 0 and not zero_ok):
        need = "non-negative" if zero_ok else "positive"
        raise ValueError(f"{file}: {what}: attribute {attr!r} must be finite and {need}, "
                         f"got {value!r}")
    return x


#: edge attributes that give a speed, in the order they are looked for, and m/s per unit
SPEED_ATTRS = (("speed_kph", KPH), ("speed_kmph", KPH), ("speed", 1.0))


def _edge_seconds(file: Path, what: str, data: dict) -> tuple[float, float]:
    """``(seconds, metres)`` of one edge's attributes: ``length`` metres (required, may be 0)
    and ``travel_time`` seconds, else ``length`` over the first speed of :data:`SPEED_ATTRS`.
    A ``travel_time`` of 0 is taken for OSMnx's rounding (to 0.1 s) of a very short edge where
    a speed says so (length / speed < 0.05 s: that time is used); otherwise ValueError naming
    the file, the edge and the attribute."""
    if data.get("length") is None:
        raise ValueError(f"{file}: {what}: missing attribute 'length'")
    m = _positive(file, what, "length", data["length"], zero_ok=True)
    speed = next(((a, f) for a, f in SPEED_ATTRS if data.get(a) is not None), None)
    if data.get("travel_time") is not None:
        s = _positive(file, what, "travel_time", data["travel_time"], zero_ok=True)
        if s > 0:
            return s, m
        if speed is not None and m > 0:
            unrounded = m / (_positive(file, what, speed[0], data[speed[0]]) * speed[1])
            if unrounded < OSMNX_TIME_PRECISION / 2:
                return unrounded, m
        raise ValueError(f"{file}: {what}: attribute 'travel_time' must be finite and "
                         f"positive, got {data['travel_time']!r}")
    if speed is None:
        raise ValueError(f"{file}: {what}: missing attribute 'travel_time' (or a speed: "
                         f"{', '.join(a for a, _ in SPEED_ATTRS)})")
    s = m / (_positive(file, what, speed[0], data[speed[0]]) * speed[1])
    if s <= 0:
        raise ValueError(f"{file}: {what}: 'length' 0 with a '{speed[0]}' gives a zero time; "
                         "give a positive 'travel_time'")
    return s, m


def utm_crs(lon: np.ndarray, lat: np.ndarray) -> str:
    """The WGS 84 / UTM zone CRS (``"EPSG:326zz"`` north, ``"EPSG:327zz"`` south) of the area
    the points span, as pyproj's database gives it (its special zones included)."""
    from pyproj.aoi import AreaOfInterest
    from pyproj.database import query_utm_crs_info

    west, east = float(np.min(lon)), float(np.max(lon))
    south, north = float(np.min(lat)), float(np.max(lat))
    found = query_utm_crs_info(datum_name="WGS 84",
                               area_of_interest=AreaOfInterest(west, south, east, north))
    if found:  # the zone of the area's centre when it spans several
        mid_lon = (west + east) / 2
        zone = int((mid_lon + 180) // 6) % 60 + 1
        code = (32600 if (south + north) / 2 >= 0 else 32700) + zone
        best = next((c for c in found if c.code == str(code)), found[0])
        return f"{best.auth_name}:{best.code}"
    zone = int(((west + east) / 2 + 180) // 6) % 60 + 1  # outside the database's areas
    return f"EPSG:{(32600 if (south + north) >= 0 else 32700) + zone}"


def _is_lonlat(crs: Any) -> bool:
    """True when ``crs`` (any pyproj input) is geographic: coordinates are degrees."""
    from pyproj import CRS

    return bool(CRS.from_user_input(crs).is_geographic)


def _project(file: Path, xy: np.ndarray, crs: Any) -> tuple[np.ndarray, str | None]:
    """Node coordinates in metres and the CRS they are in: a geographic ``crs`` (x =
    longitude, y = latitude degrees) is projected to the local UTM zone; a projected one is
    kept (its unit converted to metres); no CRS: metres as given, with a warning when the
    coordinates look like degrees."""
    if not crs:
        if xy.size and np.all(np.abs(xy[:, 0]) <= 180) and np.all(np.abs(xy[:, 1]) <= 90) \
                and float(np.ptp(xy, axis=0).max()) < 5:
            log.warning("%s: no 'crs' graph attribute and coordinates within a few units: read "
                        "as metres; if they are longitude / latitude, add crs = 'epsg:4326'",
                        file)
        return xy, None
    try:
        geographic = _is_lonlat(crs)
    except Exception as e:  # noqa: BLE001 - pyproj raises its own CRSError
        raise ValueError(f"{file}: graph attribute 'crs' = {crs!r} is not a CRS pyproj knows "
                         f"({e})") from None
    if not geographic:
        from pyproj import CRS

        c = CRS.from_user_input(crs)
        unit = c.axis_info[0].unit_conversion_factor if c.axis_info else 1.0
        return xy * float(unit), str(crs)
    bad = (np.abs(xy[:, 0]) > 180) | (np.abs(xy[:, 1]) > 90)
    if bad.any():
        raise ValueError(f"{file}: crs {crs!r} says x, y are longitude, latitude degrees, but a "
                         f"node is at ({xy[bad][0, 0]!r}, {xy[bad][0, 1]!r})")
    from pyproj import Transformer

    target = utm_crs(xy[:, 0], xy[:, 1])
    transformer = Transformer.from_crs(crs, target, always_xy=True)
    x, y = transformer.transform(xy[:, 0], xy[:, 1])
    return np.column_stack([x, y]), target


def _graph_network(file: Path, name: str, nodes: list[tuple[Any, dict]],
                   edges: Any, directed: bool, crs: Any) -> RoadGraph:
    """A graph from a graph file's records (GraphML and node-link JSON share this): ``nodes`` as
    ``(key, attributes)`` with ``x``/``y``, ``edges`` as ``(u key, v key, attributes)`` (see
    :func:`_edge_seconds`; a multigraph's parallel edges all given: the fastest is kept), both
    directions of an undirected graph's edges; coordinates projected by :func:`_project`."""
    index: dict[Any, int] = {}
    xy = np.empty((len(nodes), 2))
    for i, (k, data) in enumerate(nodes):
        if k in index:
            raise ValueError(f"{file}: node {k!r} appears twice")
        index[k] = i
        for j, attr in enumerate(("x", "y")):
            if data.get(attr) is None:
                raise ValueError(f"{file}: node {k!r}: missing attribute {attr!r}")
            try:
                xy[i, j] = float(data[attr])
            except (TypeError, ValueError):
                raise ValueError(f"{file}: node {k!r}: attribute {attr!r} is not a number: "
                                 f"{data[attr]!r}") from None
            if not np.isfinite(xy[i, j]):
                raise ValueError(f"{file}: node {k!r}: attribute {attr!r} is not finite: "
                                 f"{data[attr]!r}")
    u, v, sec, met = [], [], [], []
    for a, b, data in edges:
        what = f"edge {a!r} -> {b!r}"
        for end in (a, b):
            if end not in index:
                raise ValueError(f"{file}: {what}: no node {end!r}")
        s, m = _edge_seconds(file, what, data)
        u.append(index[a]), v.append(index[b]), sec.append(s), met.append(m)
    u_a, v_a = np.array(u, dtype=np.int64), np.array(v, dtype=np.int64)
    sec_a, met_a = np.array(sec, dtype=np.float64), np.array(met, dtype=np.float64)
    if not directed:
        u_a, v_a = np.concatenate([u_a, v_a]), np.concatenate([v_a, u_a])
        sec_a, met_a = np.tile(sec_a, 2), np.tile(met_a, 2)
    xy, crs_out = _project(file, xy, crs)
    keys = [k for k, _ in nodes]
    ids: Any = (np.array(keys, dtype=np.int64)
                if keys and all(type(k) is int for k in keys) else [str(k) for k in keys])
    return RoadGraph(name, xy, ids, u_a, v_a, sec_a, met_a, crs_out)


def _stem(path: Path) -> str:
    """A graph file's name without its suffixes (``city.graphml.gz`` -> ``city``)."""
    name = path.name
    if name.lower().endswith(".gz"):
        name = name[:-3]
    return name.rsplit(".", 1)[0] if "." in name else name


def _open(path: Path):
    """A binary file handle, decompressed when the name ends in ``.gz``."""
    if path.name.lower().endswith(".gz"):
        import gzip

        return gzip.open(path, "rb")
    return open(path, "rb")


def read_graphml(path: str | Path, *, name: str | None = None) -> RoadGraph:
    """A graph from GraphML (``.graphml`` or ``.graphml.gz``), e.g. ``ox.save_graphml``'s:
    node ``x``/``y``, edge ``length`` (metres) and ``travel_time`` (seconds) or a speed
    (``speed_kph`` / ``speed_kmph`` km/h, ``speed`` m/s; ``travel_time`` wins); attribute
    values may be strings, as OSMnx writes them. Undirected graphs get both directions; of a
    multigraph's parallel edges the fastest is kept. The graph attribute ``crs`` says what x/y
    are: geographic (``epsg:4326``: longitude, latitude) is projected to the local UTM zone,
    anything else is kept; without it x/y are metres. A missing, non-numeric, non-finite or
    non-positive attribute raises ValueError naming the file, the node or edge and the
    attribute (a ``length`` may be 0; a ``travel_time`` may not, see :func:`_edge_seconds`)."""
    import networkx as nx

    path = Path(path)
    with _open(path) as fh:
        g = nx.read_graphml(fh)
    edges = g.edges(data=True)
    return _graph_network(path, name or _stem(path), list(g.nodes(data=True)), edges,
                          g.is_directed(), g.graph.get("crs"))


def read_node_link(path: str | Path, *, name: str | None = None) -> RoadGraph:
    """A graph from networkx node-link JSON (``.json`` or ``.json.gz``: what
    ``json.dump(nx.node_link_data(G), f)`` writes of an OSMnx graph): ``directed``, ``graph``
    (its ``crs``), ``nodes`` (each with ``id``, ``x``, ``y``) and ``links`` (or ``edges``; each
    with ``source``, ``target`` and the attributes :func:`read_graphml` reads). Read directly,
    without networkx; the same rules and errors as :func:`read_graphml`."""
    import json

    path = Path(path)
    try:
        with _open(path) as fh:
            doc = json.load(fh)
    except (OSError, EOFError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not node-link JSON ({type(e).__name__}: {e})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("nodes"), list):
        raise ValueError(f"{path}: not node-link JSON (no 'nodes' list)")
    links = doc.get("links", doc.get("edges"))
    if not isinstance(links, list):
        raise ValueError(f"{path}: not node-link JSON (no 'links' or 'edges' list)")
    nodes = []
    for i, rec in enumerate(doc["nodes"]):
        if not isinstance(rec, dict) or "id" not in rec:
            raise ValueError(f"{path}: nodes[{i}] has no 'id'")
        k = rec["id"]
        nodes.append((k if isinstance(k, (int, str)) else str(k), rec))
    edges = []
    for i, rec in enumerate(links):
        if not isinstance(rec, dict) or "source" not in rec or "target" not in rec:
            raise ValueError(f"{path}: links[{i}] has no 'source' and 'target'")
        edges.append((rec["source"], rec["target"], rec))
    graph = doc.get("graph") if isinstance(doc.get("graph"), dict) else {}
    return _graph_network(path, name or _stem(path), nodes, edges,
                          bool(doc.get("directed", True)), graph.get("crs"))


def _tntp_table(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """``(metadata, column names, rows)`` of a TNTP file: ``<KEY> value`` lines up to
    ``<END OF METADATA>`` (if any), a header line (``~ a b c ;`` or ``a b c``), then
    whitespace-separated numeric rows, each optionally ending with ``;``."""
    text = path.read_text()
    meta: dict[str, str] = {}
    head, sep, body = text.partition("<END OF METADATA>")
    if sep:
        for line in head.splitlines():
            line = line.strip()
            if line.startswith("<") and ">" in line:
                key, _, value = line[1:].partition(">")
                meta[key.strip().upper()] = value.strip()
    else:
        body = text
    lines = body.splitlines()
    header_at = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if header_at is None:
        raise ValueError(f"{path}: no header line and no rows")
    columns = [c.lower() for c in lines[header_at].replace(";", " ").replace("~", " ").split()]
    if not columns or _is_number(columns[0]):
        raise ValueError(f"{path}: expected a header line naming the columns, got "
                         f"{lines[header_at].strip()!r}")
    rows = [ln for ln in lines[header_at + 1:] if ln.strip() and not ln.lstrip().startswith("~")]
    tokens = " ".join(rows).replace(";", " ").split()
    if len(tokens) % len(columns):
        counts = [len(r.replace(";", " ").split()) for r in rows]
        bad = next(i for i, c in enumerate(counts) if c != len(columns))
        raise ValueError(f"{path}: row {rows[bad].strip()!r} has {counts[bad]} values, "
                         f"expected {len(columns)} ({' '.join(columns)})")
    try:
        data = np.array(tokens, dtype=np.float64).reshape(-1, len(columns))
    except ValueError as e:
        raise ValueError(f"{path}: non-numeric value in the table: {e}") from None
    return meta, columns, data


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _column(path: Path, columns: list[str], data: np.ndarray, name: str) -> np.ndarray:
    if name not in columns:
        raise ValueError(f"{path}: no column {name!r} (columns: {' '.join(columns)})")
    return data[:, columns.index(name)]


def read_tntp(net_path: str | Path, node_path: str | Path, *, name: str | None = None,
              crs: str | None = CHICAGO_CRS) -> RoadGraph:
    """A graph from a TNTP link file and node file (see ``data/roads/PROVENANCE.txt``).

    Zone centroids (node numbers below ``<FIRST THRU NODE>``) and every link touching them are
    dropped. Lengths are miles, free-flow times minutes; where a free-flow time is 0 the time is
    length / speed (mph). Node X/Y are read in US survey feet (``crs`` EPSG:26771, the Chicago
    Regional frame) and stored in metres. ValueError naming the file for anything malformed
    (a link to a node the node file lacks, a link with neither a time nor a positive speed)."""
    net_path, node_path = Path(net_path), Path(node_path)
    meta, cols, links = _tntp_table(net_path)
    _, ncols, nodes = _tntp_table(node_path)
    first_thru = int(float(meta.get("FIRST THRU NODE", "1")))
    node_no = _column(node_path, ncols, nodes, "node").astype(np.int64)
    node_xy = np.column_stack([_column(node_path, ncols, nodes, "x"),
                               _column(node_path, ncols, nodes, "y")]) * US_SURVEY_FOOT
    a = _column(net_path, cols, links, "init_node").astype(np.int64)
    b = _column(net_path, cols, links, "term_node").astype(np.int64)
    miles = _column(net_path, cols, links, "length")
    minutes = _column(net_path, cols, links, "free_flow_time")
    mph = _column(net_path, cols, links, "speed")

    thru = node_no >= first_thru
    node_no, node_xy = node_no[thru], node_xy[thru]
    keep = (a >= first_thru) & (b >= first_thru)
    a, b, miles, minutes, mph = a[keep], b[keep], miles[keep], minutes[keep], mph[keep]
    log.debug("%s: dropped %d zone centroids and %d links touching them", net_path.name,
              int((~thru).sum()), int((~keep).sum()))

    order = np.argsort(node_no)
    sorted_no = node_no[order]
    if np.any(sorted_no[1:] == sorted_no[:-1]):
        raise ValueError(f"{node_path}: node numbers repeat")
    u, v = np.searchsorted(sorted_no, a), np.searchsorted(sorted_no, b)
    for ends, nums in ((u, a), (v, b)):
        at = np.minimum(ends, sorted_no.size - 1)
        missing = (ends >= sorted_no.size) | (sorted_no[at] != nums)
        if missing.any():
            raise ValueError(f"{net_path}: link node {int(nums[missing][0])} is not in "
                             f"{node_path.name}")
    u, v = order[u], order[v]

    metres = miles * MILE
    with np.errstate(divide="ignore", invalid="ignore"):
        seconds = np.where(minutes > 0, minutes * 60.0, metres / (mph * MPH))
    bad = ~(np.isfinite(seconds) & (seconds > 0) & np.isfinite(metres) & (metres >= 0))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{net_path}: link {int(a[k])} -> {int(b[k])}: no positive travel time "
                         f"(free_flow_time {minutes[k]!r}, length {miles[k]!r}, speed {mph[k]!r})")
    stem = net_path.name.removesuffix(".tntp").removesuffix("_net")
    return RoadGraph(name or stem, node_xy, node_no, u, v, seconds, metres, crs)


# ============================================================ shipped files, a scenario's file
def chicago_files() -> tuple[Path, Path]:
    """Paths of the shipped Chicago Regional link and node files."""
    root = importlib.resources.files("dispatch") / _CHICAGO_DIR
    net = Path(str(root / _CHICAGO_NET))
    return net, node_file(net)


def node_file(net: Path) -> Path:
    """``X_net.tntp`` -> ``X_node.tntp`` beside it."""
    stem = net.name.removesuffix(".tntp")
    if not stem.endswith("_net"):
        raise ValueError(f"{net}: a TNTP link file must be named X_net.tntp "
                         "(its node file X_node.tntp)")
    return net.with_name(stem.removesuffix("_net") + "_node.tntp")


def manhattan_osm_file() -> Path:
    """Path of the shipped Manhattan street network (OSMnx, node-link JSON, gzip; BSD, see
    ``dispatch/data/nyc_manhattan/README.md``)."""
    return Path(str(importlib.resources.files("dispatch") / _NYC_DIR / _NYC_NET))


#: networks shipped with the package, by the name a scenario gives them
SHIPPED = {"chicago": lambda: chicago_files()[0], "manhattan_osm": manhattan_osm_file}


def graph_suffix(path: Path) -> str | None:
    """The graph-file suffix of :data:`GRAPH_SUFFIXES` the name ends with, or None."""
    low = path.name.lower()
    return next((s for s in sorted(GRAPH_SUFFIXES, key=len, reverse=True) if low.endswith(s)),
                None)


def read_graph(path: Path, name: str | None = None) -> RoadGraph:
    """The graph of a network file, read by its suffix (:data:`GRAPH_SUFFIXES`: GraphML or
    node-link JSON; otherwise TNTP, ``X_net.tntp`` with its ``X_node.tntp`` beside it)."""
    suffix = graph_suffix(path)
    if suffix is not None and suffix.startswith(".graphml"):
        return read_graphml(path, name=name)
    if suffix is not None:
        return read_node_link(path, name=name)
    return read_tntp(path, node_file(path), name=name)


def locate(source: str, base: Path) -> tuple[Path, str | None, tuple[int, int]]:
    """Where a scenario's network file is: ``(path, name, modification times)``, ``source``
    being a shipped network's name (``"chicago"``, ``"manhattan_osm"``: named so) or a file
    relative to ``base`` (``.graphml``, node-link ``.json``, either ``.gz``, or ``X_net.tntp``;
    named by its file); the times (ns) are the file's and, for TNTP, its node file's (0
    otherwise). ValueError with a one-line message naming the file for a missing file or an
    unknown suffix."""
    if source in SHIPPED:
        path, name = SHIPPED[source](), source
    else:
        path, name = (Path(base) / source).resolve(), None
        if path.suffix.lower() != ".tntp" and graph_suffix(path) is None:
            suffix = path.suffix or "(no suffix)"
            # a name without a suffix is most likely a shipped network's, misspelt
            close = difflib.get_close_matches(source, ["manhattan", *SHIPPED], n=1)
            if not path.suffix and close:
                raise ValueError(f"{source!r} is neither a shipped network nor a file (did you "
                                 f"mean {close[0]!r}?); shipped: 'manhattan', "
                                 f"{', '.join(repr(k) for k in SHIPPED)}")
            raise ValueError(f"{path}: unknown road network format {suffix!r}; expected "
                             f"'manhattan', {', '.join(repr(k) for k in SHIPPED)}, a .graphml, "
                             "a node-link .json (or either .gz) or an X_net.tntp file")
    if not path.is_file():
        raise ValueError(f"{path}: road network file not found")
    node_mtime = 0
    if path.suffix.lower() == ".tntp":
        node = node_file(path)
        if not node.is_file():
            raise ValueError(f"{node}: TNTP node file not found (needed beside {path.name})")
        node_mtime = node.stat().st_mtime_ns
    return path, name, (path.stat().st_mtime_ns, node_mtime)
