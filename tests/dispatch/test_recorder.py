"""The streaming recorder: rows go to disk in whole chunk files every ``flush_rows`` rows (so
memory stays bounded and a killed run leaves readable files), ``finish`` merges them atomically
into one ``part-0.parquet`` per table, in one Hive layout whatever the number of runs."""

from __future__ import annotations

import gc
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dispatch import __version__
from dispatch.output.parquet import SCHEMAS, TIMING_COLUMNS, Recorder
from dispatch.run.runner import read_table, run_one
from dispatch.scenario.load import load_scenario
from tests.conftest import ROOT, write_scenario
from tests.dispatch.test_determinism import bitwise, without_timing

PARTITION = {"allocator": "greedy", "planner": "astar", "n_agents": 2, "seed": 7}
LEAF = "allocator=greedy/planner=astar/n_agents=2/seed=7"


def event(i: int) -> dict:
    return dict(t=float(i), event="move", agent_id=i % 3, task_id=i, request_id=100 + i, x=0.5,
                y=1.5, z=float(i))


def summary_row() -> dict:
    """A summary row with every column (a typed value of each, the partition's keys)."""
    row = {}
    for f in SCHEMAS["summary"]:
        if f.name == "run_id":
            continue
        if f.name in PARTITION:
            row[f.name] = PARTITION[f.name]
        elif pa.types.is_string(f.type):
            row[f.name] = f.name
        elif pa.types.is_integer(f.type):
            row[f.name] = 1
        else:
            row[f.name] = 0.5
    return row


def recorder(out: Path, flush_rows: int) -> Recorder:
    return Recorder(out, "run-1", {"dispatch.scenario": "name = 'x'", "dispatch.seed": "7"},
                    PARTITION, flush_rows=flush_rows)


def test_chunks_appear_at_flush_rows_and_finish_merges_them(tmp_path):
    rec = recorder(tmp_path, flush_rows=3)
    leaf = tmp_path / "events" / LEAF
    for i in range(2):
        rec.add("events", **event(i))
    assert not leaf.exists()  # nothing written below flush_rows
    rec.add("events", **event(2))
    assert sorted(p.name for p in leaf.iterdir()) == ["_inflight-00000.parquet.chunk"]
    for i in range(3, 8):
        rec.add("events", **event(i))
    chunks = sorted(leaf.iterdir())
    assert [p.name for p in chunks] == ["_inflight-00000.parquet.chunk", "_inflight-00001.parquet.chunk"]
    assert rec.chunks("events") == chunks
    assert (rec.written("events"), rec.buffered("events")) == (6, 2)
    for k, chunk in enumerate(chunks):  # each chunk is a whole file with its rows
        t = pq.read_table(chunk)
        assert t.column("t").to_pylist() == [3.0 * k, 3.0 * k + 1, 3.0 * k + 2]
        assert t.schema.metadata[b"dispatch.run_id"] == b"run-1"
    rec.add("summary", **summary_row())
    rec.table_metadata["obstacles"] = {"dispatch.cell": "0.5"}  # may be set late
    files = rec.finish()

    assert sorted(files) == sorted(SCHEMAS)
    for name, path in files.items():
        assert path == tmp_path / name / LEAF / "part-0.parquet"
        assert sorted(p.name for p in path.parent.iterdir()) == ["part-0.parquet"], name
    events = pq.read_table(files["events"])
    assert events.column("t").to_pylist() == [float(i) for i in range(8)]  # in order
    assert events.column("run_id").to_pylist() == ["run-1"] * 8
    assert events.schema.remove_metadata().equals(SCHEMAS["events"])
    # the partition columns are in the path, not in the file; read_table puts them back
    summary = pq.read_table(files["summary"])
    assert not set(PARTITION) & set(summary.column_names)
    back = read_table(files["summary"], PARTITION, "summary")
    assert back.schema.remove_metadata().equals(SCHEMAS["summary"])
    assert back.to_pylist() == [{"run_id": "run-1", **summary_row()}]
    # an empty table is still a typed file
    empty = pq.read_table(files["assignments"])
    assert empty.num_rows == 0
    assert empty.schema.remove_metadata().equals(SCHEMAS["assignments"])
    for name, path in files.items():
        meta = pq.read_schema(path).metadata
        assert meta[b"dispatch.version"].decode() == __version__
        assert meta[b"dispatch.run_id"] == b"run-1"
        assert meta[b"dispatch.scenario"] == b"name = 'x'" and meta[b"dispatch.seed"] == b"7"
        assert (b"dispatch.cell" in meta) == (name == "obstacles")
    assert not [p for p in tmp_path.rglob("*") if p.is_file() and p.name.startswith((".", "_"))]
    with pytest.raises(RuntimeError):
        rec.add("events", **event(9))


def test_buffer_never_exceeds_flush_rows(tmp_path):
    rec = recorder(tmp_path, flush_rows=50)
    peak = 0
    for i in range(1234):
        rec.add("events", **event(i))
        peak = max(peak, rec.buffered("events"))
        assert rec.written("events") + rec.buffered("events") == i + 1
    assert peak == 49  # a full buffer is written by the add that fills it
    assert len(rec.chunks("events")) == 1234 // 50
    assert pq.read_table(rec.finish()["events"]).column("t").to_pylist() == [
        float(i) for i in range(1234)]


def test_rows_are_checked(tmp_path):
    rec = recorder(tmp_path, flush_rows=10)
    with pytest.raises(KeyError, match="missing"):
        rec.add("events", t=0.0)
    with pytest.raises(KeyError, match="unexpected"):
        rec.add("events", **event(0), extra=1)
    rec.add("summary", **{**summary_row(), "seed": 8})  # not this run's partition
    with pytest.raises(ValueError, match="seed=8"):
        rec.finish()


def test_abort_keeps_what_was_recorded(tmp_path):
    rec = recorder(tmp_path, flush_rows=4)
    for i in range(10):
        rec.add("events", **event(i))
    rec.abort()
    leaf = tmp_path / "events" / LEAF
    chunks = sorted(leaf.iterdir())
    assert [p.name for p in chunks] == [f"_inflight-{k:05d}.parquet.chunk" for k in range(3)]
    rows = pa.concat_tables([pq.read_table(p) for p in chunks]).column("t").to_pylist()
    assert rows == [float(i) for i in range(10)]  # the buffered rest too
    assert not list(tmp_path.rglob("part-0.parquet"))
    assert not [p for p in tmp_path.rglob(".*")]
    rec.abort()  # idempotent
    # the next recorder of the same partition starts afresh
    again = recorder(tmp_path, flush_rows=4)
    again.add("events", **event(0))
    files = again.finish()
    assert sorted(p.name for p in leaf.iterdir()) == ["part-0.parquet"]
    assert pq.read_table(files["events"]).num_rows == 1


def test_run_one_small_chunks_same_tables(tmp_path):
    """A run flushed every 7 rows gives the tables of a run kept in one chunk."""
    path = write_scenario(tmp_path, fleet={"agents": 4},
                          tasks={"source": "poisson", "rate": 2.0, "count": 20, "ttl": 2.0,
                                 "service_time": 0.5}, duration=60.0)
    [spec] = load_scenario(path).runs()
    a = run_one(spec, tmp_path / "a", flush_rows=7)
    b = run_one(spec, tmp_path / "b")
    assert a.tables["events"].num_rows > 7 * 5
    for name in SCHEMAS:
        ta, tb = without_timing(a.tables[name]), without_timing(b.tables[name])
        assert ta.schema.equals(tb.schema, check_metadata=True), name
        assert bitwise(ta).equals(bitwise(tb)), name
        assert a.tables[name].column_names == SCHEMAS[name].names
    assert set(SCHEMAS["summary"].names) - {"run_id"} <= set(a.summary)
    for k in set(a.summary) - TIMING_COLUMNS:
        va, vs = a.summary[k], a.tables["summary"].column(k)[0].as_py()
        assert va == vs or (isinstance(va, float) and math.isnan(va) and math.isnan(vs)), k


def test_run_one_without_out_cleans_up(tiny_scenario):
    [spec] = load_scenario(tiny_scenario).runs()
    result = run_one(spec)
    folder = result.out
    assert result.tables["summary"].num_rows == 1
    assert all(p.is_file() for p in result.files.values())
    del result
    gc.collect()
    assert not folder.exists()


def test_failing_run_is_aborted(tmp_path, monkeypatch):
    """An exception half-way: the chunks written so far stay (readable), no part-0 file."""
    from dispatch.output.rows import DecisionWriter

    path = write_scenario(tmp_path, tasks={"source": "periodic", "interval": 0.5, "count": 40,
                                           "ttl": 1.0})
    [spec] = load_scenario(path).runs()
    real, calls = DecisionWriter.__call__, []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 10:
            raise RuntimeError("boom")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(DecisionWriter, "__call__", failing)
    with pytest.raises(RuntimeError, match="boom"):
        run_one(spec, tmp_path / "out", flush_rows=5)
    files = sorted((tmp_path / "out").rglob("*.parquet*"))
    assert files and all(f.name.startswith("_inflight-") for f in files)
    assert all(pq.read_table(f).num_rows > 0 for f in files)
    assert not [p for p in (tmp_path / "out").rglob(".*")]


KILLED_RUN = """
import sys
from pathlib import Path
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
[spec] = load_scenario(Path(sys.argv[1])).runs()
run_one(spec, Path(sys.argv[2]), flush_rows=200)
"""


def test_run_killed_half_way_leaves_readable_chunks(tmp_path):
    """SIGKILL while a long run records: every Parquet file left behind reads, with rows."""
    path = write_scenario(tmp_path, duration=1e6,
                          tasks={"source": "periodic", "interval": 0.05, "max_active": 4,
                                 "ttl": 1.0})
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", KILLED_RUN, str(path), str(out)], env=env,
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.glob("events/**/_inflight-*.parquet.chunk"))) < 2:
            assert proc.poll() is None, proc.communicate()[1].decode()
            assert time.monotonic() < deadline, "no two chunks of events within 120 s"
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == -signal.SIGKILL
    # A kill can land while a chunk is half-written into its hidden temp file; readers skip
    # hidden files (pyarrow's datasets do), and nothing else may be left unreadable.
    everything = sorted(out.rglob("*.parquet*"))
    hidden = [f for f in everything if f.name.startswith(".")]
    assert all(".tmp-" in f.name for f in hidden), hidden
    files = [f for f in everything if f not in hidden]
    assert len([f for f in files if f.relative_to(out).parts[0] == "events"]) >= 2
    assert not list(out.rglob("part-0.parquet"))  # the run never finished
    for f in files:
        t = pq.read_table(f)
        assert t.num_rows > 0, f
        assert t.schema.metadata[b"dispatch.run_id"] == spec_id(path).encode()


def spec_id(path: Path) -> str:
    return load_scenario(path).runs()[0].run_id


def test_dispatch_run_writes_the_one_layout_and_the_results_page_reads_it(tiny_scenario, cli, tmp_path):
    """A single ``dispatch run`` writes the Hive layout of a sweep; the pyarrow snippet of the
    results page (docs/explanation/output.md) reads it as it is written there."""
    out = tmp_path / "out"
    proc = cli("run", tiny_scenario, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert str(out) in proc.stdout.replace("\n", "")
    leaf = "scenario=tiny/allocator=hungarian/planner=astar/n_agents=3/seed=0"
    assert (out / "summary" / leaf / "part-0.parquet").is_file()
    assert not (out / "summary.parquet").exists()
    assert (out / "_runs" / leaf / "done.json").is_file()
    page = (ROOT / "docs" / "explanation" / "output.md").read_text(encoding="utf-8")
    snippet = next(block for block in re.findall(r"```python\n(.*?)```", page, re.S)
                   if "pyarrow.dataset" in block)
    folder = re.search(r'ds\.dataset\("([^"]+)/summary"', snippet).group(1)
    scope: dict = {}
    exec(snippet.replace(folder, str(out)), scope)  # noqa: S102 - the page's own code
    summary = scope["summary"]
    assert len(summary) == 1
    row = summary.iloc[0]
    assert (row["allocator"], row["planner"], int(row["n_agents"]), int(row["seed"])) == (
        "hungarian", "astar", 3, 0)
    assert row["run_id"] == "tiny__hungarian__astar__n3__s0" and row["n_tasks"] == 3


def test_rows_are_tied_to_columns_by_name():
    """Every table written during a run declares the columns its row function fills, checked
    against the schema when the run starts (a schema column without a value, or a value
    without a column, fails at once, naming it); each value lands in its named column."""
    from dispatch.output import rows as recording
    for table, cols in (("tasks", recording.TASK_COLUMNS),
                        ("decisions", recording.DECISION_COLUMNS),
                        ("assignments", recording.ASSIGNMENT_COLUMNS),
                        ("vehicles", recording.VEHICLE_COLUMNS)):
        recording.check_columns(table, cols)
    with pytest.raises(KeyError, match=recording.TASK_COLUMNS[-1]):
        recording.check_columns("tasks", recording.TASK_COLUMNS[:-1])
    with pytest.raises(KeyError, match="schema order"):
        recording.check_columns("assignments", ("round", "decision", "agent_id", "task_id",
                                                "request_id", "cost", "won", "alloc_seconds"))

    class Tag(str):
        """A value that says which attribute it was read from."""

        def __getattr__(self, name):
            return Tag(f"{self}.{name}" if self else name)

    row = dict(zip(recording.TASK_COLUMNS,
                   recording.task_row(Tag(), "xyz", "XYZ", "bcd", "efg", ("w", "W")),
                   strict=True))
    assert row["task_id"] == "id" and row["state"] == "state._value_"
    assert (row["board_x"], row["board_y"], row["alight_x"], row["alight_y"]) == \
        ("b", "c", "e", "f")
    assert (row["walk_to_board_m"], row["walk_from_alight_m"]) == ("w", "W")
    assert (row["x"], row["z"], row["dropoff_y"]) == ("x", "z", "Y")
    assert all(row[c] == c for c in ("request_id", "released_at", "max_wait", "snap_m",
                                     "dropoff_snap_m",
                                     "assigned_at", "agent_id", "cost", "picked_up_at",
                                     "completed_at", "conflicted", "closed_at", "reassigned",
                                     "transfers", "passengers", "direct_time", "max_delay",
                                     "shared", "offers", "fare"))
    counts = {"waits": "W", "replans": "R", "wait_seconds": "S"}
    row = dict(zip(recording.VEHICLE_COLUMNS,
                   recording.vehicle_row(Tag(), "xyz", "down", counts, None), strict=True))
    assert (row["agent_id"], row["tasks_completed"], row["x0"], row["down_seconds"]) == \
        ("id", "completed", "x", "down")
    assert (row["waits"], row["replans"], row["wait_seconds"]) == ("W", "R", "S")
    assert all(row[c] == c for c in ("kind", "speed", "distance", "empty_distance",
                                     "occupied_distance", "busy_seconds", "failures",
                                     "capacity", "passenger_distance"))
    assert all(math.isnan(row[c]) for c in ("kwh_drawn", "soc_min", "soc_end"))
    row = dict(zip(recording.ASSIGNMENT_COLUMNS,
                   recording.assignment_row("i", Tag(), "s", "r"), strict=True))
    assert row == {"decision": "i", "round": "round", "agent_id": "agent_id",
                   "task_id": "task_id", "request_id": "r", "cost": "cost", "won": "won",
                   "alloc_seconds": "s"}


def test_a_runs_request_id_type_is_its_own_in_every_table(tmp_path):
    """A run of string ids writes ``request_id`` as strings in each table that has it (empty
    ones too); every other column keeps the schema's type."""
    import pyarrow as pa

    rec = Recorder(tmp_path, "run-1", {}, {"seed": 0}, types={"request_id": pa.string()})
    rec.add("events", **{**event(0), "request_id": "trip-7"})
    files = rec.finish()
    having = [name for name, schema in SCHEMAS.items() if "request_id" in schema.names]
    assert sorted(having) == ["assignments", "events", "tasks"]
    for name in SCHEMAS:
        got = pq.read_table(files[name]).schema.remove_metadata()
        want = SCHEMAS[name].remove(SCHEMAS[name].get_field_index("seed")) \
            if "seed" in SCHEMAS[name].names else SCHEMAS[name]
        if name in having:
            i = want.get_field_index("request_id")
            assert want.field(i).type == pa.int64()
            want = want.set(i, pa.field("request_id", pa.string()))
        assert got.equals(want), name
    assert pq.read_table(files["events"]).column("request_id").to_pylist() == ["trip-7"]
