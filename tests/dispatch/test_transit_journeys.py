"""Door-to-door transit journeys (dispatch.space.journeys): walks to and from stations found
by distance, the best journey and its summary as a mode choice option, a fleet feeder as a
source or an egress, on the hand-made feed (known answers) and on the Manhattan subway (the
summary adds up to the door-to-door time)."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from dispatch.files.gtfs import feed_path, read_gtfs
from dispatch.space.journeys import access, best_journey
from dispatch.space.transit import Timetable
from tests.dispatch.gtfs_feeds import _place, tiny_tables, write_feed


def h(text: str) -> float:
    hh, mm, ss = (int(x) for x in text.split(":"))
    return hh * 3600 + mm * 60 + ss


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Timetable:
    folder = write_feed(tmp_path_factory.mktemp("tiny"), tiny_tables())
    return Timetable.from_feed(read_gtfs(folder, dt.date(2026, 3, 11)))


def test_access_finds_the_stations_within_the_walk(tiny):
    lon, lat = _place(100.0, 0.0)  # 100 m east of A, 1,900 m west of B
    near = access(tiny, lon, lat, max_walk=500.0, walk_speed=1.0)
    assert list(near) == [tiny.station("A")] and near[tiny.station("A")] == pytest.approx(
        100.0, abs=0.5)
    assert len(access(tiny, lon, lat, max_walk=2000.0, walk_speed=1.0)) == 2


def test_walk_train_change_train_walk(tiny):
    """Ready 07:58:00, 100 s to A: R1 08:00 -> B 08:05, 180 s change misses G1 (08:07), G2
    08:12 -> E 08:18, 50 s to the goal: 08:18:50."""
    a, e = tiny.station("A"), tiny.station("E")
    j = best_journey(tiny, h("07:58:00"), {a: 100.0}, {e: 50.0})
    assert j.arrive == h("08:18:50")
    assert [(leg.mode, leg.trip_id) for leg in j.legs] == [("train", "R1"), ("train", "G2")]
    o = j.option
    assert (o.kind, o.ivt, o.wait, o.walk, o.change, o.changes) == \
        ("train", 660.0, 20.0, 150.0, 420.0, 1)
    assert o.ivt + o.wait + o.walk + o.change == j.arrive - j.depart


def test_a_fleet_feeder_as_a_source_or_an_egress(tiny):
    """A vehicle drops the rider at B at 08:06 (no change time: they did not leave a train):
    G1 at 08:07, E at 08:13. A vehicle from C to the goal (600 s, its wait included) after
    R1: 08:10 + 600 s, counted aboard."""
    b, c, e = tiny.station("B"), tiny.station("C"), tiny.station("E")
    j = best_journey(tiny, h("08:00:00"), {b: 360.0}, {e: 0.0}, kind="fleet+train",
                     access_walks=False)
    assert j.arrive == h("08:13:00") and j.option.kind == "fleet+train"
    assert (j.option.wait, j.option.ivt, j.option.walk) == (60.0, 360.0 + 360.0, 0.0)
    a = tiny.station("A")
    k = best_journey(tiny, h("08:00:00"), {a: 0.0}, {c: 600.0}, kind="train+fleet",
                     egress_walks=False)
    assert k.arrive == h("08:20:00")
    assert (k.option.ivt, k.option.walk, k.option.wait) == (600.0 + 600.0, 0.0, 0.0)


def test_no_journey(tiny):
    a, e = tiny.station("A"), tiny.station("E")
    assert best_journey(tiny, h("09:00:00"), {e: 0.0}, {a: 0.0}) is None  # no train back
    assert best_journey(tiny, h("09:00:00"), {a: 0.0}, {}) is None
    assert best_journey(tiny, h("08:00:00"), {a: 10.0}, {a: 10.0}) is None  # walking wins


def test_manhattan_journeys_add_up():
    tt = Timetable.from_feed(read_gtfs(feed_path("nyc_subway", Path(".")),
                                       dt.date(2026, 9, 23)))
    rng = np.random.default_rng(11)
    found = 0
    for _ in range(100):
        o, d = rng.integers(tt.n_stations, size=2)
        (olon, olat), (dlon, dlat) = tt.lonlat[o] + 0.001, tt.lonlat[d] - 0.001
        src = access(tt, olon, olat, max_walk=600.0, walk_speed=1.3)
        dst = access(tt, dlon, dlat, max_walk=600.0, walk_speed=1.3)
        t0 = float(rng.uniform(6 * 3600, 22 * 3600))
        j = best_journey(tt, t0, src, dst)
        if j is None:
            continue
        found += 1
        opt = j.option
        assert opt.ivt + opt.wait + opt.walk + opt.change == pytest.approx(j.arrive - t0)
        assert min(opt.ivt, opt.wait, opt.walk, opt.change) >= 0
        assert opt.changes == sum(leg.mode == "train" for leg in j.legs) - 1
    assert found > 50
