"""Metrics agree with a hand computation from the Parquet files; reading works on every layout."""

from __future__ import annotations

import math
import statistics
import subprocess
import sys
from collections import defaultdict

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats

from analysis import metrics as M
from analysis.io import NoResultsError, open_results
from analysis.timeline import positions_at, trajectories, vehicle_intervals
from paired.stats import mean_ci, t_quantile
from tests.analysis.helpers import read_hive_rows
from tests.conftest import ROOT


@pytest.mark.parametrize("df", [1, 2, 3, 4, 7, 10, 31, 250, 5000])
@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_t_quantile_matches_scipy(df, level):
    assert t_quantile(level, df) == pytest.approx(stats.t.ppf((1 + level) / 2, df), rel=1e-6)


def test_mean_ci_by_hand():
    xs = [3.0, 5.0, 4.0, 8.0]
    m, h, n = mean_ci(xs + [math.nan])
    assert n == 4 and m == pytest.approx(5.0)
    assert h == pytest.approx(stats.t.ppf(0.975, 3) * statistics.stdev(xs) / 2)
    assert math.isnan(mean_ci([1.0])[1]) and mean_ci([])[2] == 0


# ----------------------------------------------------------------------------- reading


def test_open_sweep_has_run_keys(small_sweep):
    res = open_results(small_sweep)
    assert [s.kind for s in res.sources] == ["hive"]
    assert len(res.summary) == 18
    for name in ("tasks", "events", "vehicles", "obstacles", "assignments", "decisions"):
        df = res.table(name)
        for k in ("scenario", "allocator", "planner", "n_agents", "seed", "run_id"):
            assert k in df.columns, (name, k)
        assert str(df["n_agents"].dtype) == "int64"
    one = res.run("tiny__greedy__astar__n3__s1")
    assert set(one["tasks"]["run_id"]) == {"tiny__greedy__astar__n3__s1"}
    assert len(one["vehicles"]) == 3
    assert res.world("tiny__greedy__astar__n3__s1") == ((12.0, 12.0, 6.0), 1.0)
    with pytest.raises(KeyError, match="no run"):
        res.run("nosuch")


def test_open_run_folder_and_parent(single_run, small_sweep, tmp_path):
    import shutil

    res = open_results(single_run)
    assert [s.kind for s in res.sources] == ["hive"]
    tasks = res.table("tasks")
    assert set(tasks["allocator"]) == {"hungarian"} and set(tasks["seed"]) == {2}
    # a folder holding results is searched; the folders are read together (copied into a
    # folder of their own: the session's temporary root also holds other tests' outputs)
    shutil.copytree(single_run, tmp_path / "a" / "run")
    shutil.copytree(small_sweep, tmp_path / "b" / "sweep")
    both = open_results(tmp_path)
    assert [s.kind for s in both.sources] == ["hive", "hive"] and len(both.summary) == 19
    with pytest.raises(NoResultsError):
        open_results(single_run / "nowhere")


def test_old_single_run_folders_still_read(single_run, tmp_path):
    """Results of older versions: one run as ``<table>.parquet`` files (no partition folders,
    the run keys inside the summary), tasks with ``arrived_at`` and decisions with ``n_agents``
    (the idle vehicles) for what are now ``picked_up_at`` and ``n_idle``."""
    from dispatch.run.runner import read_table

    new = open_results(single_run)
    run_id = new.run_ids()[0]
    partition = {"scenario": "tiny", "allocator": "hungarian", "planner": "astar", "n_agents": 3,
                 "seed": 2}
    old = tmp_path / "old"
    old.mkdir()
    for name in ("summary", "tasks", "assignments", "decisions", "events", "vehicles",
                 "obstacles"):
        (path,) = (single_run / name).rglob("part-0.parquet")
        t = read_table(path, partition, name)
        t = t.rename_columns([{"picked_up_at": "arrived_at", "n_idle": "n_agents"}.get(c, c)
                              for c in t.column_names]).replace_schema_metadata(t.schema.metadata)
        pq.write_table(t, old / f"{name}.parquet")
    res = open_results(old)
    assert [s.kind for s in res.sources] == ["flat"]
    assert res.run_ids() == [run_id]
    for name in ("tasks", "decisions", "events", "vehicles"):
        got, want = res.table(name), new.table(name)
        assert sorted(got.columns) == sorted(want.columns), name
        assert got[list(want.columns)].equals(want), name
    picked = res.table("tasks", columns=["task_id", "picked_up_at"])
    assert picked["picked_up_at"].notna().any()
    assert (res.table("decisions")["n_agents"] == 3).all()  # the run key, not the idle count
    assert len(M.run_metrics(res.summary, res.table("tasks"), res.table("vehicles"))) == 1
    assert res.world(run_id) == new.world(run_id)


def test_cancelled_of_older_versions_reads_as_cut_off(single_run, tmp_path):
    """Older versions called a request the run's end cut off ``cancelled`` (its event
    ``cancel``, the summary's ``tasks_cancelled``): read, they are ``cut_off`` (and
    ``tasks_cut_off``), as the runs of this version write them."""
    import shutil

    import pyarrow as pa

    copy = tmp_path / "old"
    shutil.copytree(single_run, copy)
    for name, col, old in (("tasks", "state", "cancelled"), ("events", "event", "cancel")):
        f = next((copy / name).rglob("part-0.parquet"))
        t = pq.read_table(f)
        values = t.column(col).to_pylist()
        values[0] = old
        t = t.set_column(t.schema.get_field_index(col), col, pa.array(values, pa.string()))
        pq.write_table(t, f)
    f = next((copy / "summary").rglob("part-0.parquet"))
    t = pq.read_table(f)
    pq.write_table(t.rename_columns([{"tasks_cut_off": "tasks_cancelled"}.get(c, c)
                                     for c in t.column_names]), f)
    new, res = open_results(single_run), open_results(copy)
    assert res.table("tasks")["state"].iloc[0] == "cut_off"
    assert res.table("events")["event"].iloc[0] == "cut_off"
    assert "tasks_cancelled" not in res.summary.columns
    assert res.summary["tasks_cut_off"].tolist() == new.summary["tasks_cut_off"].tolist()
    assert M.run_metrics(res.summary, res.table("tasks"), res.table("vehicles"))[
        "cutOffRate"].notna().all()


def test_runs_of_integer_and_string_request_ids_read_together(single_run, tmp_path):
    """A folder holding runs of integer ids beside runs of string ids (two traces) reads its
    request ids as strings, the integers in decimal."""
    import shutil

    import pyarrow as pa

    from analysis.io import find_sources

    copy = tmp_path / "mixed"
    shutil.copytree(single_run, copy)
    f = next((copy / "tasks").rglob("part-0.parquet"))
    t = pq.read_table(f)
    assert t.schema.field("request_id").type == pa.int64()
    ints = t.column("request_id").to_pylist()
    other = f.parent.parent / "seed=9" / "part-0.parquet"
    other.parent.mkdir()
    i = t.schema.get_field_index("request_id")
    pq.write_table(t.set_column(i, "request_id", pa.array([f"x{v}" for v in ints])), other)
    [src] = find_sources(copy)
    got = src.dataset("tasks").to_table()
    assert got.schema.field("request_id").type == pa.string()
    assert sorted(got.column("request_id").to_pylist()) == sorted(
        [str(v) for v in ints] + [f"x{v}" for v in ints])


def test_sweep_files_with_fewer_columns_read_as_null(small_sweep, tmp_path):
    """Files written by an older version (a column missing) still read, the column null."""
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(small_sweep, copy)
    f = next((copy / "summary").rglob("part-0.parquet"))
    t = pq.read_table(f)
    pq.write_table(t.drop_columns(["makespan"]).replace_schema_metadata(t.schema.metadata), f)
    s = open_results(copy).summary
    assert len(s) == 18 and s["makespan"].isna().sum() == 1


# ----------------------------------------------------------------------------- Tables I / III


def test_allocator_metrics_by_hand(small_sweep):
    rows = read_hive_rows(small_sweep / "summary")
    assert len(rows) == 18
    by = defaultdict(list)
    for r in rows:
        by[(r["allocator"], r["n_agents"])].append(r)
    ref = {(r["n_agents"], r["seed"]): r["total_cost"] for r in rows
           if r["allocator"] == "hungarian"}
    am = open_results(small_sweep).summary.pipe(M.allocator_metrics).set_index(
        ["allocator", "n_agents"])
    assert list(am.index.get_level_values(0).unique()) == ["hungarian", "greedy", "random"]
    for (alloc, n), rs in by.items():
        got = am.loc[(alloc, n)]
        costs = [r["total_cost"] for r in rs]
        half = stats.t.ppf(0.975, len(costs) - 1) * statistics.stdev(costs) / math.sqrt(3)
        assert got["runs"] == 3
        assert got["total_cost_mean"] == pytest.approx(statistics.fmean(costs))
        assert got["total_cost_ci95"] == pytest.approx(half)
        gaps = [(r["total_cost"] - ref[(n, r["seed"])]) / ref[(n, r["seed"])] for r in rs]
        assert got["gap_mean"] == pytest.approx(statistics.fmean(gaps), abs=1e-12)
        assert got["conflict_free_rate_mean"] == pytest.approx(
            statistics.fmean(r["conflict_free_rate"] for r in rs))
        assert got["alloc_seconds_mean"] == pytest.approx(
            statistics.fmean(r["first_decision_seconds"] for r in rs))
        assert got["alloc_seconds_total_mean"] == pytest.approx(
            statistics.fmean(r["alloc_seconds"] for r in rs))
    assert (am.xs("hungarian")["gap_mean"] == 0).all()
    assert (am.xs("hungarian")["conflict_free_rate_mean"] == 1).all()


def test_gap_is_paired_by_seed():
    import pandas as pd

    s = pd.DataFrame({
        "scenario": "s", "planner": "p", "n_agents": 2,
        "allocator": ["hungarian", "hungarian", "greedy", "greedy"],
        "seed": [0, 1, 0, 1], "total_cost": [10.0, 20.0, 11.0, 30.0],
    })
    assert list(M.paired_gaps(s)) == pytest.approx([0, 0, 0.1, 0.5])
    # not the gap of the means: (20.5 - 15) / 15
    s2 = s.assign(conflict_free_rate=1.0, first_decision_seconds=0.1, alloc_seconds=0.1)
    am = M.allocator_metrics(s2).set_index("allocator")
    assert am.loc["greedy", "gap_mean"] == pytest.approx(0.3)


# ----------------------------------------------------------------------------- taxi-style


def test_taxi_metrics_by_hand(small_sweep):
    tasks = read_hive_rows(small_sweep / "tasks")
    vehicles = read_hive_rows(small_sweep / "vehicles")
    summary = {r["run_id"]: r for r in read_hive_rows(small_sweep / "summary")}
    res = open_results(small_sweep)
    taxi = M.taxi_metrics(res.summary, res.table("tasks"), res.table("vehicles"),
                          res.table("events")).set_index(["allocator", "n_agents"])
    for alloc in ("hungarian", "greedy", "random"):
        for n in (2, 3):
            ts = [t for t in tasks if t["allocator"] == alloc and t["n_agents"] == n]
            vs = [v for v in vehicles if v["allocator"] == alloc and v["n_agents"] == n]
            waits = np.array([t["picked_up_at"] - t["released_at"] for t in ts
                              if not math.isnan(t["picked_up_at"])])
            got = taxi.loc[(alloc, n)]
            assert got["requests"] == len(ts) == 12
            assert got["rides"] == sum(t["state"] == "completed" for t in ts)
            assert got["service_rate"] == pytest.approx(got["rides"] / 12)
            assert got["wait_average"] == pytest.approx(waits.mean())
            assert got["wait_median"] == pytest.approx(np.median(waits))
            assert got["wait_p90"] == pytest.approx(np.quantile(waits, 0.9))
            assert got["wait_max"] == pytest.approx(waits.max())
            busy = sum(v["busy_seconds"] for v in vs)
            cap = sum(summary[v["run_id"]]["sim_time"] for v in vs)
            assert got["utilization"] == pytest.approx(busy / cap)
            assert 0 < got["utilization"] <= 1
            assert got["totalDistance"] == pytest.approx(sum(v["distance"] for v in vs))
            assert got["path_stretch_mean"] >= 1 - 1e-9
            # no waits or replans yet: realized travel time = planned cost
            assert got["approach_delay_average"] == pytest.approx(0, abs=1e-9)
            # point tasks carry nothing: an empty-distance ratio would mean nothing
            assert math.isnan(got["emptyRatio"])


def test_run_metrics_of_a_busy_run(single_run):
    res = open_results(single_run)
    (path,) = (single_run / "tasks").rglob("*.parquet")
    tasks = pq.read_table(path).to_pandas()
    rm = M.run_metrics(res.summary, res.table("tasks"), res.table("vehicles"))
    assert len(rm) == 1
    r = rm.iloc[0]
    done = (tasks["state"] == "completed").sum()
    assert r["requests"] == len(tasks) and r["rides"] == done
    assert r["rejections"] == len(tasks) - done > 0  # some expired
    assert r["rejectionRate"] == pytest.approx(1 - done / len(tasks))
    assert r["wait_average"] == pytest.approx(res.summary["wait_time_mean"].iloc[0])


# ----------------------------------------------------------------------------- timeline


def test_vehicle_intervals_cover_the_run(single_run):
    res = open_results(single_run)
    events, vehicles = res.table("events"), res.table("vehicles")
    end = float(res.summary["sim_time"].iloc[0])
    iv = vehicle_intervals(events, vehicles, end)
    for v in vehicles.itertuples():
        mine = iv.loc[iv["agent_id"] == v.agent_id].sort_values("start")
        assert mine["start"].iloc[0] == 0 and mine["end"].iloc[-1] == pytest.approx(end)
        assert np.allclose(mine["start"].to_numpy()[1:], mine["end"].to_numpy()[:-1])
        busy = mine.loc[mine["state"].isin(["travel", "service"])]
        assert (busy["end"] - busy["start"]).sum() == pytest.approx(v.busy_seconds)
        service = mine.loc[mine["state"] == "service"]
        assert np.allclose(service["end"] - service["start"], 1.0)  # service_time


def test_positions_follow_the_moves(single_run):
    res = open_results(single_run)
    events, vehicles = res.table("events"), res.table("vehicles")
    traj = trajectories(events, vehicles)
    moves = events.loc[events["event"] == "move"]
    for m in moves.head(20).itertuples():
        assert positions_at(traj, m.t)[m.agent_id] == pytest.approx([m.x, m.y, m.z])
    start = positions_at(traj, 0.0)
    for v in vehicles.itertuples():
        assert start[v.agent_id] == pytest.approx([v.x0, v.y0, v.z0])


# ----------------------------------------------------------------------------- light imports


def test_analysis_works_without_pybullet_torch_or_dispatch(small_sweep, tmp_path):
    """The report needs pyarrow, pandas and matplotlib only: block the heavy modules (and the
    dispatch package itself) and write a report."""
    code = f"""
import sys
for m in ("pybullet", "torch", "dispatch", "scipy", "simpy", "ray"):
    sys.modules[m] = None
import analysis, analysis.io, analysis.metrics, analysis.plots, analysis.report, analysis.render
import analysis.timeline
from analysis.report import write_report
files = write_report({str(small_sweep)!r}, {str(tmp_path / 'rep')!r})
heavy = [m for m in ("pybullet", "torch", "dispatch") if sys.modules.get(m) is not None]
print(len(files), heavy)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["10", "[]"]


def test_importing_analysis_is_light():
    code = ("import sys, analysis.io, analysis.metrics, analysis.plots, analysis.report, "
            "analysis.render, analysis.timeline, analysis.commands, paired.stats\n"
            "print(sorted(m for m in ('matplotlib', 'pybullet', 'PIL', 'torch') "
            "if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
