"""Every row about a request traceable to its trip: ``request_id`` in the tasks, events and
assignments tables is the trace row's id.

Traces on the 6 x 5 grid (node ``n`` at ``((n % 6) * 100, (n // 6) * 100)`` metres) with integer
ids, shuffled string ids and no id column (the 1-based data row), booked ahead (their own
``booked_at`` column or ``[tasks] prebook_share``: they enter the run in booking order, not the
file's) and with riders walking, some rows left out (``[tasks] max_snap``): joined to the file by
``request_id``, every task finds exactly its own row, pickup and drop-off where the row put them,
and every event and bid about a task carries that task's id (where it was released, picked up
and dropped off agree with the row and the tasks table). Integer ids are written as integers,
others as strings. A duplicate or blank id is one error naming the file, the column and the row;
a missing ``[tasks] id_column`` one naming the scenario file, the key and the columns there.
Generated demand's ids are its draw numbers. A start file's ``vehicle_id`` is the vehicle's id
in every table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dispatch.errors import ScenarioError
from dispatch.files.traces import trip_ids
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import SOURCES, road_scenario, write_csv

BLOCK = 100.0


def _xy(node: int) -> tuple[float, float]:
    return (node % 6) * BLOCK, (node // 6) * BLOCK


def _rows(seed: int, n: int, ids, *, booked: float = 0.0, far: int = 0) -> list[dict]:
    """``n`` trips with ids ``ids`` (None: no id column), ``booked`` of them booked ahead
    (a random lead of up to 15 min), ``far`` of them (random rows) 5 km from the grid."""
    rng = np.random.default_rng(seed)
    t, rows = 0.0, []
    out = set(rng.choice(n, size=far, replace=False).tolist()) if far else set()
    for i in range(n):
        t += float(rng.exponential(20.0))
        o, d = (int(v) for v in rng.choice(30, size=2, replace=False))
        (ox, oy), (dx, dy) = _xy(o), _xy(d)
        if i in out:
            ox += 5000.0
        row = {"t": round(t, 3), "origin_x": ox, "origin_y": oy, "dest_x": dx, "dest_y": dy}
        if booked:
            row["booked_at"] = round(max(t - float(rng.uniform(60, 900)), 0.0), 3) \
                if rng.random() < booked else ""
        if ids is not None:
            row = {"request_id": ids[i], **row}
        rows.append(row)
    return rows


def _write(directory: Path, rows: list[dict], suffix: str = ".csv") -> str:
    name = "trips" + suffix
    if suffix == ".csv":
        write_csv(directory / name, list(rows[0]), [list(r.values()) for r in rows])
    else:
        pq.write_table(pa.Table.from_pylist(rows), directory / name)
    return name


def _scenario(directory: Path, trace: str, *, tasks: str = "", extra: str = "",
              capacity: int = 1, fleet: str = "agents = 4") -> Path:
    return road_scenario(directory, tasks=f'source = "trace"\ntrace = "{trace}"\n'
                         f"max_wait = 400.0\n{tasks}", fleet=f"{fleet}\ncapacity = {capacity}",
                         allocator="hungarian", extra=extra,
                         network='network = "manhattan"\nblocks = [6, 5]\n'
                                 f"block = {BLOCK}\nspeed = 10.0")


def _run(path: Path) -> dict[str, pa.Table]:
    [spec] = load_scenario(path).runs()
    return run_one(spec).tables


def _tables(directory: Path, trace: str, **kw) -> dict[str, pa.Table]:
    return _run(_scenario(directory, trace, **kw))


def _check_rows_name_their_task(tables: dict[str, pa.Table]) -> pd.DataFrame:
    """Every row of events and assignments about a task carries that task's request_id (the
    tasks table's; rows about no task: null), one request per task and one task per request,
    all three tables of one type; the tasks table as pandas."""
    typ = tables["tasks"].schema.field("request_id").type
    assert typ in (pa.int64(), pa.string())
    for name in ("events", "assignments"):
        assert tables[name].schema.field("request_id").type == typ, name
    tasks = tables["tasks"].to_pandas()
    assert tasks["request_id"].is_unique and tasks["request_id"].notna().all()
    of_task = dict(zip(tasks["task_id"], tasks["request_id"]))
    for name in ("events", "assignments"):
        df = tables[name].to_pandas()
        about = df["task_id"] >= 0
        assert df.loc[~about, "request_id"].isna().all(), name
        assert (df.loc[about, "request_id"] == df.loc[about, "task_id"].map(of_task)).all(), name
        assert about.any(), name
    return tasks


def _check_join(tables: dict[str, pa.Table], rows: list[dict], ids: list, left_out=(), *,
                walking: bool = False) -> None:
    """Each task joins to exactly one row of the file by ``request_id`` (typed as ``ids``: ints
    or strings), its pickup and drop-off the row's; every row but ``left_out`` (positions) has
    its task; each task's release and pickup events are at the row's pickup, the release no
    later than its time, its drop-off event where the tasks table says it alighted (door to
    door: the row's drop-off)."""
    want = pa.int64() if all(type(i) is int for i in ids) else pa.string()
    assert tables["tasks"].schema.field("request_id").type == want
    tasks = _check_rows_name_their_task(tables)
    assert tasks["request_id"].map(type).eq(int if want == pa.int64() else str).all()
    trace = pd.DataFrame(rows).assign(request_id=ids)
    joined = tasks.merge(trace, on="request_id", how="left", validate="one_to_one",
                         suffixes=("", "_file"), indicator=True)
    assert (joined["_merge"] == "both").all()
    assert np.allclose(joined[["x", "y", "dropoff_x", "dropoff_y"]].to_numpy(),
                       joined[["origin_x", "origin_y", "dest_x", "dest_y"]].to_numpy())
    assert np.allclose(joined["released_at"], joined["t"])  # the requested departure
    kept = {i for k, i in enumerate(ids) if k not in set(left_out)}
    assert set(tasks["request_id"]) == kept
    assert (tasks["state"] == "completed").mean() > 0.5  # the join is tested on served trips

    events = tables["events"].to_pandas()
    ev = events.merge(joined, on="request_id", suffixes=("", "_task"), validate="many_to_one")
    release = ev[ev["event"] == "release"]
    assert len(release) == len(tasks)
    assert np.allclose(release[["x", "y"]].to_numpy(), release[["origin_x", "origin_y"]])
    assert (release["t"] <= release["t_task"] + 1e-9).all()  # "t" of the file: t_task
    # a pickup event is at the requested pickup (where the rider walked from, walking), a
    # drop-off event where the vehicle let the rider off
    for event, cols in (("pickup", ["origin_x", "origin_y"]),
                        ("dropoff", ["alight_x", "alight_y"])):
        got = ev[ev["event"] == event]
        assert len(got) == (tasks["picked_up_at"].notna() if event == "pickup" else
                            tasks["state"] == "completed").sum()
        assert np.allclose(got[["x", "y"]].to_numpy(), got[cols].to_numpy()), event
    served = joined[joined["state"] == "completed"]
    door = served[["board_x", "board_y", "alight_x", "alight_y"]].to_numpy()
    asked = served[["origin_x", "origin_y", "dest_x", "dest_y"]].to_numpy()
    if walking:
        assert not np.allclose(door, asked)  # some rider walked: the test sees the difference
    else:
        assert np.allclose(door, asked)


CASES = {
    # name: (ids written (None: no column), the ids the tables hold)
    "integer": (lambda n, rng: [int(1000 + 7 * k) for k in rng.permutation(n)],
                lambda ids: ids),
    "shuffled strings": (lambda n, rng: [f"trip-{k:03d}" for k in rng.permutation(n)],
                         lambda ids: ids),
    "no column": (lambda n, rng: None, lambda ids: None),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("mode", ["immediate", "booked_at", "prebook_share", "walking"])
def test_every_row_joins_to_its_own_trip(tmp_path, case, mode):
    n, rng = 30, np.random.default_rng(len(case) + len(mode))
    written = CASES[case][0](n, rng)
    ids = CASES[case][1](written) if written is not None else list(range(1, n + 1))
    rows = _rows(5, n, written, booked=0.5 if mode == "booked_at" else 0.0, far=3)
    left_out = [k for k, r in enumerate(rows) if r["origin_x"] > 1000]
    tasks = {"prebook_share": "prebook_share = 0.5\nprebook_lead = 600.0",
             "walking": "max_walk = 150.0\nwalk_speed = 1.4"}.get(mode, "")
    trace = _write(tmp_path, rows)
    got = _tables(tmp_path, trace, tasks=tasks + "\nmax_snap = 200.0",
                  extra='prebook = "at_booking"' if "book" in mode else "",
                  capacity=2 if mode == "walking" else 1)
    if "book" in mode:
        t = got["tasks"].to_pandas()
        assert t["booked_at"].notna().any()
        # booked trips enter first: the task ids do not follow the file's rows
        assert t.sort_values("task_id")["request_id"].tolist() != \
            [i for k, i in enumerate(ids) if k not in left_out]
    _check_join(got, rows, ids, left_out, walking=mode == "walking")


def test_parquet_integer_ids_are_integers(tmp_path):
    ids = [5, 3, 9, 1, 7, 2, 8, 4, 6, 10]
    rows = _rows(2, len(ids), ids)
    _check_join(_tables(tmp_path, _write(tmp_path, rows, ".parquet")), rows, ids)


def test_trip_id_and_id_columns_are_read_the_first_found(tmp_path):
    rows = [{"trip_id": f"a{i}", "id": f"b{i}", **r} for i, r in
            enumerate(_rows(4, 12, None))]
    _check_join(_tables(tmp_path, _write(tmp_path, rows)), rows, [f"a{i}" for i in range(12)])


def test_id_column_names_the_column(tmp_path):
    """``[tasks] id_column`` wins over the columns read by default."""
    rows = [{"ride": 900 - i, "request_id": f"x{i}", **r}
            for i, r in enumerate(_rows(4, 12, None))]
    got = _tables(tmp_path, _write(tmp_path, rows), tasks='id_column = "ride"')
    _check_join(got, rows, [900 - i for i in range(12)])


@pytest.mark.parametrize("tasks, key, words", [
    ('id_column = "rid"', "tasks.id_column",
     ["trips.csv has no column 'rid'", "did you mean 'ride'?",
      "(its columns: ride, t, origin_x, origin_y, dest_x, dest_y)"]),
    ('id_colum = "ride"', "tasks.id_colum", ["unknown key (did you mean 'id_column'?"]),
    ("id_column = 3", "tasks.id_column", ["must be a non-empty string, got 3"]),
])
def test_a_wrong_id_column_is_one_line_naming_the_key(tmp_path, tasks, key, words):
    rows = [{"ride": i, **r} for i, r in enumerate(_rows(4, 6, None))]
    path = _scenario(tmp_path, _write(tmp_path, rows), tasks=tasks)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}: {key}: ") and "\n" not in msg
    for w in words:
        assert w in msg


def test_id_column_without_a_trace_is_refused(tmp_path):
    path = road_scenario(tmp_path, tasks=SOURCES["static"] + '\nid_column = "ride"')
    with pytest.raises(ScenarioError, match="tasks.id_column: is only used when source = "
                                            "'trace'"):
        load_scenario(path)


@pytest.mark.parametrize("bad, message", [("dup", "row 4, column request_id"),
                                          ("", "row 3, column request_id")])
def test_duplicate_or_blank_ids_are_refused_naming_the_row(tmp_path, bad, message):
    ids = ["a", "b", "c", "d", "e"]
    ids[2] = "" if bad == "" else "x"
    if bad == "dup":
        ids[3] = "x"
    path = _scenario(tmp_path, _write(tmp_path, _rows(1, 5, ids)))
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    # the scenario file and its key, then the trace, its row and column
    assert msg.startswith(f"{path}: tasks.trace: trips.csv: {message}: ") and "\n" not in msg
    if bad == "dup":
        assert "'x'" in msg and "row 3" in msg.split(": ", 2)[-1]


def test_duplicate_ids_of_a_named_column_are_refused(tmp_path):
    rows = [{"ride": [4, 8, 15, 8, 23][i], **r} for i, r in enumerate(_rows(1, 5, None))]
    path = _scenario(tmp_path, _write(tmp_path, rows), tasks='id_column = "ride"')
    with pytest.raises(ScenarioError, match=r"trips.csv: row 4, column ride: ride '8' is also "
                                            r"the id of row 2: ids must be unique"):
        load_scenario(path)


@pytest.mark.parametrize("cells, want", [
    (["3", "-12", "0", "40"], [3, -12, 0, 40]),
    ([3, 12, 40], [3, 12, 40]),  # a Parquet file's integers
    (["3", "007", "40"], ["3", "007", "40"]),  # a leading zero is part of the id
    (["3", "+4"], ["3", "+4"]),
    (["3", "4.0"], ["3", "4.0"]),
    (["3", " 4"], ["3", " 4"]),
    (["3", str(2**63)], ["3", str(2**63)]),  # beyond int64
    (["a1", "b2"], ["a1", "b2"]),
])
def test_ids_are_integers_only_where_every_one_is_written_as_one(cells, want):
    got = trip_ids(Path("trips.csv"), "request_id", cells, len(cells))
    assert got.tolist() == want and [type(v) for v in got.tolist()] == [type(v) for v in want]
    assert got.dtype == (np.int64 if type(want[0]) is int and all(
        type(v) is int for v in want) else object)


def test_without_an_id_column_ids_are_the_data_rows():
    assert trip_ids(Path("t.csv"), None, None, 4).tolist() == [1, 2, 3, 4]


@pytest.mark.parametrize("source", ["static", "periodic", "poisson"])
def test_generated_demand_ids_are_the_draw_numbers(tmp_path, source):
    path = road_scenario(tmp_path, tasks=SOURCES[source], allocator="hungarian")
    tables = _run(path)
    tasks = _check_rows_name_their_task(tables)
    assert tables["tasks"].schema.field("request_id").type == pa.int64()
    # drawn and released in one order: the draw number is the task id
    assert len(tasks) and (tasks["request_id"] == tasks["task_id"]).all()


def test_generated_booked_requests_keep_their_draw_numbers(tmp_path):
    """Booked generated requests enter the dispatch ahead of their departure: the task ids leave
    the draw order, the request ids keep it (0, 1, ... in the order they were drawn)."""
    path = road_scenario(tmp_path, tasks='source = "poisson"\nrate = 0.05\ncount = 40\n'
                         'prebook_share = 0.5\nprebook_lead = 400.0',
                         allocator="hungarian", extra='prebook = "lead"\nprebook_lead = 120.0')
    tasks = _check_rows_name_their_task(_run(path))
    assert sorted(tasks["request_id"]) == list(range(40))
    # drawn when booked (a booked request) or released (an immediate one), in that order
    drawn = tasks["booked_at"].fillna(tasks["released_at"])
    assert tasks["booked_at"].notna().any() and tasks["booked_at"].isna().any()
    assert drawn[tasks.sort_values("request_id").index].is_monotonic_increasing
    assert not (tasks["request_id"] == tasks["task_id"]).all()


def test_ids_read_at_once_are_the_ids_read_row_by_row(tmp_path, monkeypatch):
    """pyarrow's CSV reader and the row-by-row reader give the same ids, as written."""
    from dispatch.files import tables
    from dispatch.files.traces import read_trace

    ids = [" 7", "007", "x,y", 'say "hi"', "8.0", "é"]
    path = tmp_path / _write(tmp_path, _rows(6, len(ids), ids))
    fast = read_trace(path, "road", None)
    monkeypatch.setattr(tables.Table, "_read_csv_at_once", lambda self, want: None)
    slow = read_trace(path, "road", None)
    assert fast.ids.tolist() == slow.ids.tolist() == [ids[r - 1] for r in fast.row]


def test_an_outside_join_finds_each_trip(tmp_path):
    """As a study would: a trace of shuffled string ids with date-times, booked rows and bad
    rows (departing before the run's start, or 5 km off the map), run from the command line's
    results folder and joined back with pandas and DuckDB reading the files as written: every
    task joins to exactly its row, pickup and drop-off agreeing; the bad rows have none."""
    duckdb = pytest.importorskip("duckdb")
    from dispatch.run.cli import main

    n, rng = 40, np.random.default_rng(11)
    rows = _rows(3, n, [f"r{k:02d}-{'abc'[k % 3]}" for k in rng.permutation(n)], booked=0.4,
                 far=3)
    day = pd.Timestamp("2024-03-05 08:00:00")
    for k, r in enumerate(rows):
        when = day + pd.Timedelta(seconds=r.pop("t") - (900 if k in (4, 9) else 0))
        booked = r.pop("booked_at")
        r["departure_time"] = str(when)
        r["booked_at"] = "" if booked == "" or k in (4, 9) else str(day + pd.Timedelta(
            seconds=booked))
    bad = {4, 9} | {k for k, r in enumerate(rows) if r["origin_x"] > 1000}
    trace = _write(tmp_path, rows)
    path = _scenario(tmp_path, trace, tasks=f'start = "{day.isoformat()}"\nmax_snap = 200.0',
                     extra='prebook = "at_booking"')
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 0

    trips = pd.read_csv(tmp_path / trace, dtype={"request_id": str})
    tasks = pd.read_parquet(tmp_path / "out" / "tasks")
    assert tasks["booked_at"].notna().any()
    joined = trips.merge(tasks, on="request_id", how="left", validate="one_to_one")
    has = joined["task_id"].notna()
    assert set(np.flatnonzero(~has)) == bad
    j = joined[has]
    assert np.allclose(j[["x", "y", "dropoff_x", "dropoff_y"]].to_numpy(),
                       j[["origin_x", "origin_y", "dest_x", "dest_y"]].to_numpy())

    sql = f"""SELECT r.request_id, r.origin_x, t.x, r.dest_y, t.dropoff_y
              FROM read_csv('{tmp_path / trace}', all_varchar = true) AS r
              JOIN read_parquet('{tmp_path}/out/tasks/**/*.parquet', hive_partitioning = true)
                AS t ON r.request_id = CAST(t.request_id AS VARCHAR)"""
    got = duckdb.sql(sql).fetchall()
    assert len(got) == n - len(bad) == len({g[0] for g in got})
    assert all(float(ox) == x and float(dy) == ty for _, ox, x, dy, ty in got)


def test_a_start_files_vehicle_ids_are_the_ids_in_every_table(tmp_path):
    """Vehicles numbered 17, 3, 42, 8 by their start file, placed on nodes 0, 5, 24, 29, and
    vehicle 42 breaking down for good at 300 s by a faults file: the vehicles table places
    each id where the file does, and every table names vehicles by those ids only; each
    vehicle's first drive starts from its own start; 42's breakdown is 42's."""
    fleet = {17: 0, 3: 5, 42: 24, 8: 29}
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], list(fleet.items()))
    write_csv(tmp_path / "fail.csv", ["t", "vehicle_id", "duration"], [(300.0, 42, "inf")])
    rows = _rows(6, 30, None)
    tables = _tables(tmp_path, _write(tmp_path, rows), fleet='start = "fleet.csv"',
                     extra='[faults]\nfile = "fail.csv"')
    vehicles = tables["vehicles"].to_pandas().set_index("agent_id")
    assert sorted(vehicles.index) == sorted(fleet)
    for vid, node in fleet.items():
        assert tuple(vehicles.loc[vid, ["x0", "y0"]]) == _xy(node)
    ids = set(fleet)
    tasks = tables["tasks"].to_pandas()
    assert set(tasks["agent_id"]) - {-1} <= ids and (tasks["agent_id"] >= 0).any()
    assert set(tables["assignments"].to_pandas()["agent_id"]) <= ids
    events = tables["events"].to_pandas()
    assert set(events["agent_id"]) - {-1} == ids  # every vehicle drove
    first = events[events["event"] == "depart"].groupby("agent_id").first()
    for vid, node in fleet.items():
        assert tuple(first.loc[vid, ["x", "y"]]) == _xy(node)
    broke = events[events["event"] == "breakdown"]
    assert broke["agent_id"].tolist() == [42] and broke["t"].tolist() == [300.0]
    assert vehicles["failures"].to_dict() == {vid: int(vid == 42) for vid in vehicles.index}
    assert (events.loc[events["t"] > 300.0, "agent_id"] != 42).all()  # down for good
    # the completions per vehicle agree between tables written apart
    done = tasks[tasks["state"] == "completed"].groupby("agent_id").size()
    assert (vehicles["tasks_completed"] == done.reindex(vehicles.index, fill_value=0)).all()
