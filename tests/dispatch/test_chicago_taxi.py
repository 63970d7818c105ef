"""The Chicago taxi day: the shipped sample, the empirical demand model (hour profile and OD
distribution against the sample by chi-square, seeding, scale), the hourly congestion (the
calibration and the scaled costs and drives on hand-built networks, by hand), the scenario
keys' errors, and the derivation script against the raw sample (skipped where it is absent)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chisquare

from dispatch.api.legs import RoadPoint
from dispatch.files.empirical import (MIN_POOL, WEEKDAYS, draw_day, hour_pools, load_factors,
                                      load_sample, pickup_weights)
from dispatch.files.hourly import NO_CONGESTION, HourlyFactors, calibrate
from dispatch.run import cli
from dispatch.run.runner import default_out, run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.congestion import CongestedPlanner, scale_leg
from dispatch.space.roads import load_network, manhattan
from tests.conftest import missing_data
from tests.dispatch.test_trips import road_scenario, write_csv

ROOT = Path(__file__).resolve().parents[2]
RAW = ROOT.parent / "shared" / "data" / "taxi" / "chicago_taxi_trips_sample.csv"


@pytest.fixture(scope="module")
def sample():
    return load_sample()


# ----------------------------------------------------------------------------- shipped data


def test_shipped_sample_and_factors(sample):
    assert len(sample) == 14518  # rows with both ends and trip_seconds (NOTICE.md)
    assert sample.used().size == 14518 - 1581  # ends on one node are left out
    assert set(np.unique(sample.day)) == set(range(1, 8))
    assert sample.hour.min() == 0 and sample.hour.max() == 23
    assert np.percentile(sample.origin_snap_m, 95) < 500
    net = load_network("chicago", base=ROOT)
    for ids in (sample.origin, sample.dest):  # every snapped node is a node of the network
        assert all(net.index_of(int(i)) >= 0 for i in np.unique(ids))
    f = np.array(load_factors().factors)
    assert f.shape == (24,) and 1.5 < f.min() and f.max() < 3.5
    assert f[17] > f[4]  # the evening peak is slower than the small hours


def test_shipped_factors_are_the_calibration_of_the_shipped_trips(sample):
    net = load_network("chicago", base=ROOT)
    idx = {int(i): net.index_of(int(i)) for i in np.unique(np.r_[sample.origin, sample.dest])}
    o = np.array([idx[int(i)] for i in sample.origin])
    d = np.array([idx[int(i)] for i in sample.dest])
    factors, trips, _ = calibrate(net, o, d, sample.hour, sample.trip_seconds)
    np.testing.assert_allclose(factors, load_factors().factors, atol=5e-5)
    assert trips.min() >= 200


# ----------------------------------------------------------------------------- demand


def _expected_counts(total, shares):
    return total * np.asarray(shares) / np.sum(shares)


def test_hour_profile_of_a_drawn_day_matches_the_sample(sample):
    day = draw_day(sample, 30000, np.random.default_rng(11))
    hist = np.bincount((day.t // 3600).astype(int), minlength=24)
    assert hist.size == 24 and day.t.min() >= 0 and day.t.max() < 86400
    p = chisquare(hist, _expected_counts(hist.sum(), sample.profile())).pvalue
    assert p > 0.01, p
    # the test has power: a flat profile is rejected outright
    assert chisquare(hist, _expected_counts(hist.sum(), np.ones(24))).pvalue < 1e-12


def _binned(values, keys, expected_share, min_expected=5.0):
    """Observed and expected counts of ``keys`` (each with expected count >= min_expected),
    plus one bin for everything else."""
    total = len(values)
    obs, exp = [], []
    for k, s in zip(keys, expected_share):
        if s * total >= min_expected:
            obs.append(int(np.sum(values == k)))
            exp.append(s * total)
    obs.append(total - sum(obs))
    exp.append(total - sum(exp))
    return np.array(obs), np.array(exp)


def test_od_distribution_of_a_drawn_day_matches_the_sample(sample):
    day = draw_day(sample, 30000, np.random.default_rng(12))
    used = sample.used()
    # origins: the day's origin nodes against the sample's shares
    nodes, counts = np.unique(sample.origin[used], return_counts=True)
    obs, exp = _binned(day.origin[:, 0].astype(np.int64), nodes, counts / counts.sum())
    assert len(obs) > 30
    assert chisquare(obs, exp).pvalue > 0.01
    # pairs: drawn jointly, so the (origin, destination) pairs keep the sample's shares
    pair = sample.origin[used] * 100000 + sample.dest[used]
    keys, counts = np.unique(pair, return_counts=True)
    drawn = (day.origin[:, 0] * 100000 + day.dest[:, 0]).astype(np.int64)
    obs, exp = _binned(drawn, keys, counts / counts.sum())
    assert len(obs) > 50
    assert chisquare(obs, exp).pvalue > 0.01
    # independent ends would not fit: shuffling destinations breaks the pairs
    shuffled = (day.origin[:, 0] * 100000
                + np.random.default_rng(0).permutation(day.dest[:, 0])).astype(np.int64)
    obs, exp = _binned(shuffled, keys, counts / counts.sum())
    assert chisquare(obs, exp).pvalue < 1e-6


def test_same_seed_same_day_other_seed_other_day(sample):
    a, b = (draw_day(sample, 5000, np.random.default_rng(3)) for _ in range(2))
    c = draw_day(sample, 5000, np.random.default_rng(4))
    assert np.array_equal(a.t, b.t) and np.array_equal(a.origin, b.origin)
    assert np.array_equal(a.dest, b.dest)
    assert len(a) != len(c) or not np.array_equal(a.origin, c.origin)
    assert np.all(np.diff(a.t) >= 0)


def test_trips_per_day_is_the_poisson_mean(sample):
    rng = np.random.default_rng(5)
    for rate in (500.0, 4000.0):
        n = np.array([len(draw_day(sample, rate, rng)) for _ in range(20)])
        # sum of 20 Poisson(rate) days: mean 20 rate, sd sqrt(20 rate)
        assert abs(n.sum() - 20 * rate) < 4 * math.sqrt(20 * rate), (rate, n)


def test_weekday_draws_only_that_days_trips(sample):
    pools = hour_pools(sample, "sunday")
    for h, pool in enumerate(pools):
        assert len(pool) >= MIN_POOL
        assert np.all(sample.day[pool] == 1)  # trip_start_day 1 = Sunday
        assert np.all(sample.origin[pool] != sample.dest[pool])
    sunday = sample.used("sunday")
    assert sum(sample.profile("sunday")) == sunday.size
    # an hour with enough Sunday trips draws from that hour alone
    busy = int(np.argmax(sample.profile("sunday")))
    assert np.all(sample.hour[pools[busy]] == busy)
    day = draw_day(sample, 2000, np.random.default_rng(1), "sunday")
    pairs = set(zip(sample.origin[sunday], sample.dest[sunday]))
    assert all((int(o), int(d)) in pairs for o, d in zip(day.origin[:, 0], day.dest[:, 0]))
    nodes, p = pickup_weights(sample, "sunday")
    assert math.isclose(p.sum(), 1.0) and set(nodes) == set(sample.origin[sunday])
    assert WEEKDAYS[0] == "sunday"


# ----------------------------------------------------------------------------- congestion


def test_calibration_by_hand():
    net = manhattan(3, 1, 100.0, 10.0)  # 0 - 1 - 2, 10 s per edge
    o = np.array([0, 0, 1, 0, 2, 1])
    d = np.array([1, 2, 2, 2, 2, 0])
    hour = np.array([0, 0, 0, 1, 1, 5])
    sec = np.array([25.0, 60.0, 20.0, 40.0, 99.0, 0.0])  # ratios 2.5, 3, 2, 2; o == d; 0 s
    f, trips, widths = calibrate(net, o, d, hour, sec, min_trips=3)
    assert (f[0], trips[0], widths[0]) == (2.5, 3, 0)  # median(2.5, 3, 2)
    assert (f[1], trips[1], widths[1]) == (2.25, 4, 1)  # hours 0..2: median(2.5, 3, 2, 2)
    assert (f[12], trips[12], widths[12]) == (2.25, 4, 12)  # the whole day
    assert (f[23], widths[23]) == (2.5, 1)  # hours 22, 23, 0
    with pytest.raises(ValueError, match="usable trips"):
        calibrate(net, o, d, hour, sec, min_trips=5)


def test_factor_of_time_and_scaled_costs_by_hand():
    hf = HourlyFactors(tuple([2.0] + [3.0] + [1.0] * 22))
    assert hf.factor(0.0) == 2.0 and hf.factor(3599.9) == 2.0 and hf.factor(3600.0) == 3.0
    assert hf.factor(86400.0 + 10) == 2.0  # the next day's midnight
    assert NO_CONGESTION.factor(5000.0) == 1.0
    with pytest.raises(ValueError):
        HourlyFactors((1.0,) * 23)
    net = manhattan(3, 1, 100.0, 10.0)
    leg = net.leg(RoadPoint(1, 0, 7.0, 70.0), [1, 2])  # 7 s left on 0 -> 1, then 10 s
    scaled = scale_leg(leg, 2.0)
    assert scaled.times.tolist() == [7.0, 27.0] and scaled.metres.tolist() == leg.metres.tolist()
    from dispatch.api.problem import AgentView, TaskView
    from planners.road import RoadPlanner

    clock = [10.0]
    planner = CongestedPlanner(RoadPlanner(net), hf, lambda: clock[0])
    agents = (AgentView(0, "car", RoadPoint(1, 0, 7.0, 70.0), 10.0), AgentView(1, "car", 0, 10.0))
    tasks = (TaskView(0, "trip", 2, 0.0),)
    assert planner.costs(agents, tasks)[:, 0].tolist() == [7.0 + 2 * 10.0, 2 * 20.0]
    clock[0] = 4000.0
    assert planner.costs(agents, tasks)[:, 0].tolist() == [7.0 + 3 * 10.0, 3 * 20.0]
    assert planner.plan(agents[1], 2) == [0, 1, 2] and planner.name == "dijkstra"


def test_a_run_drives_at_the_hours_factor(tmp_path):
    """One taxi at node 0 of a 3 x 2 grid (0 - 1 - 2 on the first row, 10 s per edge); a
    trip 2 -> 0 released at 3590 s.
    Hour 0 doubles times, hour 1 triples them: the pickup leg (20 s free flow) is planned and
    driven at x2 (40 s, pickup at 3630), the drop-off leg departs in hour 1 at x3 (60 s)."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(3590.0, 2, 0)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    factors = [2.0, 3.0] + [1.0] * 22
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"',
                         network=f'network = "manhattan"\nblocks = [3, 2]\nblock = 100.0\n'
                                 f'speed = 10.0\ncongestion = {factors}')
    r = run_one(load_scenario(path).runs()[0])
    task = r.tables["tasks"].to_pandas().iloc[0]
    assert (task.cost, task.picked_up_at, task.completed_at) == (40.0, 3630.0, 3690.0)
    veh = r.tables["vehicles"].to_pandas().iloc[0]
    assert veh.distance == 400.0  # metres do not change
    # without congestion the same trip is free flow
    plain = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                          fleet='start = "fleet.csv"', name="plain",
                          network='network = "manhattan"\nblocks = [3, 2]\nblock = 100.0\n'
                                  'speed = 10.0')
    task = run_one(load_scenario(plain).runs()[0]).tables["tasks"].to_pandas().iloc[0]
    assert (task.cost, task.picked_up_at, task.completed_at) == (20.0, 3610.0, 3630.0)


# ----------------------------------------------------------------------------- scenarios


def test_chicago_taxi_scenario_validates():
    sc = load_scenario(ROOT / "scenarios" / "chicago_taxi.toml")
    assert sc.tasks.source == "empirical" and sc.tasks.max_wait == 600.0
    assert sc.world.roads.congestion == load_factors().factors
    assert sc.fleet.placement == "demand" and sc.duration > 86400


def test_a_short_empirical_run(tmp_path):
    path = road_scenario(tmp_path, tasks='source = "empirical"\ntrips_per_day = 2400',
                         fleet='agents = 30\nplacement = "demand"', duration=1800.0,
                         network='network = "chicago"\ncongestion = "chicago_taxi"')
    sc = load_scenario(path)
    r = run_one(sc.runs()[0])
    tasks = r.tables["tasks"].to_pandas()
    assert 20 < len(tasks) < 120  # ~ 2400 x 602 / 12937 / 2 = 56 in the first half hour
    assert (tasks.max_wait == 600.0).all()
    # each request's id: its number in the day drawn, the day's first trips released so far
    assert r.tables["tasks"].schema.field("request_id").type == "int64"
    assert sorted(tasks.request_id) == list(range(len(tasks)))
    done = tasks[tasks.state == "completed"]
    assert len(done) > 0 and ((done.picked_up_at - done.released_at) <= 600.0 + 1e-6).all()
    nodes, _ = pickup_weights(load_sample())
    net = load_network("chicago", base=ROOT)
    starts = r.tables["vehicles"].to_pandas()[["x0", "y0"]].to_numpy()
    idx = net.nearest(starts)[0]
    assert set(np.asarray(net.ids)[idx]) <= set(nodes)  # every taxi starts on a pickup node


@pytest.mark.parametrize("world,fleet,tasks,words", [
    ('network = "manhattan"', "", 'source = "empirical"\ntrips_per_day = 10',
     ["tasks.source", "world.network = 'chicago'"]),
    ('network = "chicago"', "", 'source = "empirical"', ["tasks.trips_per_day", "is required"]),
    ('network = "chicago"', "", 'source = "empirical"\ntrips_per_day = 0', ["must be > 0"]),
    ('network = "chicago"', "", 'source = "empirical"\ntrips_per_day = 9\nweekday = "mon"',
     ["tasks.weekday", "sunday"]),
    ('network = "chicago"', "", 'source = "empirical"\ntrips_per_day = 9\ncount = 3',
     ["tasks.count", "only used"]),
    ('network = "chicago"', "", 'source = "poisson"\nrate = 1.0\ntrips_per_day = 9',
     ["tasks.trips_per_day", "only used when source = 'empirical'"]),
    ('network = "chicago"', 'placement = "demand"', 'source = "poisson"\nrate = 1.0',
     ["fleet.placement = 'demand'", "needs source = 'empirical'"]),
    ('network = "chicago"', 'placement = "zones"', 'source = "poisson"\nrate = 1.0',
     ["fleet.placement", "uniform, demand"]),
    ('network = "chicago"\ncongestion = [2.0, 3.0]', "", 'source = "poisson"\nrate = 1.0',
     ["world.congestion", "24 factors"]),
    ('network = "chicago"\ncongestion = "rush"', "", 'source = "poisson"\nrate = 1.0',
     ["world.congestion", "'chicago_taxi'"]),
    ('size = [10, 10, 5]\ncongestion = "chicago_taxi"', "", 'source = "static"',
     ["world.congestion", "road network"]),
    ('network = "chicago"', "", 'source = "empirical"\ntrips_per_day = 3e6',
     ["tasks.trips_per_day", "--ignore-limits"]),
])
def test_bad_keys_one_line(tmp_path, capsys, world, fleet, tasks, words):
    path = tmp_path / "bad.toml"
    path.write_text(f"[world]\n{world}\n[fleet]\nagents = 2\n{fleet}\n[tasks]\n{tasks}\n",
                    encoding="utf-8")
    code = cli.main(["validate", str(path)])
    out, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in out + err, out + err
    assert len(err.strip().splitlines()) == 1, err
    for w in words:
        assert w in err, err


# ----------------------------------------------------------------------------- derivation


@pytest.mark.skipif(not RAW.is_file(), reason=missing_data(RAW, "the raw Chicago taxi sample"))
def test_derivation_script_reproduces_the_shipped_files(tmp_path):
    spec = importlib.util.spec_from_file_location("make_chicago_taxi",
                                                  ROOT / "scripts" / "make_chicago_taxi.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(RAW, tmp_path)
    shipped = ROOT / "dispatch" / "data" / "chicago_taxi"
    for name in ("trips.csv", "congestion.csv"):
        assert (tmp_path / name).read_bytes() == (shipped / name).read_bytes(), name


def test_batch_window_is_a_sweep_axis(tmp_path, capsys):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(5.0, 2, 0)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"',
                         extra="[sweep]\nbatch_window = [0.0, 30.0]\n"
                               "allocator = ['fcfs', 'greedy']")
    specs = load_scenario(path).runs()
    assert [(s.scenario.name, s.batch_window, s.scenario.dispatch.batch_window, s.allocator)
            for s in specs] == [
        ("road", 0.0, 0.0, "fcfs"), ("road", 30.0, 30.0, "fcfs"),
        ("road", 0.0, 0.0, "greedy"), ("road", 30.0, 30.0, "greedy")]
    # a run key: its own id part and partition level (before n_agents, as the others)
    n, seed = specs[0].agents, specs[0].seed
    assert [s.run_id for s in specs] == [f"road__{a}__dijkstra__bw{w}__n{n}__s{seed}"
                                         for a in ("fcfs", "greedy") for w in ("0", "30")]
    assert list(specs[1].partition.items())[3:] == [("batch_window", 30.0), ("n_agents", n),
                                                    ("seed", seed)]
    assert default_out(specs[1]) == Path("runs") / "road"  # both windows in one folder
    # the window delays the decision: assigned at release (5 s) or 30 s later
    for spec, at in ((specs[0], 5.0), (specs[1], 35.0)):
        task = run_one(spec).tables["tasks"].to_pandas().iloc[0]
        assert task.assigned_at == at
    assert cli.main(["run", str(path), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "imm" in out and "30s" in out  # the window beside the allocator (may wrap)
    bad = road_scenario(tmp_path, tasks='source = "static"', name="bad",
                        extra="[sweep]\nbatch_window = [30, 30]")
    assert cli.main(["validate", str(bad)]) == 2
    assert "sweep.batch_window: must be a list of distinct seconds" in capsys.readouterr().err
