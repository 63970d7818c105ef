"""Trips on road networks, end to end: random scenarios of every source and several
allocators on a Manhattan grid, checked for the life-cycle invariants and against independent
shortest paths (scipy); traces by node, metres and latitude / longitude; fleet start files;
clear errors at validate time."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.sparse.csgraph import dijkstra

from dispatch.api.legs import RoadPoint
from dispatch.errors import ScenarioError
from dispatch.run.plugins import check_runs
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import load_network, manhattan
from tests.conftest import missing_data

ROOT = Path(__file__).resolve().parents[2]
TAXI = ROOT.parent / "shared" / "data" / "taxi" / "chicago_taxi_trips_sample.csv"
TERMINAL = {"completed": "complete", "expired": "expire", "rejected": "reject",
            "unreachable": "unreachable", "cut_off": "cut_off", "failed": "failed"}


def road_scenario(directory: Path, *, tasks: str, fleet: str = "agents = 4",
                  allocator: str = "fcfs", network: str = 'network = "manhattan"\n'
                  'blocks = [6, 5]\nblock = 100.0\nspeed = 10.0', duration: float = 1e5,
                  extra: str = "", name: str = "road") -> Path:
    path = directory / f"{name}.toml"
    path.write_text(f'name = "{name}"\nseed = 3\nduration = {duration!r}\n\n[world]\n{network}\n\n'
                    f'[fleet]\n{fleet}\n\n[tasks]\n{tasks}\n\n[dispatch]\n'
                    f'allocator = "{allocator}"\nplanner = "dijkstra"\n{extra}\n', encoding="utf-8")
    return path


def write_csv(path: Path, header, rows) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


SOURCES = {
    "static": 'source = "static"\ncount = 7',
    "periodic": 'source = "periodic"\ninterval = 20.0\ncount = 15\nmax_wait = 90.0',
    "poisson": 'source = "poisson"\nrate = 0.08\ncount = 25\nttl = 200.0',
    "trace": 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 300.0',
}
ALLOCATORS = ("fcfs", "hungarian", "greedy")


def make_trace(directory: Path, rng) -> None:
    rows = []
    t = 0.0
    for i in range(20):
        t += float(rng.exponential(15.0))
        o, d = rng.choice(30, size=2, replace=False)
        rows.append((round(t, 3), int(o), int(d), 60.0 if i % 4 == 0 else ""))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "max_wait"], rows)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for source in SOURCES:
        for alloc in ALLOCATORS:
            d = tmp_path_factory.mktemp(f"{source}_{alloc}")
            make_trace(d, np.random.default_rng(7))
            [spec] = load_scenario(road_scenario(d, tasks=SOURCES[source],
                                                 allocator=alloc)).runs()
            r = run_one(spec)
            out[(source, alloc)] = (spec, r.summary, {n: t.to_pandas()
                                                      for n, t in r.tables.items()})
    return out


CASES = [(s, a) for s in SOURCES for a in ALLOCATORS]


@pytest.mark.parametrize("case", CASES, ids=[f"{s}-{a}" for s, a in CASES])
def test_every_trip_ends_in_exactly_one_terminal_state(runs, case):
    spec, s, t = runs[case]
    tasks, ev = t["tasks"], t["events"]
    released = ev[ev.event == "release"]
    assert tasks.task_id.is_unique and sorted(tasks.task_id) == sorted(released.task_id)
    term = ev[ev.event.isin(TERMINAL.values())]
    assert term.task_id.is_unique and set(term.task_id) == set(tasks.task_id)
    by_task = term.set_index("task_id").event
    for row in tasks.itertuples():
        assert by_task[row.task_id] == TERMINAL[row.state]
    done = tasks[tasks.state == "completed"]
    assert len(done) > 0
    assert (done.released_at <= done.assigned_at).all()
    assert (done.assigned_at <= done.picked_up_at).all()
    assert (done.picked_up_at <= done.completed_at).all()
    assert done.dropoff_x.notna().all()
    # a request is never picked up after its deadline
    waited = done.picked_up_at - done.released_at
    assert (waited <= done.max_wait.fillna(np.inf) + 1e-6).all()
    rejected = tasks[tasks.state == "rejected"]
    assert (rejected.agent_id == -1).all() and rejected.max_wait.notna().all()
    # summary counts match the tasks table
    states = tasks.state.value_counts().to_dict()
    for state in ("completed", "expired", "rejected", "unreachable", "cut_off", "failed"):
        assert s[f"tasks_{state}"] == states.get(state, 0), state
    assert s["n_tasks"] == len(tasks)
    assert s["total_cost"] == pytest.approx(tasks[tasks.agent_id >= 0].cost.sum())


@pytest.mark.parametrize("case", CASES, ids=[f"{s}-{a}" for s, a in CASES])
def test_no_vehicle_holds_two_trips(runs, case):
    _, _, t = runs[case]
    tasks = t["tasks"]
    served = tasks[tasks.agent_id >= 0].sort_values(["agent_id", "assigned_at"])
    for _, g in served.groupby("agent_id"):
        ends = g.closed_at.to_numpy()
        starts = g.assigned_at.to_numpy()
        assert (starts[1:] >= ends[:-1] - 1e-9).all()


@pytest.mark.parametrize("case", CASES, ids=[f"{s}-{a}" for s, a in CASES])
def test_vehicle_distances_are_the_sum_of_shortest_legs(runs, case):
    """Empty km (to each pickup) and occupied km (pickup to drop-off) equal scipy's shortest
    paths (fastest = shortest on a uniform-speed grid) over each vehicle's trips in order."""
    spec, s, t = runs[case]
    net = manhattan(6, 5, 100.0, 10.0)
    metres = dijkstra(net.length, directed=True)
    tasks, veh = t["tasks"], t["vehicles"]
    node = {(x, y): i for i, (x, y) in enumerate(net.xy)}
    assert s["tasks_cut_off"] == 0  # every leg driven to its end
    for v in veh.itertuples():
        here = node[(v.x0, v.y0)]
        empty = occupied = 0.0
        mine = tasks[(tasks.agent_id == v.agent_id)].sort_values("assigned_at")
        for trip in mine.itertuples():
            pick, drop = node[(trip.x, trip.y)], node[(trip.dropoff_x, trip.dropoff_y)]
            empty += metres[here, pick]
            occupied += metres[pick, drop]
            here = drop
        assert v.empty_distance == pytest.approx(empty)
        assert v.occupied_distance == pytest.approx(occupied)
        assert v.distance == pytest.approx(empty + occupied)
    assert s["distance"] == pytest.approx(veh.distance.sum())


@pytest.mark.parametrize("case", CASES, ids=[f"{s}-{a}" for s, a in CASES])
def test_pickup_waits_equal_the_planned_costs(runs, case):
    """A vehicle dispatched from a node reaches the pickup exactly ``cost`` seconds later, and
    the cost is scipy's fastest time from where it stood."""
    _, _, t = runs[case]
    tasks = t["tasks"]
    done = tasks[tasks.state == "completed"]
    assert np.allclose(done.picked_up_at - done.assigned_at, done.cost)
    net = manhattan(6, 5, 100.0, 10.0)
    secs = dijkstra(net.time, directed=True)
    node = {(x, y): i for i, (x, y) in enumerate(net.xy)}
    ride = [secs[node[(r.x, r.y)], node[(r.dropoff_x, r.dropoff_y)]] for r in done.itertuples()]
    assert np.allclose(done.completed_at - done.picked_up_at, ride)


def test_same_seed_same_road_run(tmp_path):
    make_trace(tmp_path, np.random.default_rng(1))
    [spec] = load_scenario(road_scenario(tmp_path, tasks=SOURCES["poisson"])).runs()
    a, b = run_one(spec), run_one(spec)
    for name in ("tasks", "events", "vehicles", "decisions"):
        cols = [c for c in a.tables[name].column_names if not c.endswith("seconds")]
        assert a.tables[name].select(cols).to_pandas().equals(
            b.tables[name].select(cols).to_pandas()), name


def test_fleet_starts_where_the_start_file_puts_it(tmp_path):
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(7, 0), (3, 29), (12, 14)])
    make_trace(tmp_path, np.random.default_rng(2))
    path = road_scenario(tmp_path, tasks=SOURCES["trace"], fleet='start = "fleet.csv"')
    [spec] = load_scenario(path).runs()
    assert spec.agents == 3
    veh = run_one(spec).tables["vehicles"].to_pandas().set_index("agent_id")
    net = manhattan(6, 5, 100.0, 10.0)
    for vid, n in ((7, 0), (3, 29), (12, 14)):
        assert (veh.loc[vid, "x0"], veh.loc[vid, "y0"]) == tuple(net.xy[n])


def test_positions_in_metres_are_snapped_and_the_distance_recorded(tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_x", "origin_y", "dest_x", "dest_y"],
              [(0.0, 130.0, 40.0, 480.0, 390.0), (5.0, 0.0, 0.0, 500.0, 400.0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"')
    [spec] = load_scenario(path).runs()
    tasks = run_one(spec).tables["tasks"].to_pandas().sort_values("task_id")
    assert list(tasks.x) == [100.0, 0.0] and list(tasks.y) == [0.0, 0.0]
    assert tasks.snap_m.tolist() == pytest.approx([50.0, 0.0])
    assert tasks.dropoff_snap_m.tolist() == pytest.approx([math.hypot(20, 10), 0.0])


@pytest.mark.skipif(not TAXI.is_file(), reason=missing_data(TAXI, "the raw Chicago taxi sample"))
def test_chicago_trace_by_latitude_longitude(tmp_path):
    """Real taxi trips (the shared Chicago sample) on the shipped Chicago network: snapped to
    through nodes a few hundred metres away, served, costs equal to scipy's Dijkstra."""
    sample = pd.read_csv(TAXI, nrows=3000)
    cols = ["pickup_latitude", "pickup_longitude", "dropoff_latitude", "dropoff_longitude"]
    trips = sample.dropna(subset=cols).head(30).copy()
    trips["t"] = np.arange(len(trips)) * 30.0
    trips[["t", *cols]].to_csv(tmp_path / "trips.csv", index=False)
    net = load_network("chicago", base=ROOT)
    # the fleet stands in the city (a start file in metres), one taxi near each pickup
    xy = net.lonlat_to_xy(trips.pickup_longitude.to_numpy(), trips.pickup_latitude.to_numpy())
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "x", "y"],
              [(i, x, y) for i, (x, y) in enumerate(xy)])
    path = road_scenario(tmp_path, network='network = "chicago"', fleet='start = "fleet.csv"',
                         tasks='source = "trace"\ntrace = "trips.csv"\nmax_wait = 1800.0')
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    tasks = r.tables["tasks"].to_pandas()
    assert len(tasks) == 30
    assert tasks.snap_m.notna().all() and (tasks.snap_m < 2000).all()
    assert tasks.snap_m.median() < 600  # PROVENANCE: median 0.25 km, p95 0.48 km
    assert (tasks.state == "completed").all()
    node = {(x, y): i for i, (x, y) in enumerate(net.xy)}
    done = tasks[tasks.state == "completed"]
    picks = [node[(x, y)] for x, y in zip(done.x, done.y)]
    drops = [node[(x, y)] for x, y in zip(done.dropoff_x, done.dropoff_y)]
    secs = dijkstra(net.time, directed=True, indices=picks)
    assert np.allclose(done.completed_at - done.picked_up_at,
                       secs[np.arange(len(picks)), drops])


def test_a_vehicle_mid_leg_is_costed_from_where_it_is():
    """Where a decision finds a vehicle part-way along a leg: the rest of its edge plus the
    fastest path from the edge's end (scipy), as the planner prices it."""
    from dispatch.api.problem import AgentView, TaskView
    from dispatch.api.registry import load

    net = manhattan(6, 5, 100.0, 10.0)
    leg = net.route(0, 29)
    planner = load("planner", "dijkstra")(net)
    secs = dijkstra(net.time, directed=True)
    for t in np.linspace(0.0, leg.seconds, 17):
        p = leg.point_at(t)
        c = planner.costs((AgentView(0, "car", p, 10.0),), (TaskView(0, "trip", 12, 0.0),))
        assert isinstance(p, RoadPoint)
        assert c[0, 0] == pytest.approx(p.remaining + secs[p.node, 12])


# ----------------------------------------------------------------------------- errors


def test_voxel_planner_on_roads_is_a_validate_time_error(tmp_path):
    path = road_scenario(tmp_path, tasks=SOURCES["static"])
    text = path.read_text().replace('planner = "dijkstra"', 'planner = "astar"')
    path.write_text(text)
    sc = load_scenario(path)
    with pytest.raises(ScenarioError, match=r"dispatch.planner.*'astar'.*road.*dijkstra"):
        check_runs(sc, ["astar"])


def test_road_planner_in_a_voxel_world_is_an_error(make_scenario):
    sc = load_scenario(make_scenario(dispatch={"planner": "dijkstra"}))
    with pytest.raises(ScenarioError, match="'dijkstra' serves road"):
        check_runs(sc, ["dijkstra"])


def test_voxel_keys_on_a_road_network_are_an_error(tmp_path):
    path = road_scenario(tmp_path, tasks=SOURCES["static"],
                         network='network = "manhattan"\ncell = 1.0')
    with pytest.raises(ScenarioError, match="world.cell.*voxel-world key"):
        load_scenario(path)


@pytest.mark.parametrize("rows, where, what", [
    ([(0.0, 1, 2), (1.0, "x", 3)], "row 2", "origin_node is not a number"),
    ([(0.0, 1, 2), (-1.0, 1, 3)], "row 2", "negative"),
    ([(0.0, 1.5, 2)], "row 1", "not a node id"),
])
def test_bad_trace_rows_are_named(tmp_path, rows, where, what):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], rows)
    with pytest.raises(ScenarioError, match=f"{where}.*{what}"):
        load_scenario(road_scenario(tmp_path, tasks=SOURCES["trace"].replace(
            '\nmax_wait = 300.0', '')))


def test_unknown_node_in_a_trace_is_named_at_validate_time(tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(0, 1, 2), (1, 99, 3)])
    sc = load_scenario(road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"'))
    with pytest.raises(ScenarioError, match="row 2.*99"):
        check_runs(sc, ["dijkstra"])


def test_a_start_file_with_a_duplicate_vehicle_is_named(tmp_path):
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(1, 0), (1, 3)])
    with pytest.raises(ScenarioError, match="row 2.*vehicle_id 1 appears twice"):
        load_scenario(road_scenario(tmp_path, tasks=SOURCES["static"],
                                    fleet='start = "fleet.csv"'))


def test_voxel_trips_with_drop_offs(make_scenario, tmp_path):
    """In the voxel world a trace may give drop-offs: each trip is driven pickup -> drop-off,
    occupied metres equal the planner's shortest paths, and the events say so."""
    write_csv(tmp_path / "trips.csv", ["t", "x", "y", "z", "dest_x", "dest_y", "dest_z"],
              [(0.0, 1.5, 1.5, 0.5, 10.5, 10.5, 0.5), (2.0, 10.5, 1.5, 0.5, 1.5, 10.5, 0.5)])
    path = make_scenario(tasks={"source": "trace", "trace": "trips.csv",
                                "ground_fraction": None},
                         obstacles={"count": 0}, fleet={"agents": 2, "uav_fraction": 0.0})
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    tasks = r.tables["tasks"].to_pandas().sort_values("task_id")
    assert list(tasks.state) == ["completed", "completed"]
    assert (tasks.picked_up_at <= tasks.completed_at).all()
    assert tasks.dropoff_x.tolist() == [10.5, 1.5]
    ev = r.tables["events"].to_pandas()
    assert (ev.event == "dropoff").sum() == 2
    # an empty 12 x 12 ground: octile distance between the cells, metres (UGVs drive 8-connected)
    octile = [9 * math.sqrt(2), 9 * math.sqrt(2)]
    assert r.summary["occupied_distance"] == pytest.approx(sum(octile))
    assert r.tables["vehicles"].to_pandas().occupied_distance.sum() == pytest.approx(sum(octile))


@pytest.mark.parametrize("name, text", [("bad.graphml", "x"), ("x_net.tntp",
                                                                 "<END OF METADATA>\nfoo\n")])
def test_a_malformed_network_file_is_one_error_naming_the_key(tmp_path, name, text):
    (tmp_path / name).write_text(text)
    (tmp_path / "x_node.tntp").write_text("node X Y\n1 a b\n")
    sc = load_scenario(road_scenario(tmp_path, tasks=SOURCES["static"],
                                     network=f'network = "{name}"'))
    with pytest.raises(ScenarioError, match=r"road.toml: world.network: .*"):
        check_runs(sc, ["dijkstra"])
