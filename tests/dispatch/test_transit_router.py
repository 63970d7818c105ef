"""Earliest-arrival routing (dispatch.space.csa over dispatch.space.transit): known answers on
a hand-made feed, the calendar's exceptions, earliest arrivals equal to an independent
reference (Dijkstra on the time-expanded graph, networkx) on 1,000 random queries, and every
train leg of a journey consistent with the shipped Manhattan subway feed."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest

from dispatch.files.gtfs import feed_path, read_gtfs
from dispatch.space.csa import TransitLeg, earliest_arrivals
from dispatch.space.transit import Timetable
from tests.dispatch.gtfs_feeds import Reference, random_tables, tiny_tables, write_feed

WED, HOLIDAY = dt.date(2026, 3, 11), dt.date(2026, 3, 4)
SUBWAY_DAY = dt.date(2026, 9, 23)


def h(text: str) -> float:
    hh, mm, ss = (int(x) for x in text.split(":"))
    return hh * 3600 + mm * 60 + ss


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory) -> Path:
    return write_feed(tmp_path_factory.mktemp("tiny"), tiny_tables())


@pytest.fixture(scope="module")
def tiny(tiny_dir) -> Timetable:
    return Timetable.from_feed(read_gtfs(tiny_dir, WED))


@pytest.fixture(scope="module")
def subway() -> Timetable:
    return Timetable.from_feed(read_gtfs(feed_path("nyc_subway", Path(".")), SUBWAY_DAY))


def _arrive(tt: Timetable, origin: str, t0: str, goal: str) -> float:
    return float(earliest_arrivals(tt, {tt.station(origin): h(t0)}).arrival[tt.station(goal)])


@pytest.mark.parametrize("origin, t0, goal, expected", [
    ("A", "08:00:00", "C", "08:10:00"),  # R1 straight through
    ("A", "08:01:00", "C", "08:20:00"),  # R1 gone: R2
    ("A", "08:00:00", "E", "08:18:00"),  # R1 to B (08:05), 180 s change misses G1 (08:07): G2
    ("D", "08:00:00", "C", "08:20:00"),  # G1 to B (08:07), R1 has left (08:05): R2 (08:15)
    ("A", "23:00:00", "C", "24:20:00"),  # R3 past midnight
    ("A", "00:00:00", "C", "00:20:00"),  # the day before's R3, after its midnight
])
def test_the_tiny_feed_known_answers(tiny, origin, t0, goal, expected):
    assert _arrive(tiny, origin, t0, goal) == h(expected)


def test_the_tiny_feed_unreachable_and_platform_ids(tiny):
    assert _arrive(tiny, "E", "08:00:00", "A") == math.inf  # no train runs back
    assert _arrive(tiny, "C", "08:30:00", "C") == h("08:30:00")  # a source is reached
    assert tiny.station("BR") == tiny.station("BG") == tiny.station("B")
    with pytest.raises(KeyError, match="stop 'Z' is no station"):
        tiny.station("Z")


def test_the_tiny_feed_journey_legs(tiny):
    a = earliest_arrivals(tiny, {tiny.station("A"): h("08:00:00")})
    assert a.journey(tiny.station("E")) == [
        TransitLeg("train", "A", "B", h("08:00:00"), h("08:05:00"), "R1", "R"),
        TransitLeg("train", "B", "E", h("08:12:00"), h("08:18:00"), "G2", "G")]
    assert a.journey(tiny.station("A")) == []


def test_a_walk_between_stations_within_the_radius(tiny_dir):
    """Stations are 2 km apart: with a 2.1 km radius at 4 m/s, walking from B to E (500 s)
    beats the change to G2, and the journey ends with the walk."""
    tt = Timetable.from_feed(read_gtfs(tiny_dir, WED), walk_radius=2100, walk_speed=4.0)
    a = earliest_arrivals(tt, {tt.station("A"): h("08:00:00")})
    e = tt.station("E")
    assert a.arrival[e] == h("08:05:00") + 500
    assert a.journey(e) == [TransitLeg("train", "A", "B", h("08:00:00"), h("08:05:00"), "R1", "R"),
                            TransitLeg("walk", "B", "E", h("08:05:00"), h("08:13:20"))]


def test_calendar_exceptions_change_the_answers(tiny_dir):
    """On 2026-03-04 the weekday service is removed and HOL's one trip (A 09:00 -> C 09:10)
    is added."""
    holiday = Timetable.from_feed(read_gtfs(tiny_dir, HOLIDAY))
    assert _arrive(holiday, "A", "08:00:00", "C") == h("09:10:00")
    assert _arrive(holiday, "A", "09:00:01", "C") == math.inf
    weekday = Timetable.from_feed(read_gtfs(tiny_dir, WED))
    assert _arrive(weekday, "A", "08:30:00", "C") == h("24:20:00")  # not R9 (09:10): R3


def test_earliest_arrivals_equal_the_time_expanded_reference(tmp_path):
    """1,000 random queries (origin, departure time) on five random feeds: the arrival at
    every station equals the reference's; with a random egress per station, the pruned scan
    finds the same best ``arrival + egress``."""
    rng = np.random.default_rng(41)
    queries = compared = reached = 0
    for k in range(5):
        feed = read_gtfs(write_feed(tmp_path / f"r{k}", random_tables(rng, hours=(7.0, 8.5))),
                         WED)
        tt = Timetable.from_feed(feed, walk_radius=400.0, walk_speed=1.3, min_change=45.0)
        assert tt.fp_to.size > tt.n_stations  # walks between stations, not changes alone
        ref = Reference(tt)
        for _ in range(200):
            origin, t0 = int(rng.integers(tt.n_stations)), float(rng.uniform(7 * 3600, 8.25 * 3600))
            want = ref.arrivals(origin, t0)
            got = earliest_arrivals(tt, {origin: t0})
            assert np.array_equal(got.arrival, want), (k, origin, t0)
            egress = np.where(rng.random(tt.n_stations) < 0.2,
                              rng.uniform(0, 600, tt.n_stations), np.inf)
            _, total = earliest_arrivals(tt, {origin: t0}, egress=egress).best(egress)
            assert total == np.min(want + egress)
            queries += 1
            compared += want.size
            reached += int(np.isfinite(want).sum())
    assert queries == 1000 and reached > compared // 2


def test_the_shipped_feed_against_the_reference_in_a_window(subway):
    """25 queries leaving 08:00-08:15 on the Manhattan subway, connections leaving up to
    08:45 (the reference graph of the whole day is too large for a quick test)."""
    rng = np.random.default_rng(7)
    window = (h("08:00:00"), h("08:45:00"))
    ref = Reference(subway, window)
    for _ in range(25):
        origin = int(rng.integers(subway.n_stations))
        t0 = float(rng.uniform(window[0], window[0] + 900))
        got = earliest_arrivals(subway, {origin: t0}, horizon=window[1]).arrival
        assert np.array_equal(got, ref.arrivals(origin, t0))


def _calls_by_trip(feed) -> dict[int, list[tuple[str, float, float]]]:
    parent = feed.stop_parent
    station = np.where(parent >= 0, parent, np.arange(parent.size))
    out: dict[int, list] = {}
    for t, s, a, d in zip(feed.call_trip, feed.call_stop, feed.call_arrival,
                          feed.call_departure):
        out.setdefault(int(t), []).append((str(feed.stop_ids[station[s]]), float(a), float(d)))
    return out


def test_every_train_leg_is_consistent_with_the_feed(subway):
    """300 random journeys on the Manhattan subway: legs in time order from the departure on;
    each train leg boards its trip at a call of the feed at that call's departure, no earlier
    than the rider reached the station, and leaves it at a later call at that call's
    arrival; the last leg ends at the station's earliest arrival."""
    rng = np.random.default_rng(3)
    calls = _calls_by_trip(subway.feed)
    trains = night = 0
    for _ in range(300):
        o, d = (int(x) for x in rng.integers(subway.n_stations, size=2))
        t0 = float(rng.uniform(0, 23 * 3600))  # from midnight: the night's trains too
        a = earliest_arrivals(subway, {o: t0})
        legs = a.journey(d)
        if o == d or not np.isfinite(a.arrival[d]):
            continue
        assert legs and legs[-1].to_stop == subway.station_ids[d]
        assert legs[-1].end == a.arrival[d]
        at, where = t0, subway.station_ids[o]
        for leg in legs:
            assert leg.from_stop == where and leg.start >= at and leg.end >= leg.start
            if leg.mode == "train":
                trains += 1
                assert subway.feed.trip_ids[leg.trip] == leg.trip_id
                seq = calls[leg.trip]
                i = next(k for k, c in enumerate(seq) if c[0] == leg.from_stop
                         and c[2] == leg.start)
                assert any(c[0] == leg.to_stop and c[1] == leg.end for c in seq[i + 1:])
                assert subway.feed.route_ids[subway.feed.trip_route[leg.trip]] == leg.route_id
                night += int(subway.feed.trip_day[leg.trip] == -1)
            else:
                assert leg.mode == "walk" and leg.to_stop != leg.from_stop
            at, where = leg.end, leg.to_stop
    assert trains > 300 and night > 0


def test_the_stations_snap_to_the_manhattan_streets(subway):
    from dispatch.space.roads import load_network

    net = load_network("manhattan_osm", base=Path("."))
    nodes, metres = subway.snap(net)
    assert nodes.shape == metres.shape == (150,)
    assert ((0 <= nodes) & (nodes < len(net.xy))).all()
    assert np.median(metres) < 50 and metres.max() < 200  # measured: 20 m, 150 m


def test_reading_and_routing_import_no_pandas():
    """A run must not load pandas (pyarrow's conversions to numpy would): a fresh process
    reads the shipped feed, builds its timetable and routes, and ends without pandas."""
    import os
    import subprocess
    import sys

    from tests.conftest import ROOT

    code = ("import sys, datetime as dt\n"
            "from pathlib import Path\n"
            "from dispatch.files.gtfs import feed_path, read_gtfs\n"
            "from dispatch.space.transit import Timetable\n"
            "from dispatch.space.csa import earliest_arrivals\n"
            "tt = Timetable.from_feed(read_gtfs(feed_path('nyc_subway', Path('.')), "
            "dt.date(2026, 9, 23)))\n"
            "a = earliest_arrivals(tt, {tt.station('A02'): 30000.0})\n"
            "assert a.journey(tt.station('R27'))\n"
            "print('pandas' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=False, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"
