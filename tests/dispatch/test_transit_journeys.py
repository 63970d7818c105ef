"""Door-to-door journeys with public transport (dispatch.space.journeys): walks to and from
stations found by distance, the best journey summed up as a mode choice option, a fleet
feeder as an access or an egress, and a rider's four options, on the hand-made feed (known
answers) and on the Manhattan subway (each option's times add up to its door-to-door time)."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest

from dispatch.files.gtfs import feed_path, read_gtfs
from dispatch.space.journeys import Part, access, best_journey, rider_options
from dispatch.space.transit import Timetable
from tests.dispatch.gtfs_feeds import _place, tiny_tables, write_feed


def h(text: str) -> float:
    hh, mm, ss = (int(x) for x in text.split(":"))
    return hh * 3600 + mm * 60 + ss


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Timetable:
    folder = write_feed(tmp_path_factory.mktemp("tiny"), tiny_tables())
    return Timetable.from_feed(read_gtfs(folder, dt.date(2026, 3, 11)))


def _adds_up(option, depart) -> bool:
    return math.isclose(option.ivt + option.wait + option.walk + option.change,
                        option.arrive - depart, abs_tol=1e-6)


def test_access_finds_the_stations_within_the_walk(tiny):
    lon, lat = _place(100.0, 0.0)  # 100 m east of A, 1,900 m west of B
    near = access(tiny, lon, lat, max_walk=500.0, walk_speed=1.0)
    assert list(near) == [tiny.station("A")]
    assert near[tiny.station("A")].walk == pytest.approx(100.0, abs=0.5)
    assert len(access(tiny, lon, lat, max_walk=2000.0, walk_speed=1.0)) == 2


def test_walk_train_change_train_walk(tiny):
    """Ready 07:58:00, 100 s to A: R1 08:00 -> B 08:05, 180 s change misses G1 (08:07), G2
    08:12 -> E 08:18, 50 s to the goal: 08:18:50."""
    a, e = tiny.station("A"), tiny.station("E")
    j = best_journey(tiny, h("07:58:00"), {a: Part(walk=100.0)}, {e: Part(walk=50.0)})
    assert j.arrive == h("08:18:50")
    assert [(leg.mode, leg.trip_id) for leg in j.legs] == [("train", "R1"), ("train", "G2")]
    o = j.option
    assert (o.kind, o.ivt, o.wait, o.walk, o.change, o.changes) == \
        ("train", 660.0, 20.0, 150.0, 420.0, 1)
    assert _adds_up(o, j.depart)


def test_a_fleet_feeder_as_an_access_or_an_egress(tiny):
    """A vehicle (60 s wait, 300 s ride) drops the rider at B at 08:06 (no change time: they
    did not leave a train): G1 at 08:07, E at 08:13. A vehicle from C (its wait 100 s, its
    ride 500 s) after R1 (C at 08:10): 08:20."""
    b, c, e = tiny.station("B"), tiny.station("C"), tiny.station("E")
    j = best_journey(tiny, h("08:00:00"), {b: Part(wait=60.0, ivt=300.0)}, {e: Part()},
                     kind="fleet+train")
    assert j.arrive == h("08:13:00") and j.option.kind == "fleet+train"
    assert (j.option.wait, j.option.ivt, j.option.walk) == (60.0 + 60.0, 300.0 + 360.0, 0.0)
    a = tiny.station("A")
    k = best_journey(tiny, h("08:00:00"), {a: Part()}, {c: Part(wait=100.0, ivt=500.0)},
                     kind="train+fleet")
    assert k.arrive == h("08:20:00")
    assert (k.option.ivt, k.option.walk, k.option.wait) == (600.0 + 500.0, 0.0, 100.0)
    assert _adds_up(j.option, j.depart) and _adds_up(k.option, k.depart)


def test_no_journey(tiny):
    a, e = tiny.station("A"), tiny.station("E")
    assert best_journey(tiny, h("09:00:00"), {e: Part()}, {a: Part()}) is None  # none back
    assert best_journey(tiny, h("09:00:00"), {a: Part()}, {}) is None
    assert best_journey(tiny, h("08:00:00"), {a: Part(walk=10.0)},
                        {a: Part(walk=10.0)}) is None  # no train beats walking


def _fleet_on(points: dict[int, np.ndarray]):
    """A fleet that waits 60 s and drives straight lines at 10 m/s between ``points``."""
    def estimate(u: int, v: int, ready: float):
        return 60.0, float(np.hypot(*(points[u] - points[v]))) / 10.0
    return estimate


def test_the_four_options_of_a_rider(tiny):
    """From 100 m east of A to 50 m east of E, ready 07:58:00, walking at 1 m/s; a fleet
    waiting 60 s and driving straight at 10 m/s (stations are their own street nodes)."""
    o_xy, g_xy = np.array([100.0, 0.0]), np.array([2050.0, 2000.0])
    ends = (_place(*o_xy), _place(*g_xy))
    points = {s: tiny.xy[s] - tiny.xy[tiny.station("A")] for s in range(tiny.n_stations)}
    points.update({100: o_xy, 101: g_xy})
    snapped = (np.arange(tiny.n_stations), np.zeros(tiny.n_stations))
    t0 = h("07:58:00")
    got = {o.kind: (o, j) for o, j in rider_options(
        tiny, t0, ends, (100, 101), _fleet_on(points), snapped=snapped, max_walk=500.0,
        walk_speed=1.0)}
    assert set(got) == {"fleet", "train", "fleet+train", "train+fleet"}
    door = math.hypot(1950.0, 2000.0) / 10.0
    assert got["fleet"][0].arrive == pytest.approx(t0 + 60.0 + door)
    assert got["train"][0].arrive == pytest.approx(h("08:18:50"), abs=0.5)
    feeder = got["fleet+train"][0]  # to B (08:02:10), G1 08:07 -> E 08:13, 50 s walk
    assert feeder.arrive == pytest.approx(h("08:13:50"), abs=0.5)
    assert (feeder.wait, feeder.ivt) == pytest.approx((60.0 + 290.0, 190.0 + 360.0), abs=0.5)
    after = got["train+fleet"][0]  # walk to A, R1 to B (08:05), vehicle from B
    assert after.arrive == pytest.approx(h("08:05:00") + 60.0 + math.hypot(50.0, 2000.0) / 10,
                                         abs=0.5)
    assert got["train+fleet"][1].legs[-1].to_stop == "B"
    for option, _ in got.values():
        assert _adds_up(option, t0)
    no_fleet = rider_options(tiny, t0, ends, (100, 101), None, snapped=snapped,
                             max_walk=500.0, walk_speed=1.0)
    assert [o.kind for o, _ in no_fleet] == ["train"]


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
        assert _adds_up(opt, t0)
        assert min(opt.ivt, opt.wait, opt.walk, opt.change) >= 0
        assert opt.changes == sum(leg.mode == "train" for leg in j.legs) - 1
    assert found > 50
