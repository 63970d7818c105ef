"""Manhattan on its OSMnx street network with the NYC taxi requests of 2014-12-21.

The loaders against independent answers: the shipped node-link JSON read with networkx and
its own ``travel_time`` values (the fastest of parallel links), networkx's Dijkstra on that
graph, pyproj's projection of the nodes' longitudes / latitudes; GraphML as OSMnx writes it
(every attribute a string). Traces with ``o_lat, o_lon, d_lat, d_lon, departure_time``:
date-times read from ``[tasks] start``, trips farther than ``[tasks] max_snap`` from the
network left out with a count (brute-force nearest nodes), bad rows named by their row."""

from __future__ import annotations

import csv
import gzip
import json
import logging
from pathlib import Path

import networkx as nx
import numpy as np
import pyarrow.parquet as pq
import pytest
from pyproj import Transformer

from dispatch.errors import ScenarioError
from dispatch.files.roads import manhattan_osm_file, read_graphml, read_node_link
from dispatch.files.traces import shipped_trace
from dispatch.run.runner import run_metadata, run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import RoadNetwork, load_network

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data" / "nyc_manhattan"
START = "2014-12-21T00:00"
HEADER = ["request_id", "o_lat", "o_lon", "d_lat", "d_lon", "departure_time", "passengers"]
#: places in and around Manhattan (latitude, longitude)
TIMES_SQUARE = (40.7580, -73.9855)
UNION_SQUARE = (40.7359, -73.9911)
WALL_STREET = (40.7060, -74.0088)
HARLEM = (40.8116, -73.9465)
HOBOKEN = (40.7440, -74.0324)  # New Jersey, across the Hudson
PROSPECT_PARK = (40.6602, -73.9690)  # Brooklyn


@pytest.fixture(scope="module")
def doc() -> dict:
    with gzip.open(manhattan_osm_file(), "rt") as fh:
        return json.load(fh)


@pytest.fixture(scope="module")
def net():
    return load_network("manhattan_osm", base=ROOT)


def _fastest(doc: dict) -> dict[tuple[int, int], dict]:
    """The fastest link per (source, target) of the JSON, read independently."""
    best: dict[tuple[int, int], dict] = {}
    for link in doc["links"]:
        k = (link["source"], link["target"])
        if k not in best or link["travel_time"] < best[k]["travel_time"]:
            best[k] = link
    return best


# ---------------------------------------------------------------- the shipped network
def test_shipped_files_sit_with_their_licence_and_match_the_source(doc):
    folder = manhattan_osm_file().parent
    assert "BSD 3-Clause" in (folder / "LICENSE.txt").read_text()
    assert "LICENSE.txt" in (folder / "README.md").read_text()
    assert shipped_trace("nyc_taxi_2014-12-21").parent == folder
    if SHARED.is_dir():
        raw = gzip.decompress(manhattan_osm_file().read_bytes())
        assert raw == (SHARED / "manhattan_osm_network.json").read_bytes()
        for name in ("LICENSE.txt", "nyc_taxi_2014-12-21_20k.csv"):
            assert (folder / name).read_bytes() == (SHARED / name).read_bytes()
    assert len(doc["nodes"]) == 4197 and len(doc["links"]) == 7534
    assert doc["graph"]["crs"] == "epsg:4326"


def test_node_and_edge_counts_and_fastest_parallel_links(net, doc):
    best = _fastest(doc)
    assert len(best) == 7534 - 5  # five node pairs have two links
    assert net.n == 4197 and net.n_edges == len(best) == 7529
    assert net.crs == "EPSG:32618" and net.name == "manhattan_osm"
    for (a, b), link in best.items():
        assert net.edge(net.index_of(a), net.index_of(b)) == (link["travel_time"],
                                                              link["length"])
    # and the parallel pairs: the slower link was dropped, its length with it
    pairs = {}
    for link in doc["links"]:
        pairs.setdefault((link["source"], link["target"]), []).append(link)
    parallel = [v for v in pairs.values() if len(v) > 1]
    assert len(parallel) == 5
    for links in parallel:
        fast = min(links, key=lambda x: x["travel_time"])
        assert net.edge(net.index_of(fast["source"]), net.index_of(fast["target"]))[0] == \
            fast["travel_time"]


def test_projected_coordinates_equal_pyproj_directly(net, doc):
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32618", always_xy=True)
    lon = np.array([n["x"] for n in doc["nodes"]])
    lat = np.array([n["y"] for n in doc["nodes"]])
    x, y = to_utm.transform(lon, lat)
    idx = [net.index_of(n["id"]) for n in doc["nodes"]]
    np.testing.assert_allclose(net.xy[idx], np.column_stack([x, y]), rtol=0, atol=1e-6)
    # and back: lonlat_to_xy of the nodes' own degrees lands on them
    np.testing.assert_allclose(net.lonlat_to_xy(lon, lat), net.xy[idx], rtol=0, atol=1e-6)


def test_shortest_times_equal_networkx_on_the_json(net, doc):
    g = nx.DiGraph()
    for (a, b), link in _fastest(doc).items():
        g.add_edge(a, b, w=link["travel_time"])
    rng = np.random.default_rng(5)
    sources = [doc["nodes"][i]["id"] for i in rng.choice(len(doc["nodes"]), 4, replace=False)]
    got = net.distances_from([net.index_of(s) for s in sources])
    for row, s in zip(got, sources):
        want = nx.single_source_dijkstra_path_length(g, s, weight="w")
        assert len(want) == net.n  # strongly connected: every node reached
        ids = list(want)
        np.testing.assert_allclose(row[[net.index_of(k) for k in ids]],
                                   [want[k] for k in ids], rtol=1e-12)


# ---------------------------------------------------------------- GraphML as OSMnx writes it
def _osmnx_graphml(doc: dict, path: Path, *, drop: tuple[str, ...] = (), crs=None,
                   xy=None) -> Path:
    """``doc`` as ``ox.save_graphml`` writes a graph: every graph, node and edge attribute a
    string; ``drop`` removes edge attributes; ``crs`` / ``xy`` replace the CRS and the
    coordinates (a projected graph)."""
    g = nx.node_link_graph(doc, edges="links")
    if crs is not None:
        g.graph["crs"] = crs
    for i, (_, data) in enumerate(g.nodes(data=True)):
        if xy is not None:
            data["x"], data["y"] = xy[i]
        for k, v in list(data.items()):
            data[k] = str(v)
    for _, _, data in g.edges(data=True):
        for k in drop:
            data.pop(k, None)
        for k, v in list(data.items()):
            data[k] = str(v)
    g.graph = {k: str(v) for k, v in g.graph.items()}
    nx.write_graphml(g, path)
    return path


def test_osmnx_graphml_unprojected_and_projected_load_alike(tmp_path, net, doc):
    a = RoadNetwork.from_graph(read_graphml(_osmnx_graphml(doc, tmp_path / "city.graphml")))
    assert (a.n, a.n_edges, a.crs) == (net.n, net.n_edges, "EPSG:32618")
    assert list(a.ids) == [str(i) for i in net.ids]
    np.testing.assert_array_equal(a.xy, net.xy)
    np.testing.assert_array_equal(a.time.data, net.time.data)
    np.testing.assert_array_equal(a.length.data, net.length.data)
    # projected by the user (x, y metres in EPSG:32618): the same network, its CRS kept
    b = RoadNetwork.from_graph(read_graphml(_osmnx_graphml(
        doc, tmp_path / "utm.graphml", crs="EPSG:32618",
        xy=net.xy[[net.index_of(n["id"]) for n in doc["nodes"]]])))
    assert b.crs == "EPSG:32618"
    np.testing.assert_allclose(b.xy, net.xy, atol=1e-6)
    np.testing.assert_array_equal(b.time.data, net.time.data)
    # gzip'd GraphML through load_network, by suffix
    gz = tmp_path / "city.graphml.gz"
    gz.write_bytes(gzip.compress((tmp_path / "city.graphml").read_bytes()))
    c = load_network("city.graphml.gz", base=tmp_path)
    assert c.name == "city" and c.n_edges == net.n_edges


def test_speed_kph_without_travel_time(tmp_path, doc):
    """Edges with only ``length`` and ``speed_kph`` (as after ``ox.add_edge_speeds``): time =
    length / (speed_kph / 3.6), the fastest parallel link by that time."""
    small = {"directed": True, "multigraph": True, "graph": {"crs": "epsg:4326"},
             "nodes": [{"id": 1, "x": -73.99, "y": 40.75}, {"id": 2, "x": -73.98, "y": 40.75},
                       {"id": 3, "x": -73.98, "y": 40.76}],
             "links": [{"source": 1, "target": 2, "key": 0, "length": 900.0, "speed_kph": 36.0},
                       {"source": 1, "target": 2, "key": 1, "length": 1000.0, "speed_kph": 72},
                       {"source": 2, "target": 3, "key": 0, "length": 100.0, "speed_kmph": 18},
                       {"source": 3, "target": 1, "key": 0, "length": 50.0, "speed": 5.0},
                       {"source": 3, "target": 2, "key": 0, "length": 0.4, "speed_kph": 40.0,
                        "travel_time": 0.0}]}  # OSMnx rounded 0.036 s to 0.0
    (tmp_path / "small.json").write_text(json.dumps(small))
    net = RoadNetwork.from_graph(read_node_link(tmp_path / "small.json"))
    i = {k: net.index_of(k) for k in (1, 2, 3)}
    assert net.edge(i[1], i[2]) == pytest.approx((50.0, 1000.0))
    assert net.edge(i[2], i[3]) == pytest.approx((20.0, 100.0))
    assert net.edge(i[3], i[1]) == pytest.approx((10.0, 50.0))
    assert net.edge(i[3], i[2]) == pytest.approx((0.4 / (40 / 3.6), 0.4))
    assert net.crs.startswith("EPSG:326")
    _osmnx_graphml(small, tmp_path / "small.graphml")
    g = RoadNetwork.from_graph(read_graphml(tmp_path / "small.graphml"))
    np.testing.assert_allclose(g.time.data, net.time.data)
    np.testing.assert_allclose(g.xy, net.xy)


@pytest.mark.parametrize("edit, match", [
    ({"x": 500.0}, r"crs 'epsg:4326' says x, y are longitude, latitude degrees"),
    ({"crs": "not a crs"}, r"graph attribute 'crs' = 'not a crs' is not a CRS"),
    ({"travel_time": 0.0}, r"edge 1 -> 2: attribute 'travel_time' must be finite and positive"),
    ({"length": None}, r"edge 1 -> 2: missing attribute 'length'"),
    ({"travel_time": None}, r"edge 1 -> 2: missing attribute 'travel_time' \(or a speed"),
])
def test_bad_node_link_names_file_and_attribute(tmp_path, edit, match):
    link = {"source": 1, "target": 2, "length": 100.0, "travel_time": 9.0}
    node = {"id": 1, "x": -73.99, "y": 40.75}
    graph = {"crs": "epsg:4326"}
    for k, v in edit.items():
        target = node if k in ("x",) else graph if k == "crs" else link
        if v is None:
            target.pop(k)
        else:
            target[k] = v
    doc = {"directed": True, "graph": graph, "nodes": [node, {"id": 2, "x": -73.98, "y": 40.75}],
           "links": [link, {"source": 2, "target": 1, "length": 100.0, "travel_time": 9.0}]}
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"bad\.json: " + match):
        load_network("bad.json", base=tmp_path)


def test_degrees_without_a_crs_are_read_as_metres_with_a_warning(tmp_path, caplog):
    doc = {"directed": False, "graph": {}, "nodes": [{"id": "a", "x": -73.99, "y": 40.75},
                                                     {"id": "b", "x": -73.98, "y": 40.75}],
           "links": [{"source": "a", "target": "b", "length": 800.0, "travel_time": 60.0}]}
    (tmp_path / "nocrs.json").write_text(json.dumps(doc))
    with caplog.at_level(logging.WARNING, logger="dispatch.files.roads"):
        net = RoadNetwork.from_graph(read_node_link(tmp_path / "nocrs.json"))
    assert "crs = 'epsg:4326'" in caplog.text and net.crs is None
    assert net.edge(0, 1) == net.edge(1, 0) == (60.0, 800.0)  # undirected: both ways


# ---------------------------------------------------------------- traces
def _trace(path: Path, rows) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        for i, (o, d, when) in enumerate(rows):
            w.writerow([i, *o, *d, when, 1])
    return path


def _scenario(tmp_path: Path, tasks: str, *, network: str = "manhattan_osm",
              agents: int = 3) -> Path:
    path = tmp_path / "nyc.toml"
    path.write_text(f'name = "nyc"\nduration = 7200.0\n\n[world]\nnetwork = "{network}"\n\n'
                    f'[fleet]\nagents = {agents}\n\n[tasks]\nsource = "trace"\n{tasks}\n\n'
                    '[dispatch]\nallocator = "hungarian"\nplanner = "dijkstra"\n'
                    'batch_window = 30.0\n', encoding="utf-8")
    return path


ROWS = [(TIMES_SQUARE, UNION_SQUARE, "2014-12-21 00:00:00"),
        (WALL_STREET, HOBOKEN, "2014-12-21 00:01:00"),  # drop-off in New Jersey
        (UNION_SQUARE, HARLEM, "2014-12-21T00:02"),
        (PROSPECT_PARK, TIMES_SQUARE, "2014-12-21 00:02:30"),  # pickup in Brooklyn
        (HARLEM, WALL_STREET, "2014-12-21 00:05:00")]


def test_departure_times_are_seconds_from_start(tmp_path):
    rows = [*ROWS, (TIMES_SQUARE, HARLEM, "2014-12-20 23:59:00"),  # before start: left out
            (HARLEM, UNION_SQUARE, "2014-12-21 23:59:30")]
    _trace(tmp_path / "trips.csv", rows)
    sc = load_scenario(_scenario(tmp_path, f'trace = "trips.csv"\nstart = "{START}"'))
    trips = sc.tasks.trips
    assert trips.t.tolist() == [0.0, 60.0, 120.0, 150.0, 300.0, 86370.0]
    assert trips.row.tolist() == [1, 2, 3, 4, 5, 7]  # the file's data rows
    assert trips.dropped == (("departed before tasks.start (2014-12-21T00:00:00)", 1),)
    assert trips.layout == "latlon" and trips.origin[0].tolist() == list(TIMES_SQUARE)
    # a TOML date-time and a time zone on both sides give the same seconds
    sc2 = load_scenario(_scenario(tmp_path, 'trace = "trips.csv"\nstart = 2014-12-21T00:00:00'))
    assert sc2.tasks.trips.t.tolist() == trips.t.tolist()
    assert sc2.tasks.start == sc.tasks.start
    _trace(tmp_path / "tz.csv", [(TIMES_SQUARE, HARLEM, "2014-12-21T06:00:00+01:00")])
    sc3 = load_scenario(_scenario(tmp_path, 'trace = "tz.csv"\nstart = "2014-12-21T00:00Z"'))
    assert sc3.tasks.trips.t.tolist() == [5 * 3600.0]


def test_points_beyond_max_snap_are_left_out_with_a_count(tmp_path, net, caplog):
    _trace(tmp_path / "trips.csv", ROWS)
    with caplog.at_level(logging.WARNING, logger="dispatch.scenario.load"):
        sc = load_scenario(_scenario(tmp_path, f'trace = "trips.csv"\nstart = "{START}"\n'
                                               'max_snap = 250.0'))
    trips = sc.tasks.trips
    assert "trips.csv: 2 of 5 trips left out: pickup or drop-off farther than " \
           "tasks.max_snap = 250 m from the network" in caplog.text
    assert trips.row.tolist() == [1, 3, 5] and len(trips) == 3
    assert trips.dropped == (("pickup or drop-off farther than tasks.max_snap = 250 m from "
                              "the network", 2),)
    # brute force: the farthest end of each trip from its nearest node
    def far(o, d):
        xy = net.lonlat_to_xy([o[1], d[1]], [o[0], d[0]])
        return max(np.hypot(*(net.xy - p).T).min() for p in xy)
    dist = [far(o, d) for o, d, _ in ROWS]
    assert [r for r, m in enumerate(dist, 1) if m <= 250] == [1, 3, 5]
    assert min(dist[1], dist[3]) > 1000  # across the river, not a near miss
    # the count travels with the results, and the run serves the three that are left
    [spec] = sc.runs()
    meta = run_metadata(spec)
    assert json.loads(meta["dispatch.trips_dropped"]) == {trips.dropped[0][0]: 2}
    r = run_one(spec, tmp_path / "out")
    tasks = r.tables["tasks"].to_pandas()
    assert len(tasks) == 3 and (tasks.state == "completed").all()
    assert (tasks.snap_m <= 250).all() and (tasks.dropoff_snap_m <= 250).all()
    [summary] = (tmp_path / "out" / "summary").rglob("part-0.parquet")
    assert b"dispatch.trips_dropped" in pq.read_schema(summary).metadata


def test_without_max_snap_every_point_is_snapped(tmp_path):
    _trace(tmp_path / "trips.csv", ROWS)
    sc = load_scenario(_scenario(tmp_path, f'trace = "trips.csv"\nstart = "{START}"'))
    assert len(sc.tasks.trips) == 5 and sc.tasks.trips.dropped == ()


def test_the_shipped_day(net):
    sc = load_scenario(ROOT / "scenarios" / "nyc_manhattan.toml")
    trips = sc.tasks.trips
    assert sc.world.roads.network == "manhattan_osm" and sc.tasks.max_snap == 250.0
    assert len(trips) + trips.dropped[0][1] == 19979
    assert trips.dropped[0][1] == 1812 and len(trips) == 18167
    assert trips.t[0] == 0.0 and trips.t[-1] == 86340.0  # 23:59
    assert sc.dispatch.allocator == "hungarian" and sc.dispatch.batch_window == 30.0
    assert sc.tasks.max_wait == 300.0


@pytest.mark.parametrize("rows, tasks, key, match", [
    ([(TIMES_SQUARE, HARLEM, "2014-12-21 00:00"), (HARLEM, TIMES_SQUARE, "2014-13-21 00:00")],
     f'start = "{START}"', "row 2", r"departure_time '2014-13-21 00:00' is not a date-time"),
    ([(TIMES_SQUARE, HARLEM, "")], f'start = "{START}"', "row 1", "is not a date-time"),
    ([(TIMES_SQUARE, HARLEM, "2014-12-21 00:00")], "", "departure_time",
     r"holds date-times: set \[tasks\] start"),
    ([(TIMES_SQUARE, HARLEM, "2014-12-20 00:00")], f'start = "{START}"', "departure_time",
     r"no trip departs at or after tasks.start"),
    ([(TIMES_SQUARE, (95.0, -73.9), "2014-12-21 00:00")], f'start = "{START}"', "row 1",
     r"d_lat = 95.0 is not a coordinate"),
])
def test_bad_trace_rows_name_file_and_row(tmp_path, rows, tasks, key, match):
    _trace(tmp_path / "trips.csv", rows)
    with pytest.raises(ScenarioError, match=rf"trips\.csv: {key}: .*{match}"):
        load_scenario(_scenario(tmp_path, f'trace = "trips.csv"\n{tasks}'))


@pytest.mark.parametrize("header, match", [
    (["o_lat", "o_lon", "d_lat", "departure_time"],
     r"<header>: drop-off needs all of d_lat, d_lon"),
    (["o_lat", "d_lat", "d_lon", "departure_time"],
     r"<header>: missing column\(s\): .*o_lat, o_lon"),
    (["o_lat", "o_lon", "d_lat", "d_lon"],
     r"<header>: missing column\(s\): release_time \(or t, or departure_time\)"),
])
def test_missing_columns_are_named(tmp_path, header, match):
    with (tmp_path / "trips.csv").open("w", newline="") as fh:
        csv.writer(fh).writerows([header, ["40.75", "-73.99", "40.76", "2014-12-21 00:00"]])
    with pytest.raises(ScenarioError, match=rf"trips\.csv: {match}"):
        load_scenario(_scenario(tmp_path, f'trace = "trips.csv"\nstart = "{START}"'))


@pytest.mark.parametrize("tasks, key, match", [
    ('trace = "t.csv"\nstart = "yesterday"', "tasks.start", "must be a date-time"),
    ('trace = "s.csv"\nstart = "2014-12-21T00:00"', "t", "gives times in seconds"),
    ('trace = "s.csv"\nmax_snap = 100.0', "tasks.max_snap", "trace of coordinates"),
    ('trace = "t.csv"\nstart = "2014-12-21T00:00"\nmax_snap = 0', "tasks.max_snap", "> 0"),
    ('trace = "t.csv"\nstart = "2014-12-21T00:00"\nmax_snap = 1.0', "tasks.max_snap",
     "leaves no trip of t.csv"),
])
def test_bad_start_and_max_snap_name_the_key(tmp_path, tasks, key, match):
    _trace(tmp_path / "t.csv", [(TIMES_SQUARE, HARLEM, "2014-12-21 00:10")])
    (tmp_path / "s.csv").write_text("t,origin_node,dest_node\n0,42421728,42421731\n")
    with pytest.raises(ScenarioError, match=rf"{key}: .*{match}"):
        load_scenario(_scenario(tmp_path, tasks))


def test_max_snap_and_start_need_a_road_trace(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('[world]\nnetwork = "manhattan"\n[tasks]\nsource = "poisson"\nrate = 1.0\n'
                    'max_snap = 100.0\n')
    with pytest.raises(ScenarioError, match=r"tasks.max_snap: is only used with a trace"):
        load_scenario(path)
    path.write_text('[tasks]\nsource = "poisson"\nrate = 1.0\nstart = "2014-12-21T00:00"\n')
    with pytest.raises(ScenarioError, match=r"tasks.start: is only used when source = 'trace'"):
        load_scenario(path)


def test_parquet_timestamps_as_departure_time(tmp_path):
    import datetime as dt

    import pyarrow as pa

    when = [dt.datetime(2014, 12, 21, 0, 0), dt.datetime(2014, 12, 21, 1, 30, 15)]
    pq.write_table(pa.table({"o_lat": [TIMES_SQUARE[0], HARLEM[0]],
                             "o_lon": [TIMES_SQUARE[1], HARLEM[1]],
                             "d_lat": [HARLEM[0], TIMES_SQUARE[0]],
                             "d_lon": [HARLEM[1], TIMES_SQUARE[1]],
                             "departure_time": pa.array(when, pa.timestamp("s")),
                             "passengers": [1, 2]}), tmp_path / "trips.parquet")
    sc = load_scenario(_scenario(tmp_path, f'trace = "trips.parquet"\nstart = "{START}"'))
    assert sc.tasks.trips.t.tolist() == [0.0, 5415.0]
