"""The road-network space against independent answers: scipy's Dijkstra on the same CSR
matrices, networkx on an independent parse of the Chicago files, brute-force nearest nodes."""

from __future__ import annotations

import os
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components, dijkstra

from dispatch.api.legs import Leg, RoadPoint
from dispatch.files.roads import MILE, MPH, US_SURVEY_FOOT, chicago_files, read_graphml, read_tntp
from dispatch.space.roads import RoadNetwork, load_network, manhattan

SHARED = Path("/work/shared/data/roads/chicago_regional")


@pytest.fixture(scope="module")
def chicago() -> RoadNetwork:
    return load_network("chicago", base=Path("."))


def _edge(net: RoadNetwork, u: int, v: int) -> tuple[float, float]:
    """Edge seconds and metres read straight from the CSR matrices (not through net.edge)."""
    return float(net.time[u, v]), float(net.length[u, v])


def _mid_edge_points(net: RoadNetwork, rng: np.random.Generator, k: int) -> list[RoadPoint]:
    """``k`` random points part-way along random edges."""
    coo = net.time.tocoo()
    pick = rng.integers(0, coo.nnz, k)
    frac = rng.uniform(0.05, 0.95, k)
    return [RoadPoint(int(coo.col[e]), int(coo.row[e]), float(f * coo.data[e]),
                      float(f * net.length[coo.row[e], coo.col[e]])) for e, f in zip(pick, frac)]


# ---------------------------------------------------------------- Manhattan
def test_manhattan_ids_positions_and_edges():
    net = manhattan(5, 3, block=100.0, speed=5.0)
    assert net.n == 15 and net.kind == "road" and net.crs is None
    assert list(net.ids) == list(range(15))
    for row in range(3):
        for col in range(5):
            assert net.position(row * 5 + col) == (col * 100.0, row * 100.0, 0.0)
    # 4-neighbour streets, both ways: rows * (columns - 1) + columns * (rows - 1) pairs
    assert net.n_edges == 2 * (3 * 4 + 5 * 2)
    assert net.edge(0, 1) == (20.0, 100.0) and net.edge(6, 1) == (20.0, 100.0)
    with pytest.raises(ValueError, match="no edge 0 -> 6"):
        net.edge(0, 6)
    assert net.index_of(7) == 7 and net.index_of("7") == 7 and net.index_of(np.int64(7)) == 7
    with pytest.raises(ValueError, match="no node 99"):
        net.index_of(99)
    d = net.describe()
    assert d["dispatch.space"] == "road" and d["dispatch.nodes"] == "15"
    assert d["dispatch.edges"] == str(net.n_edges)
    with pytest.raises(ValueError, match="no CRS"):
        net.lonlat_to_xy(0.0, 0.0)


def test_load_network_manhattan_uses_blocks_as_columns_rows():
    net = load_network("manhattan", base=Path("."), blocks=(4, 2), block=50.0, speed=10.0)
    assert net.n == 8 and net.position(7) == (150.0, 50.0, 0.0) and net.edge(3, 7) == (5.0, 50.0)


# ---------------------------------------------------------------- travel times
@pytest.mark.parametrize("which", ["manhattan", "chicago"])
@pytest.mark.parametrize("shape", [(40, 7), (7, 40)])  # forward and backward strategies
def test_travel_times_equal_scipy_dijkstra(which, shape, chicago):
    net = chicago if which == "chicago" else manhattan(12, 9, block=150.0, speed=7.0)
    rng = np.random.default_rng(11 if which == "chicago" else 12)
    ns, nt = shape
    sources: list = [int(x) for x in rng.integers(0, net.n, ns - ns // 2)]
    sources += _mid_edge_points(net, rng, ns // 2)
    sources.append(sources[0])  # a repeated source node
    targets = [int(x) for x in rng.integers(0, net.n, nt)] + [sources[1]]
    got = net.travel_times(sources, targets)

    nodes = [s.node if isinstance(s, RoadPoint) else s for s in sources]
    rem = np.array([s.remaining if isinstance(s, RoadPoint) else 0.0 for s in sources])
    want = dijkstra(net.time, indices=nodes)[:, targets] + rem[:, None]
    assert got.shape == (ns + 1, nt + 1)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
    assert np.isfinite(got).all()  # strongly connected
    np.testing.assert_allclose(net.distance_to(targets[0]),
                               dijkstra(net.time.T.tocsr(), indices=targets[0]), rtol=1e-12)


def test_chicago_travel_times_match_networkx_on_an_independent_parse(chicago):
    """Read the shipped files with plain Python, route with networkx: same seconds."""
    net_file, node_file = chicago_files()
    g = nx.DiGraph()
    past_meta = False
    for line in net_file.read_text().splitlines():
        if "<END OF METADATA>" in line:
            past_meta = True
            continue
        f = line.replace(";", " ").split()
        if not past_meta or not f or f[0].startswith("~"):
            continue
        a, b, length, fft, speed = int(f[0]), int(f[1]), float(f[3]), float(f[4]), float(f[7])
        if a < 1791 or b < 1791:
            continue
        t = fft * 60 if fft > 0 else length * MILE / (speed * MPH)
        if not g.has_edge(a, b) or g[a][b]["t"] > t:
            g.add_edge(a, b, t=t)
    assert max(len(c) for c in nx.strongly_connected_components(g)) == chicago.n
    rng = np.random.default_rng(5)
    ids = np.asarray(chicago.ids)
    src = [int(ids[i]) for i in rng.integers(0, chicago.n, 2)]
    tgt = [int(ids[i]) for i in rng.integers(0, chicago.n, 30)]
    got = chicago.travel_times([chicago.index_of(s) for s in src],
                               [chicago.index_of(t) for t in tgt])
    for i, s in enumerate(src):
        dist = nx.single_source_dijkstra_path_length(g, s, weight="t")
        np.testing.assert_allclose(got[i], [dist[t] for t in tgt], rtol=1e-9)


# ---------------------------------------------------------------- routes and legs
def test_route_legs_are_edge_paths_with_cumulative_times(chicago):
    rng = np.random.default_rng(3)
    starts: list = [int(x) for x in rng.integers(0, chicago.n, 4)]
    starts += _mid_edge_points(chicago, rng, 4)
    goals = [int(x) for x in rng.integers(0, chicago.n, 8)]
    expect = chicago.travel_times(starts, goals)
    for i, (start, goal) in enumerate(zip(starts, goals)):
        leg = chicago.route(start, goal)
        p = start if isinstance(start, RoadPoint) else RoadPoint(start)
        assert leg.nodes[0] == p.node and leg.nodes[-1] == goal
        steps = [_edge(chicago, int(u), int(v)) for u, v in zip(leg.nodes[:-1], leg.nodes[1:])]
        assert all(s > 0 for s, _ in steps)  # every step is an edge
        secs = np.concatenate([[0.0], np.cumsum([s for s, _ in steps])])
        metres = np.concatenate([[0.0], np.cumsum([m for _, m in steps])])
        np.testing.assert_allclose(leg.times, p.remaining + secs)
        np.testing.assert_allclose(leg.metres, p.remaining_m + metres)
        assert leg.seconds == pytest.approx(expect[i, i], rel=1e-12)
        assert chicago.path_metres(start, goal) == pytest.approx(leg.length)
        assert leg.prev == (p.prev if not p.on_node else -1)
    assert chicago.route(5, 5).nodes.tolist() == [5]


def test_leg_rejects_non_edges_and_wrong_start():
    net = manhattan(3, 3)
    with pytest.raises(ValueError, match="no edge 0 -> 4"):
        net.leg(0, [0, 4])
    with pytest.raises(ValueError, match="must start"):
        net.leg(RoadPoint(1, 0, 5.0, 50.0), [0, 1])


def test_point_at_interpolates_along_the_current_edge():
    net = manhattan(3, 1, block=200.0, speed=10.0)  # 0 -- 1 -- 2, 20 s a block
    leg = net.leg(0, [0, 1, 2])
    assert leg.seconds == 40.0 and leg.length == 400.0
    assert leg.point_at(-1.0) == RoadPoint(0)
    assert leg.point_at(0.0) == RoadPoint(0)
    assert leg.point_at(5.0) == RoadPoint(1, 0, 15.0, 150.0)
    assert leg.point_at(20.0) == RoadPoint(1)
    assert leg.point_at(30.0) == RoadPoint(2, 1, 10.0, 100.0)
    assert leg.point_at(40.0) == RoadPoint(2) == leg.point_at(1e9)
    assert net.position(leg.point_at(5.0)) == pytest.approx((50.0, 0.0, 0.0))
    assert net.position(leg.point_at(30.0)) == pytest.approx((300.0, 0.0, 0.0))

    # a leg that starts part-way along 0 -> 1, 10 s (100 m) before node 1
    mid = net.leg(RoadPoint(1, 0, 10.0, 100.0), [1, 2])
    assert mid.times.tolist() == [10.0, 30.0] and mid.metres.tolist() == [100.0, 300.0]
    assert mid.point_at(4.0) == RoadPoint(1, 0, 6.0, 60.0)
    assert net.position(mid.point_at(4.0)) == pytest.approx((140.0, 0.0, 0.0))
    assert mid.point_at(10.0) == RoadPoint(1)
    assert mid.point_at(20.0) == RoadPoint(2, 1, 10.0, 100.0)
    assert isinstance(mid, Leg) and RoadPoint(3).on_node and not RoadPoint(1, 0, 1.0).on_node


def test_positions_vectorized_equal_position(chicago):
    rng = np.random.default_rng(8)
    locs: list = [int(x) for x in rng.integers(0, chicago.n, 5)] + _mid_edge_points(chicago, rng, 5)
    got = chicago.positions(locs)
    assert got.shape == (10, 3)
    for row, loc in zip(got, locs):
        assert tuple(row) == pytest.approx(chicago.position(loc))
    # a mid-edge point lies on the segment prev -> node at the driven fraction
    p = locs[-1]
    full, _ = _edge(chicago, p.prev, p.node)
    want = chicago.xy[p.node] + (p.remaining / full) * (chicago.xy[p.prev] - chicago.xy[p.node])
    np.testing.assert_allclose(got[-1, :2], want)
    ints = np.array(locs[:5])
    np.testing.assert_array_equal(chicago.positions(ints), got[:5])


# ---------------------------------------------------------------- GraphML
def test_graphml_round_trip(tmp_path):
    g = nx.MultiDiGraph(crs="EPSG:32616")
    for k, (x, y) in {"a": (0, 0), "b": (100, 0), "c": (100, 50)}.items():
        g.add_node(k, x=float(x), y=float(y))
    g.add_edge("a", "b", length=100.0, travel_time=12.0, speed=50.0)  # travel_time wins
    g.add_edge("a", "b", length=130.0, travel_time=9.0)  # faster parallel edge: kept, its length
    g.add_edge("b", "c", length=50.0, speed=5.0)  # 10 s
    g.add_edge("c", "a", length=120.0, speed=4.0)  # 30 s
    path = tmp_path / "tiny.graphml"
    nx.write_graphml(g, path)
    net = RoadNetwork.from_graph(read_graphml(path))
    a, b, c = (net.index_of(k) for k in "abc")
    assert net.crs == "EPSG:32616" and net.name == "tiny" and net.n == 3
    assert net.edge(a, b) == (9.0, 130.0)
    assert net.edge(b, c) == (10.0, 50.0) and net.edge(c, a) == (30.0, 120.0)
    assert net.n_edges == 3
    assert net.position(c) == (100.0, 50.0, 0.0)
    assert load_network("tiny.graphml", base=tmp_path).edge(a, b) == (9.0, 130.0)


def test_graphml_undirected_gets_both_directions(tmp_path):
    g = nx.Graph()
    g.add_node(1, x=0.0, y=0.0)
    g.add_node(2, x=30.0, y=40.0)
    g.add_edge(1, 2, length=50.0, speed=10.0)
    path = tmp_path / "u.graphml"
    nx.write_graphml(g, path)
    net = RoadNetwork.from_graph(read_graphml(path))
    assert net.crs is None and net.ids == ["1", "2"]
    assert net.edge(0, 1) == (5.0, 50.0) == net.edge(1, 0)
    assert net.index_of(2) == 1


@pytest.mark.parametrize("edit, attr", [
    ({"speed": -3.0}, "speed"),
    ({"travel_time": float("inf")}, "travel_time"),
    ({"travel_time": 0.0}, "travel_time"),
    ({"length": None}, "length"),
    ({"speed": None}, "travel_time"),
])
def test_graphml_bad_edge_attribute_names_it(tmp_path, edit, attr):
    g = nx.DiGraph()
    g.add_node("p", x=0.0, y=0.0)
    g.add_node("q", x=1.0, y=0.0)
    data = {"length": 10.0, "speed": 2.0}
    data.update(edit)
    g.add_edge("p", "q", **{k: v for k, v in data.items() if v is not None})
    g.add_edge("q", "p", length=10.0, speed=2.0)
    path = tmp_path / "bad.graphml"
    nx.write_graphml(g, path)
    with pytest.raises(ValueError, match=rf"bad\.graphml: edge 'p' -> 'q': .*'{attr}'"):
        read_graphml(path)


def test_graphml_missing_node_coordinate(tmp_path):
    g = nx.DiGraph()
    g.add_node("p", x=0.0)
    path = tmp_path / "nox.graphml"
    nx.write_graphml(g, path)
    with pytest.raises(ValueError, match=r"nox\.graphml: node 'p': missing attribute 'y'"):
        read_graphml(path)


# ---------------------------------------------------------------- TNTP
NET = """<NUMBER OF ZONES> 2
<NUMBER OF NODES> 6
<FIRST THRU NODE> 3
<NUMBER OF LINKS> 9
<END OF METADATA>


~\tinit_node\tterm_node\tcapacity\tlength\tfree_flow_time\tb\tpower\tspeed\ttoll\tlink_type\t;
\t1\t3\t1000\t0.5\t0\t0.15\t4\t25\t0\t3\t;
\t3\t1\t1000\t0.5\t0\t0.15\t4\t25\t0\t3\t;
\t2\t6\t1000\t0.5\t0\t0.15\t4\t25\t0\t3\t;
\t3\t4\t1000\t1.0\t2.0\t0.15\t4\t30\t0\t1\t;
\t4\t3\t1000\t1.0\t0\t0.15\t4\t30\t0\t1\t;
\t4\t5\t1000\t2.0\t3.0\t0.15\t4\t40\t0\t2\t;
\t5\t3\t1000\t0.5\t1.5\t0.15\t4\t20\t0\t1\t;
\t5\t6\t1000\t0.25\t1.0\t0.15\t4\t20\t0\t1\t;
\t4\t5\t1000\t2.5\t2.5\t0.15\t4\t60\t0\t2\t;
"""
NODES = ("node\tX\tY\t;\n1\t0\t0\t;\n2\t3937\t0\t;\n3\t0\t3937\t;\n4\t3937\t3937\t;\n"
         "5\t7874\t0\t;\n6\t0\t7874\t;\n")


def _tiny_tntp(tmp_path: Path) -> Path:
    (tmp_path / "Tiny_net.tntp").write_text(NET)
    (tmp_path / "Tiny_node.tntp").write_text(NODES)
    return tmp_path / "Tiny_net.tntp"


def test_tntp_drops_zones_and_derives_zero_times(tmp_path, caplog):
    net_file = _tiny_tntp(tmp_path)
    with caplog.at_level("INFO", logger="dispatch.space.roads"):
        net = RoadNetwork.from_graph(read_tntp(net_file, tmp_path / "Tiny_node.tntp"))
    # zones 1, 2 dropped; node 6 (reached only by 5 -> 6, never left) is outside the largest SCC
    assert list(net.ids) == [3, 4, 5] and net.crs == "EPSG:26771" and net.name == "Tiny"
    assert "dropped 1" in caplog.text
    i3, i4, i5 = (net.index_of(k) for k in (3, 4, 5))
    assert net.edge(i3, i4) == pytest.approx((120.0, MILE))
    assert net.edge(i4, i3) == pytest.approx((MILE / (30 * MPH), MILE))  # free_flow_time 0
    assert net.edge(i4, i5) == pytest.approx((150.0, 2.5 * MILE))  # the faster parallel link
    np.testing.assert_allclose(net.xy[i4], [3937 * US_SURVEY_FOOT, 3937 * US_SURVEY_FOOT])
    assert net.xy[i4][0] == pytest.approx(1200.0)
    assert net.n_edges == 4


def test_load_network_finds_the_node_file_and_caches_per_mtime(tmp_path):
    net_file = _tiny_tntp(tmp_path)
    a = load_network("Tiny_net.tntp", base=tmp_path)
    assert load_network(str(net_file), base=Path("/")) is a
    st = net_file.stat()
    os.utime(net_file, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    b = load_network("Tiny_net.tntp", base=tmp_path)
    assert b is not a and b.n == a.n


@pytest.mark.parametrize("source, match", [
    ("nowhere.graphml", "nowhere.graphml: road network file not found"),
    ("roads.osm", "unknown road network format '.osm'"),
])
def test_load_network_errors_name_the_file(tmp_path, source, match):
    with pytest.raises(ValueError, match=match):
        load_network(source, base=tmp_path)


def test_tntp_without_its_node_file(tmp_path):
    (tmp_path / "Lone_net.tntp").write_text(NET)
    with pytest.raises(ValueError, match="Lone_node.tntp: TNTP node file not found"):
        load_network("Lone_net.tntp", base=tmp_path)


# ---------------------------------------------------------------- Chicago
def test_chicago_shipped_byte_for_byte_and_strongly_connected(chicago):
    net_file, node_file = chicago_files()
    for f in (net_file, node_file, net_file.with_name("ChicagoRegional_README.md")):
        if SHARED.is_dir():
            assert f.read_bytes() == (SHARED / f.name).read_bytes()
    notice = " ".join((net_file.parent / "NOTICE.md").read_text().replace("*", "").split())
    assert "academic research purposes only" in notice
    assert "d1639b4ef218c17928ba573e806ddf8ba5e7ae6d" in notice
    assert 11_000 <= chicago.n <= 11_300 and chicago.n == 11_180
    assert chicago.crs == "EPSG:26771" and chicago.name == "chicago"
    assert np.asarray(chicago.ids).min() >= 1791  # no zone centroid
    n_comp, _ = connected_components(chicago.time, directed=True, connection="strong")
    assert n_comp == 1
    assert (chicago.time.data > 0).all() and (chicago.length.data >= 0).all()
    assert load_network("chicago", base=Path(".")) is chicago  # cached


def test_willis_tower_snaps_to_a_node_within_a_km(chicago):
    xy = chicago.lonlat_to_xy(-87.6359, 41.8789)
    idx, dist = chicago.nearest(xy)
    assert xy.shape == (1, 2) and dist[0] < 1000.0
    assert np.hypot(*(chicago.xy[idx[0]] - xy[0])) == pytest.approx(dist[0])


def test_nearest_equals_brute_force(chicago):
    rng = np.random.default_rng(21)
    lo, hi = chicago.xy.min(axis=0), chicago.xy.max(axis=0)
    pts = rng.uniform(lo, hi, (200, 2))
    idx, dist = chicago.nearest(pts)
    d = np.linalg.norm(pts[:, None, :] - chicago.xy[None, :, :], axis=2)
    np.testing.assert_allclose(dist, d.min(axis=1))
    np.testing.assert_allclose(d[np.arange(200), idx], d.min(axis=1))


def test_positions_point_by_point_equal_vectorized_bit_for_bit(chicago):
    """A short list (the per-vehicle calls of a decision) takes a pure-Python path; it must
    give exactly the floats of the vectorized path, edge starts and ends included."""
    from dispatch.space.roads import _FEW_POINTS

    rng = np.random.default_rng(11)
    pts = _mid_edge_points(chicago, rng, 200)
    ends = [RoadPoint(p.node, p.prev, 1e9, 0.0) for p in pts[:5]]  # past the edge: clipped
    locs: list = pts + ends + [RoadPoint(p.node, p.prev, 0.0) for p in pts[:5]] \
        + [int(x) for x in rng.integers(0, chicago.n, 5)]
    assert len(locs) > _FEW_POINTS
    many = chicago.positions(locs)
    one = np.vstack([chicago.positions([loc]) for loc in locs])
    assert one.shape == many.shape and np.array_equal(one, many)
    few = chicago.positions(locs[:_FEW_POINTS])
    assert np.array_equal(few, many[:_FEW_POINTS])
    np.testing.assert_array_equal(chicago.positions(ends[:1])[0, :2], chicago.xy[ends[0].prev])
    with pytest.raises(ValueError, match="no edge"):
        chicago.positions([RoadPoint(int(pts[0].node), int(pts[0].node), 3.0)])


def _point_at_numpy(leg: Leg, t: float) -> RoadPoint:
    """Leg.point_at as it was written on the arrays (the reference for the list version)."""
    times, nodes = leg.times, leg.nodes
    if t >= times[-1]:
        return RoadPoint(int(nodes[-1]))
    t = max(float(t), 0.0)
    i = int(np.searchsorted(times, t, side="right"))
    if i == 0:
        rem = float(times[0]) - t
        return RoadPoint(int(nodes[0]), leg.prev, rem, float(leg.metres[0]) * rem / float(times[0]))
    if t == times[i - 1]:
        return RoadPoint(int(nodes[i - 1]))
    span = float(times[i] - times[i - 1])
    rem = float(times[i]) - t
    return RoadPoint(int(nodes[i]), int(nodes[i - 1]), rem,
                     float(leg.metres[i] - leg.metres[i - 1]) * rem / span)


def test_point_at_equals_the_array_computation_bit_for_bit(chicago):
    """point_at works on cached Python lists; every field must equal the numpy computation
    exactly, at node arrival times, between them, before the start and past the end."""
    rng = np.random.default_rng(12)
    starts = _mid_edge_points(chicago, rng, 20) + [int(x) for x in rng.integers(0, chicago.n, 20)]
    checked = 0
    for start in starts:
        goal = int(rng.integers(0, chicago.n))
        leg = chicago.route(start, goal)
        if leg is None or leg.nodes.size < 2:
            continue
        ts = np.r_[-1.0, 0.0, leg.times, leg.times[-1] + 5.0,
                   rng.uniform(0.0, leg.seconds, 30)]
        for t in ts.tolist():
            got, want = leg.point_at(t), _point_at_numpy(leg, t)
            assert got == want and type(got.node) is int and type(got.prev) is int
            checked += 1
    assert checked > 500
