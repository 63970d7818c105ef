"""GTFS feeds read for one service day (dispatch.files.gtfs): the calendar and its exceptions,
times past 24:00:00, untimed calls, the shipped Manhattan subway feed, a zip read as its
folder, and bad feeds refused in one line naming the file."""

from __future__ import annotations

import datetime as dt
import zipfile
from pathlib import Path

import numpy as np
import pytest

from dispatch.errors import ScenarioError
from dispatch.files.gtfs import feed_path, read_gtfs
from tests.dispatch.gtfs_feeds import tiny_tables, write_feed

WED, THU, SAT = dt.date(2026, 3, 11), dt.date(2026, 3, 5), dt.date(2026, 3, 7)
HOLIDAY = dt.date(2026, 3, 4)


@pytest.fixture
def tiny(tmp_path) -> Path:
    return write_feed(tmp_path / "tiny", tiny_tables())


def _trips(feed, day: int = 0) -> set[str]:
    return set(feed.trip_ids[feed.trip_day == day])


def test_the_calendar_picks_the_days_trips(tiny):
    """Service WK runs on weekdays; on 2026-03-04 calendar_dates removes it and adds HOL.
    The day before's R3 (24:10 to 24:20) runs after its midnight, so a day after a weekday
    has it too."""
    every = {"R1", "R2", "R3", "G1", "G2"}
    assert _trips(read_gtfs(tiny, WED)) == every and _trips(read_gtfs(tiny, WED), -1) == {"R3"}
    assert _trips(read_gtfs(tiny, THU)) == every and _trips(read_gtfs(tiny, THU), -1) == set()
    assert _trips(read_gtfs(tiny, HOLIDAY)) == {"R9"}
    assert _trips(read_gtfs(tiny, HOLIDAY), -1) == {"R3"}
    monday = read_gtfs(tiny, dt.date(2026, 3, 9))
    assert _trips(monday) == every and _trips(monday, -1) == set()  # Sunday runs nothing
    with pytest.raises(ScenarioError, match="calendar.txt: service_date: no service runs on "
                                            "2026-03-07"):
        read_gtfs(tiny, SAT)


def test_calls_are_seconds_of_the_service_day_past_midnight_too(tiny):
    feed = read_gtfs(tiny, WED)
    today, before = np.flatnonzero(feed.trip_ids == "R3")
    assert feed.trip_day[today] == 0 and feed.trip_day[before] == -1
    calls = feed.call_trip == today
    assert feed.call_arrival[calls].tolist() == [24 * 3600 + 600, 24 * 3600 + 900,
                                                 24 * 3600 + 1200]
    assert feed.call_arrival[feed.call_trip == before].tolist() == [600, 900, 1200]
    assert list(feed.stop_ids[feed.call_stop[calls]]) == ["A", "BR", "C"]
    # every trip's calls in order: arrival <= departure <= the next call's arrival
    same = feed.call_trip[1:] == feed.call_trip[:-1]
    assert (feed.call_arrival <= feed.call_departure).all()
    assert (feed.call_departure[:-1][same] <= feed.call_arrival[1:][same]).all()
    assert feed.stop_parent[list(feed.stop_ids).index("BR")] == list(feed.stop_ids).index("B")
    assert feed.transfer_seconds.tolist() == [180.0]


def test_untimed_calls_are_interpolated_and_a_zip_reads_as_its_folder(tmp_path):
    tables = tiny_tables()
    for row in tables["stop_times.txt"]:
        if row["trip_id"] == "R2" and row["stop_id"] == "BR":
            row["arrival_time"] = row["departure_time"] = ""
    folder = write_feed(tmp_path / "f", tables)
    feed = read_gtfs(folder, WED)
    r2 = feed.call_trip == int(np.flatnonzero(feed.trip_ids == "R2")[0])
    assert feed.call_arrival[r2].tolist() == [8 * 3600 + 600, 8 * 3600 + 900, 8 * 3600 + 1200]
    with zipfile.ZipFile(tmp_path / "f.zip", "w") as zf:
        for p in folder.iterdir():
            zf.write(p, f"inner/{p.name}")  # members in one folder of the zip
    z = read_gtfs(tmp_path / "f.zip", WED)
    for name in ("stop_ids", "trip_ids", "trip_day", "call_trip", "call_stop", "call_arrival",
                 "call_departure", "stop_lon", "transfer_seconds"):
        assert np.array_equal(getattr(z, name), getattr(feed, name)), name


def test_the_shipped_manhattan_subway_feed():
    """The shipped feed's weekday: 150 stations' 300 platforms, 7,444 trips (and 180 of the
    day before running after midnight), 25 routes."""
    path = feed_path("nyc_subway", Path("."))
    assert path.stat().st_size < 2**20 and (path.parent / "NOTICE.md").exists()
    feed = read_gtfs(path, dt.date(2026, 9, 23))
    today = feed.trip_day[feed.call_trip] == 0
    assert (feed.trip_day == 0).sum() == 7444 and today.sum() == 93010
    assert (feed.trip_day == -1).sum() == 180
    assert (feed.stop_parent < 0).sum() == 150 and feed.route_ids.size == 25
    assert feed.call_departure.max() > 24 * 3600  # trips run past midnight
    lon, lat = feed.stop_lon, feed.stop_lat
    assert (-74.03 < lon).all() and (lon < -73.90).all() and (40.69 < lat).all() \
        and (lat < 40.88).all()
    with pytest.raises(ScenarioError, match="no service runs on 2026-09-07"):  # Labor Day
        read_gtfs(path, dt.date(2026, 9, 7))


def _broken(tmp_path, edit) -> Path:
    tables = tiny_tables()
    edit(tables)
    return write_feed(tmp_path / "bad", tables)


def _set(table, row, **cells):
    def edit(tables):
        tables[table][row].update(cells)
    return edit


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.pop("stop_times.txt"), r"bad/stop_times\.txt: <file>: is missing"),
    (lambda t: [t.pop("calendar.txt"), t.pop("calendar_dates.txt")],
     r"calendar\.txt: <file>: is missing, and so is calendar_dates\.txt"),
    (lambda t: [r.pop("stop_sequence") for r in t["stop_times.txt"]],
     r"stop_times\.txt: stop_sequence: column is missing"),
    (_set("stop_times.txt", 4, stop_id="Z9"),
     r"stop_times\.txt: row 5: stop_id 'Z9' names no stop of stops\.txt"),
    (_set("stop_times.txt", 0, trip_id="NOPE"),
     r"stop_times\.txt: row 1: trip_id 'NOPE' names no trip of trips\.txt"),
    (_set("stop_times.txt", 2, arrival_time="8:7:00"),
     r"stop_times\.txt: row 3: arrival_time '8:7:00' is not a time H:MM:SS"),
    (_set("stop_times.txt", 1, departure_time="07:00:00"),
     r"stop_times\.txt: arrival_time: trip 'R1': times run backwards"),
    (_set("stop_times.txt", 0, arrival_time="", departure_time=""),
     r"trip 'R1': its first call has no time"),
    (_set("stop_times.txt", 1, stop_sequence=1),
     r"trip 'R1' has stop_sequence 1 twice"),
    (_set("trips.txt", 0, route_id="X"), r"trips\.txt: row 1: route_id 'X' names no route"),
    (_set("stops.txt", 0, stop_lat="north"),
     r"stops\.txt: row 1: stop_lat 'north' is not a number in \[-90, 90\]"),
    (_set("stops.txt", 5, parent_station="Q"),
     r"stops\.txt: row 6: parent_station 'Q' names no stop"),
    (_set("transfers.txt", 0, to_stop_id="Q"),
     r"transfers\.txt: row 1: to_stop_id 'Q' names no stop"),
    (_set("calendar.txt", 0, end_date="2026-12-31"),
     r"calendar\.txt: row 1: '2026-12-31' is not a date YYYYMMDD"),
])
def test_a_bad_feed_is_one_line_naming_the_file(tmp_path, edit, message):
    with pytest.raises(ScenarioError, match=message) as err:
        read_gtfs(_broken(tmp_path, edit), WED)
    assert "\n" not in str(err.value)


def test_a_missing_or_unreadable_feed_is_one_line(tmp_path):
    with pytest.raises(ScenarioError, match="nothing.zip: <file>: cannot be read: file not "
                                            "found"):
        read_gtfs(tmp_path / "nothing.zip", WED)
    (tmp_path / "junk.zip").write_bytes(b"not a zip")
    with pytest.raises(ScenarioError, match="junk.zip: <file>: is not a GTFS zip or folder"):
        read_gtfs(tmp_path / "junk.zip", WED)
