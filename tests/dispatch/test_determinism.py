"""Same scenario and seed, same Parquet content (wall-clock columns aside); a sweep writes a
Hive-partitioned folder that pyarrow reads back with its partition columns."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from dispatch.output.parquet import SCHEMAS, TIMING_COLUMNS
from dispatch.run.runner import execute
from dispatch.scenario.load import load_scenario
from tests.conftest import write_scenario

TABLES = tuple(SCHEMAS)

#: A scenario that exercises every random stream: obstacles, fleet, task positions, Poisson
#: release times and the random allocator's choices.
BUSY = dict(
    fleet={"agents": 3},
    tasks={"source": "poisson", "rate": 3.0, "count": 20, "max_active": 4, "ttl": 1.5,
           "service_time": 1.0},
    dispatch={"allocator": "random"},
    duration=60.0,
)


def leaf_files(folder: Path) -> list[Path]:
    """The Parquet files of a folder holding one run (one ``part-0.parquet`` per table)."""
    return sorted(folder.rglob("*.parquet"))


def read_run(folder: Path) -> dict:
    """The tables of a folder holding one run, each read from its one file."""
    out = {}
    for name in TABLES:
        (path,) = (folder / name).rglob("*.parquet")
        out[name] = pq.read_table(path)
    return out


def without_timing(table):
    return table.drop_columns([c for c in table.column_names if c in TIMING_COLUMNS])


def bitwise(table: pa.Table) -> pa.Table:
    """Float columns reinterpreted as their int64 bit patterns, so that ``.equals`` compares
    them byte for byte (``Table.equals`` never finds NaN equal to NaN; NaN marks "never"
    in several columns)."""
    cols = []
    for col in table.columns:
        arr = col.combine_chunks()
        cols.append(arr.view(pa.int64()) if pa.types.is_float64(arr.type) else arr)
    return pa.table(cols, names=table.column_names)


def assert_same_content(x: pa.Table, y: pa.Table, name: str) -> None:
    assert x.schema.equals(y.schema, check_metadata=True), name
    assert x.schema.metadata == y.schema.metadata, name
    assert x.num_rows == y.num_rows, name
    assert bitwise(x).equals(bitwise(y)), f"{name} differs between two runs of the same seed"


def run_into(scenario: Path, out: Path, **overrides) -> list[dict]:
    specs = load_scenario(scenario).runs(**overrides)
    assert len(specs) == 1
    return execute(specs, out)


@pytest.mark.parametrize("allocator", ["hungarian", "greedy", "random"])
def test_same_seed_same_parquet(tmp_path, allocator):
    scenario = write_scenario(tmp_path, **{**BUSY, "dispatch": {"allocator": allocator}})
    a, b = tmp_path / "a", tmp_path / "b"
    sa = run_into(scenario, a, seed=3)
    sb = run_into(scenario, b, seed=3)
    leaf = "scenario=tiny/allocator=" + allocator + "/planner=astar/n_agents=3/seed=3/part-0.parquet"
    assert [str(p.relative_to(a)) for p in leaf_files(a)] == sorted(f"{n}/{leaf}"
                                                                    for n in TABLES)
    ta, tb = read_run(a), read_run(b)
    for name in TABLES:
        assert_same_content(without_timing(ta[name]), without_timing(tb[name]), name)
    # the runs were busy: tasks expired (NaN times) and releases were skipped (NaN positions)
    states = ta["tasks"].column("state").to_pylist()
    assert "completed" in states and "expired" in states
    assert "skipped" in ta["events"].column("event").to_pylist()
    for k in set(sa[0]) - TIMING_COLUMNS:
        va, vb = sa[0][k], sb[0][k]
        assert va == vb or (va != va and vb != vb), k  # NaN == NaN here


def test_timing_columns_exist():
    """The columns left out of the comparison are real columns of the tables."""
    names = {f.name for schema in SCHEMAS.values() for f in schema}
    assert TIMING_COLUMNS <= names


def test_different_seed_different_tasks(tmp_path):
    scenario = write_scenario(tmp_path, **BUSY)
    a, b = tmp_path / "a", tmp_path / "b"
    run_into(scenario, a, seed=1)
    run_into(scenario, b, seed=2)
    ta, tb = read_run(a), read_run(b)
    cols = ["kind", "x", "y", "z", "released_at"]
    assert not ta["tasks"].select(cols).equals(tb["tasks"].select(cols))
    assert ta["tasks"].schema.metadata[b"dispatch.seed"] == b"1"
    assert tb["tasks"].schema.metadata[b"dispatch.seed"] == b"2"
    # the world is drawn from the seed too
    assert not ta["obstacles"].drop_columns(["run_id"]).equals(
        tb["obstacles"].drop_columns(["run_id"]))


def test_allocators_share_the_instance_of_a_seed(tmp_path):
    """Paired runs: the same seed gives the same world, fleet and static tasks for every
    allocator."""
    scenario = write_scenario(tmp_path, fleet={"agents": 4}, tasks={"count": 6})
    runs = {}
    for alloc in ("hungarian", "greedy", "random"):
        run_into(scenario, tmp_path / alloc, allocator=alloc, seed=5)
        runs[alloc] = read_run(tmp_path / alloc)
    ref = runs["hungarian"]
    for alloc, t in runs.items():
        assert t["obstacles"].drop_columns(["run_id"]).equals(
            ref["obstacles"].drop_columns(["run_id"])), alloc
        cols = ["agent_id", "kind", "speed", "x0", "y0", "z0"]
        assert t["vehicles"].select(cols).equals(ref["vehicles"].select(cols)), alloc
        cols = ["task_id", "kind", "x", "y", "z", "released_at"]
        # rows are written as tasks close, so their order depends on the allocator
        assert t["tasks"].select(cols).sort_by("task_id").equals(
            ref["tasks"].select(cols).sort_by("task_id")), alloc


def test_sweep_writes_hive_partitions(tmp_path):
    sweep = {"allocator": ["hungarian", "greedy"], "agents": [2, 3], "seed": [0, 1]}
    scenario = write_scenario(tmp_path, sweep=sweep, tasks={"count": 3})
    specs = load_scenario(scenario).runs()
    assert len(specs) == 8
    out = tmp_path / "out"
    summaries = execute(specs, out)
    assert len(summaries) == 8
    leaf = out / "summary" / "scenario=tiny" / "allocator=greedy" / "planner=astar" / "n_agents=3" / "seed=1"
    assert (leaf / "part-0.parquet").is_file()
    for name in TABLES:
        dataset = ds.dataset(out / name, partitioning="hive")
        table = dataset.to_table()
        for col in ("allocator", "planner", "n_agents", "seed"):
            assert col in table.column_names, (name, col)
        assert len(dataset.files) == 8, name
    summary = ds.dataset(out / "summary", partitioning="hive").to_table().to_pandas()
    assert len(summary) == 8
    got = sorted(zip(summary.allocator, summary.planner, summary.n_agents, summary.seed))
    want = sorted((a, "astar", n, s) for a in sweep["allocator"] for n in sweep["agents"]
                  for s in sweep["seed"])
    assert got == want
    # the restored columns agree with the run ids and with the returned summaries
    for row in summary.itertuples():
        assert row.run_id == f"tiny__{row.allocator}__{row.planner}__n{row.n_agents}__s{row.seed}"
        assert row.n_tasks == 3
    by_id = {s["allocator"] + str(s["n_agents"]) + str(s["seed"]): s for s in summaries}
    for row in summary.itertuples():
        s = by_id[row.allocator + str(row.n_agents) + str(row.seed)]
        assert row.total_cost == pytest.approx(s["total_cost"])
    # per-run files keep the metadata of their run
    meta = pq.read_schema(leaf / "part-0.parquet").metadata
    assert meta[b"dispatch.seed"] == b"1"
    assert b"dispatch.scenario" in meta and b"dispatch.version" in meta
    # a sweep's tasks can be filtered by partition without reading the rest
    tasks = ds.dataset(out / "tasks", partitioning="hive")
    greedy = tasks.to_table(filter=ds.field("allocator") == "greedy").to_pandas()
    assert set(greedy.allocator) == {"greedy"} and len(greedy) == 4 * 3


def test_sweep_is_deterministic(tmp_path):
    sweep = {"allocator": ["random"], "agents": [3], "seed": [0, 4]}
    scenario = write_scenario(tmp_path, sweep=sweep, **{k: v for k, v in BUSY.items()
                                                       if k != "dispatch"})
    specs = load_scenario(scenario).runs()
    execute(specs, tmp_path / "a")
    execute(specs, tmp_path / "b")
    for name in TABLES:
        a = without_timing(ds.dataset(tmp_path / "a" / name, partitioning="hive").to_table())
        b = without_timing(ds.dataset(tmp_path / "b" / name, partitioning="hive").to_table())
        assert_same_content(a, b, name)
