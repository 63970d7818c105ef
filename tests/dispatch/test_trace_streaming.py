"""Trace demand streams: a CSV trace is read into number arrays, by pyarrow where every cell
is a number and else in chunks of rows (either way the trips of an independent
``csv.DictReader`` reference, and the same first error as a read of the whole file column by
column), its requests are made as the clock reaches them, and a scenario parsed again reuses
the trips read for the same bytes."""

from __future__ import annotations

import csv
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import simpy

from dispatch.config.tasks import TaskConfig
from dispatch.errors import ScenarioError
from dispatch.events import EventBus
from dispatch.files import tables as table_files
from dispatch.files.traces import read_trace
from dispatch.plan.demand import RoadDemand
from dispatch.plan.tasks import TaskBook, TaskSource
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import manhattan

HEADER = ["request_id", "t", "origin_x", "origin_y", "dest_x", "dest_y", "max_wait",
          "passengers"]


def write_trace(path: Path, rows) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(HEADER)
        w.writerows(rows)
    return path


def random_rows(rng: np.random.Generator, n: int) -> list[list[str]]:
    rows = []
    for i in range(n):
        wait = "" if rng.random() < 0.3 else f"{rng.uniform(10, 900):.2f}"
        seats = "" if rng.random() < 0.5 else str(int(rng.integers(1, 4)))
        rows.append([str(i), f"{rng.uniform(0, 3600):.3f}",
                     *(f"{v:.3f}" for v in rng.uniform(0, 500, 4)), wait, seats])
    return rows


def reference(path: Path) -> dict[str, list]:
    """The trips as an independent reader sees them: every row, sorted by time (stable)."""
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    order = sorted(range(len(rows)), key=lambda i: float(rows[i]["t"]))
    num = (lambda v, blank: blank if not v.strip() else float(v))
    return {
        "t": [float(rows[i]["t"]) for i in order],
        "origin": [[float(rows[i]["origin_x"]), float(rows[i]["origin_y"])] for i in order],
        "dest": [[float(rows[i]["dest_x"]), float(rows[i]["dest_y"])] for i in order],
        "max_wait": [num(rows[i]["max_wait"], -1.0) for i in order],
        "passengers": [int(num(rows[i]["passengers"], 1.0)) for i in order],
        "row": [i + 1 for i in order],
    }


@pytest.mark.parametrize("chunk", [1, 3, 64, 10**6])
def test_a_trace_read_in_chunks_is_the_whole_file(tmp_path, monkeypatch, chunk):
    path = write_trace(tmp_path / "trips.csv", random_rows(np.random.default_rng(7), 200))
    monkeypatch.setattr(table_files, "CHUNK_ROWS", chunk)
    trips = read_trace(path, "road", None)
    want = reference(path)
    assert trips.layout == "metres" and len(trips) == 200
    assert trips.t.tolist() == want["t"]
    assert trips.origin.tolist() == want["origin"] and trips.dest.tolist() == want["dest"]
    assert np.nan_to_num(trips.max_wait, nan=-1.0).tolist() == want["max_wait"]
    assert trips.passengers.tolist() == want["passengers"]
    assert trips.row.tolist() == want["row"]


@pytest.mark.parametrize("chunk", [2, 10**6])
def test_the_first_column_checked_names_its_error_whatever_the_row(tmp_path, monkeypatch,
                                                                   chunk):
    """Row 2's origin_x and row 5's t are both bad: t is checked first (as a reader of the
    whole file column by column does), even when the rows fall in different chunks."""
    rows = random_rows(np.random.default_rng(1), 6)
    rows[1][2] = "north"
    rows[4][1] = "soon"
    path = write_trace(tmp_path / "trips.csv", rows)
    monkeypatch.setattr(table_files, "CHUNK_ROWS", chunk)
    with pytest.raises(ScenarioError, match=r"row 5.*t is not a number \('soon'\)"):
        read_trace(path, "road", None)
    rows[4][1] = "12.0"
    write_trace(path, rows)
    with pytest.raises(ScenarioError, match=r"row 2.*origin_x is not a number \('north'\)"):
        read_trace(path, "road", None)


def test_a_row_check_names_the_first_failing_row_not_the_first_in_time(tmp_path):
    rows = random_rows(np.random.default_rng(2), 5)
    rows[3][1], rows[3][6] = "5.0", "-3"     # row 4: max_wait not > 0, early in time
    rows[1][1], rows[1][7] = "3000", "2.5"  # row 2: passengers not whole, late in time
    path = write_trace(tmp_path / "trips.csv", rows)
    with pytest.raises(ScenarioError, match=r"row 2.*passengers = 2.5 is not a whole number"):
        read_trace(path, "road", None)


def all_numbers(tmp_path: Path) -> Path:
    rows = random_rows(np.random.default_rng(8), 300)
    for r in rows:
        r[6], r[7] = r[6] or "600", r[7] or "1"
    return write_trace(tmp_path / "trips.csv", rows)


def test_a_trace_of_numbers_is_read_at_once_as_row_by_row(tmp_path, monkeypatch):
    path = all_numbers(tmp_path)
    used = []
    at_once = table_files.Table._read_csv_at_once
    monkeypatch.setattr(table_files.Table, "_read_csv_at_once",
                        lambda self, want: used.append(at_once(self, want)) or used[-1])
    fast = read_trace(path, "road", None)
    assert used and used[0] is not None  # pyarrow read it
    monkeypatch.setattr(table_files.Table, "_read_csv_at_once", lambda self, want: None)
    slow = read_trace(path, "road", None)
    want = reference(path)
    for trips in (fast, slow):
        assert trips.t.tolist() == want["t"] and trips.row.tolist() == want["row"]
        assert trips.origin.tolist() == want["origin"] and trips.dest.tolist() == want["dest"]
        assert trips.max_wait.tolist() == want["max_wait"]
        assert trips.passengers.tolist() == want["passengers"]


@pytest.mark.parametrize("cell, what", [("", "t is not a number"), ("1_0", None),
                                        ("inf", "t is not finite"), (" 7 ", None)])
def test_a_cell_pyarrow_reads_otherwise_is_read_row_by_row(tmp_path, cell, what):
    """A blank, an underscore, an infinity, spaces: Python's float() decides, as row by row."""
    rows = [list(r) for r in random_rows(np.random.default_rng(9), 4)]
    for r in rows:
        r[6], r[7] = r[6] or "600", r[7] or "1"
    rows[2][1] = cell
    path = write_trace(tmp_path / "trips.csv", rows)
    if what is None:
        assert float(cell) in read_trace(path, "road", None).t.tolist()
    else:
        with pytest.raises(ScenarioError, match=f"row 3: {what}"):
            read_trace(path, "road", None)


def test_reading_a_large_trace_holds_numbers_not_a_string_per_cell(tmp_path, monkeypatch):
    """100,000 rows (about 4 MB) read row by row (the way a trace with a blank cell is read;
    pyarrow's memory is not traced): the read peaks at a few times the file, not at the
    ~70 MB of a string per cell and a dict per row."""
    monkeypatch.setattr(table_files.Table, "_read_csv_at_once", lambda self, want: None)
    rng = np.random.default_rng(3)
    n = 100_000
    path = tmp_path / "big.csv"
    t = np.sort(rng.uniform(0, 86400, n))
    xy = rng.uniform(0, 4000, (n, 4))
    with path.open("w") as fh:
        fh.write("t,origin_x,origin_y,dest_x,dest_y\n")
        fh.writelines("%.3f,%.2f,%.2f,%.2f,%.2f\n" % (a, *b) for a, b in zip(t, xy))
    size = path.stat().st_size
    tracemalloc.start()
    try:
        trips = read_trace(path, "road", None)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(trips) == n
    assert trips.t.tolist() == [float("%.3f" % a) for a in t]
    assert peak < 8 * size, f"peak {peak / 2**20:.1f} MiB for a {size / 2**20:.1f} MiB file"


class CountingDemand(RoadDemand):
    """A road demand that counts the requests its trace iterator has made."""

    made = 0

    def from_trace(self, trips):
        for req in super().from_trace(trips):
            self.made += 1
            yield req


@pytest.mark.parametrize("count", [None, 3])
def test_trace_requests_are_made_as_the_clock_reaches_them(tmp_path, count):
    rows = random_rows(np.random.default_rng(4), 10)
    path = write_trace(tmp_path / "trips.csv", rows)
    trips = read_trace(path, "road", None)
    env = simpy.Environment()
    book = TaskBook(env, EventBus())
    demand = CountingDemand(manhattan(6, 6, 100.0, 10.0), np.random.default_rng(0))
    tasks = TaskConfig(source="trace", max_wait=600.0, trips=trips)
    TaskSource(env, book, demand, tasks, count, np.random.default_rng(0), notify=lambda: None,
               trips=trips)
    for t in sorted({*trips.t.tolist(), trips.t[-1] + 1.0}):
        env.run(until=t + 1e-9)
        assert demand.made == book.released  # none made before its release
    assert book.released == (10 if count is None else count)


def test_an_unknown_node_is_named_before_the_run_starts_releasing(tmp_path):
    path = tmp_path / "trips.csv"
    path.write_text("t,origin_node,dest_node\n5,1,2\n1,3,999\n2,998,4\n0.5,997,1\n")
    trips = read_trace(path, "road", None)
    demand = RoadDemand(manhattan(6, 6, 100.0, 10.0), np.random.default_rng(0))
    # pickups are checked before drop-offs, each in time order
    with pytest.raises(ScenarioError, match=r"row 4: .*no node 997"):
        demand.from_trace(trips)


def test_a_scenario_parsed_again_reuses_the_trips_of_the_same_bytes(tmp_path):
    rows = random_rows(np.random.default_rng(5), 4)
    write_trace(tmp_path / "trips.csv", rows)
    scenario = tmp_path / "s.toml"
    scenario.write_text('name = "s"\nseed = 1\nduration = 100.0\n[world]\nnetwork = '
                        '"manhattan"\nblocks = [6, 6]\nblock = 100.0\nspeed = 10.0\n[fleet]\n'
                        'agents = 2\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                        '[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\n')
    first = load_scenario(scenario).tasks.trips
    assert load_scenario(scenario).tasks.trips is first
    rows[0][1] = rows[0][1][::-1]  # the same size, other bytes: read again
    write_trace(tmp_path / "trips.csv", rows)
    again = load_scenario(scenario).tasks.trips
    assert again is not first and float(rows[0][1]) in again.t.tolist()
