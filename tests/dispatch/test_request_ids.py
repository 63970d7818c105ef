"""Every task traceable to its trip: the tasks table's ``request_id`` is the trace row's id.

Traces on the 6 x 5 grid (node ``n`` at ``((n % 6) * 100, (n // 6) * 100)`` metres) with integer
ids, shuffled string ids and no id column (the 1-based data row), booked ahead (their own
``booked_at`` column or ``[tasks] prebook_share``: they enter the run in booking order, not the
file's) and with riders walking, some rows left out (``[tasks] max_snap``): joined to the file by
``request_id``, every task finds exactly its own row, pickup and drop-off where the row put them.
A duplicate or blank id is one error naming the file, the column and the row; generated demand's
ids are its task ids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dispatch.errors import ScenarioError
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


def _tasks(directory: Path, trace: str, *, tasks: str = "", extra: str = "",
           capacity: int = 1) -> pd.DataFrame:
    path = road_scenario(directory, tasks=f'source = "trace"\ntrace = "{trace}"\n'
                         f"max_wait = 400.0\n{tasks}", fleet=f"agents = 4\ncapacity = {capacity}",
                         allocator="hungarian", extra=extra,
                         network='network = "manhattan"\nblocks = [6, 5]\n'
                                 f"block = {BLOCK}\nspeed = 10.0")
    [spec] = load_scenario(path).runs()
    return run_one(spec).tables["tasks"].to_pandas()


def _check_join(tasks: pd.DataFrame, rows: list[dict], ids: list[str], left_out=()) -> None:
    """Each task joins to exactly one row of the file by ``request_id`` (a string), its
    pickup and drop-off the row's; every row but ``left_out`` (positions) has its task."""
    assert tasks["request_id"].map(type).eq(str).all()
    trace = pd.DataFrame(rows).assign(request_id=ids)
    joined = tasks.merge(trace, on="request_id", how="left", validate="one_to_one",
                         suffixes=("", "_file"), indicator=True)
    assert (joined["_merge"] == "both").all()
    assert np.allclose(joined[["x", "y", "dropoff_x", "dropoff_y"]].to_numpy(),
                       joined[["origin_x", "origin_y", "dest_x", "dest_y"]].to_numpy())
    kept = {i for k, i in enumerate(ids) if k not in set(left_out)}
    assert set(tasks["request_id"]) == kept
    assert (tasks["state"] == "completed").mean() > 0.5  # the join is tested on served trips


CASES = {
    # name: (ids written (None: no column), the ids the tasks table holds)
    "integer": (lambda n, rng: [1000 + 7 * i for i in range(n)],
                lambda ids: [str(i) for i in ids]),
    "shuffled strings": (lambda n, rng: [f"trip-{k:03d}" for k in rng.permutation(n)],
                         lambda ids: ids),
    "no column": (lambda n, rng: None, lambda ids: None),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("mode", ["immediate", "booked_at", "prebook_share", "walking"])
def test_every_task_joins_to_its_own_row(tmp_path, case, mode):
    n, rng = 30, np.random.default_rng(len(case) + len(mode))
    written = CASES[case][0](n, rng)
    ids = CASES[case][1](written) if written is not None else [str(i) for i in range(1, n + 1)]
    rows = _rows(5, n, written, booked=0.5 if mode == "booked_at" else 0.0, far=3)
    left_out = [k for k, r in enumerate(rows) if r["origin_x"] > 1000]
    tasks = {"prebook_share": "prebook_share = 0.5\nprebook_lead = 600.0",
             "walking": "max_walk = 150.0\nwalk_speed = 1.4"}.get(mode, "")
    trace = _write(tmp_path, rows)
    got = _tasks(tmp_path, trace, tasks=tasks + "\nmax_snap = 200.0",
                 extra='prebook = "at_booking"' if "book" in mode else "",
                 capacity=2 if mode == "walking" else 1)
    if "book" in mode:
        assert got["booked_at"].notna().any()
        # booked trips enter first: the task ids do not follow the file's rows
        assert not got.sort_values("task_id")["request_id"].tolist() == \
            [i for k, i in enumerate(ids) if k not in left_out]
    if mode == "walking":
        assert (got["walk_to_board_m"] > 0).any()
    _check_join(got, rows, ids, left_out)


def test_parquet_integer_ids_are_written_in_decimal(tmp_path):
    ids = [5, 3, 9, 1, 7, 2, 8, 4, 6, 10]
    rows = _rows(2, len(ids), ids)
    got = _tasks(tmp_path, _write(tmp_path, rows, ".parquet"))
    _check_join(got, rows, [str(i) for i in ids])


def test_trip_id_and_id_columns_are_read_the_first_found(tmp_path):
    rows = [{"trip_id": f"a{i}", "id": f"b{i}", **r} for i, r in
            enumerate(_rows(4, 12, None))]
    got = _tasks(tmp_path, _write(tmp_path, rows))
    _check_join(got, rows, [f"a{i}" for i in range(12)])


@pytest.mark.parametrize("bad, message", [("dup", "row 4, column request_id"),
                                          ("", "row 3, column request_id")])
def test_duplicate_or_blank_ids_are_refused_naming_the_row(tmp_path, bad, message):
    ids = ["a", "b", "c", "d", "e"]
    ids[2] = "" if bad == "" else "x"
    if bad == "dup":
        ids[3] = "x"
    _write(tmp_path, _rows(1, 5, ids))
    with pytest.raises(ScenarioError) as e:
        _tasks(tmp_path, "trips.csv")
    msg = str(e.value)
    assert "trips.csv" in msg and message in msg and "\n" not in msg
    if bad == "dup":
        assert "'x'" in msg and "row 3" in msg.split(": ", 2)[-1]


@pytest.mark.parametrize("source", ["static", "periodic", "poisson"])
def test_generated_demand_ids_are_the_task_ids(tmp_path, source):
    path = road_scenario(tmp_path, tasks=SOURCES[source], allocator="hungarian")
    [spec] = load_scenario(path).runs()
    tasks = run_one(spec).tables["tasks"].to_pandas()
    assert len(tasks) and (tasks["request_id"] == tasks["task_id"].astype(str)).all()


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
