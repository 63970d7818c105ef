"""``dispatch report`` / ``dispatch render`` on a small sweep; DuckDB and polars read the output."""

from __future__ import annotations

import csv
import math
import statistics
from collections import defaultdict

import pytest
from PIL import Image

from analysis.report import FIGURES, write_report
from tests.analysis.helpers import read_hive_rows

# (a voxel report: its service metrics are service.csv; taxi.csv is a road report's)
FILES = ("report.md", "allocators.csv", "service.csv", "runs.csv", *FIGURES)


@pytest.fixture(scope="module")
def report(small_sweep, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    files = write_report(small_sweep, out)
    return out, files


def test_report_files(report):
    out, files = report
    assert [f.name for f in files] == list(FILES)
    for name in FIGURES:
        with Image.open(out / name) as img:
            assert img.format == "PNG"
            assert img.width >= 600 and img.height >= 300
            # not a blank canvas: many distinct colours
            assert len(img.convert("RGB").getcolors(maxcolors=1 << 16) or range(1 << 16)) > 20
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files


def test_report_tables_agree_with_parquet(report, small_sweep):
    """Table I's cells are the mean total cost ± CI [gap] computed by hand from the files."""
    from scipy import stats

    out, _ = report
    text = (out / "report.md").read_text()
    rows = read_hive_rows(small_sweep / "summary")
    by = defaultdict(list)
    for r in rows:
        by[(r["allocator"], r["n_agents"])].append(r)
    ref = {(r["n_agents"], r["seed"]): r["total_cost"] for r in rows
           if r["allocator"] == "hungarian"}
    table1 = text.split("## Table I")[1].split("## ")[0]
    for n in (2, 3):
        line = next(ln for ln in table1.splitlines() if ln.startswith(f"| {n} |"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[1] == "3"  # runs
        for col, alloc in zip(cells[2:], ("hungarian", "greedy", "random")):
            costs = [r["total_cost"] for r in by[(alloc, n)]]
            half = stats.t.ppf(0.975, 2) * statistics.stdev(costs) / math.sqrt(3)
            want = f"{statistics.fmean(costs):.1f} ± {half:.1f}"
            if alloc != "hungarian":
                gaps = [(r["total_cost"] - ref[(n, r["seed"])]) / ref[(n, r["seed"])]
                        for r in by[(alloc, n)]]
                want += f" [{100 * statistics.fmean(gaps):+.1f} %]"
            assert col == want, (n, alloc)
    table3 = text.split("## Table III")[1].split("## ")[0]
    line = next(ln for ln in table3.splitlines() if ln.startswith("| 3 |"))
    greedy = [c.strip() for c in line.strip("|").split("|")][3]
    rate = statistics.fmean(r["conflict_free_rate"] for r in by[("greedy", 3)])
    assert greedy.startswith(f"{100 * rate:.1f} % / ")
    for name in FIGURES:
        assert f"]({name})" in text
    # the CSVs hold the same numbers
    with open(out / "allocators.csv") as f:
        got = {(r["allocator"], int(r["n_agents"])): r for r in csv.DictReader(f)}
    for key, rs in by.items():
        assert float(got[key]["total_cost_mean"]) == pytest.approx(
            statistics.fmean(r["total_cost"] for r in rs))
    assert not (out / "taxi.csv").exists()
    assert "All columns: service.csv" in text
    with open(out / "service.csv") as f:
        taxi = list(csv.DictReader(f))
    assert len(taxi) == 6
    for col in ("wait_average", "wait_median", "wait_p90", "service_rate", "utilization",
                "totalEmptyDistance", "rejectionRate", "rides"):
        assert col in taxi[0]
    with open(out / "runs.csv") as f:
        assert len(list(csv.DictReader(f))) == 18


def test_html_report_and_chosen_run(small_sweep, tmp_path):
    files = write_report(small_sweep, tmp_path, fmt="html", run_id="tiny__random__astar__n2__s1")
    html = files[0].read_text()
    assert files[0].name == "report.html" and html.startswith("<!doctype html>")
    assert "<table" in html and "tiny__random__astar__n2__s1" in html
    assert "<img src='timeline.png'" in html
    with pytest.raises(ValueError):
        write_report(small_sweep, tmp_path, fmt="pdf")


def test_cli_report_and_render(small_sweep, tmp_path, cli):
    out = tmp_path / "rep"
    proc = cli("report", small_sweep, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "report.md" in proc.stdout
    assert all((out / f).is_file() for f in FILES)
    proc = cli("report", tmp_path / "nothing-here")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "no such file" in proc.stderr

    gif = tmp_path / "run.gif"
    proc = cli("render", small_sweep, "--run-id", "tiny__greedy__astar__n3__s0", "--out", gif,
               "--fps", "4", "--seconds", "2", "--size", "160x120")
    assert proc.returncode == 0, proc.stderr
    with Image.open(gif) as img:
        assert img.format == "GIF" and img.size == (160, 120)
        # 2 s at 4 fps = 8 frames; Pillow merges identical ones (vehicles standing still)
        assert 2 <= img.n_frames <= 8
        img.seek(0)
        first = img.convert("RGB").tobytes()
        img.seek(img.n_frames - 1)
        assert img.convert("RGB").tobytes() != first  # vehicles moved
    proc = cli("render", small_sweep, "--run-id", "nosuch", "--out", gif)
    assert proc.returncode == 2 and "nosuch" in proc.stderr


def test_render_a_run_folder(single_run, tmp_path):
    from analysis.render import render_run

    path = render_run(single_run, tmp_path / "a.gif", fps=3, seconds=1, size=(96, 72))
    with Image.open(path) as img:
        assert 2 <= img.n_frames <= 3 and img.size == (96, 72)


# ----------------------------------------------------------------------------- other readers


def test_duckdb_reads_the_sweep(small_sweep):
    duckdb = pytest.importorskip("duckdb")
    rows = read_hive_rows(small_sweep / "summary")
    con = duckdb.connect()
    got = con.execute(f"""
        SELECT allocator, n_agents, count(*) AS runs, avg(total_cost) AS cost
        FROM read_parquet('{small_sweep}/summary/**/*.parquet', hive_partitioning = true)
        GROUP BY ALL ORDER BY ALL""").fetchall()
    assert len(got) == 6
    for alloc, n, runs, cost in got:
        mine = [r["total_cost"] for r in rows if r["allocator"] == alloc and r["n_agents"] == n]
        assert runs == 3 and cost == pytest.approx(statistics.fmean(mine))
    waits = con.execute(f"""
        SELECT allocator, median(picked_up_at - released_at)
        FROM read_parquet('{small_sweep}/tasks/**/*.parquet', hive_partitioning = true)
        WHERE state = 'completed' GROUP BY ALL""").fetchall()
    assert {a for a, _ in waits} == {"hungarian", "greedy", "random"}


def test_polars_reads_the_sweep(small_sweep):
    pl = pytest.importorskip("polars")
    rows = read_hive_rows(small_sweep / "tasks")
    df = pl.scan_parquet(small_sweep / "tasks" / "**" / "*.parquet",
                         hive_partitioning=True).collect()
    assert df.height == len(rows) == 18 * 4
    assert {"allocator", "planner", "n_agents", "seed"} <= set(df.columns)
    per = (df.group_by("allocator", "n_agents").agg(pl.len().alias("tasks"))
             .sort("allocator", "n_agents"))
    assert per["tasks"].to_list() == [12] * 6


# ----------------------------------------------------------------------------- taxi runs


@pytest.fixture(scope="module")
def road_sweep(tmp_path_factory):
    """Two allocators on a 6 x 6 grid: 6 taxis, Poisson trips for 40 simulated minutes."""
    from dispatch.run.runner import sweep
    from dispatch.scenario.load import load_scenario

    d = tmp_path_factory.mktemp("road_sweep")
    path = d / "grid.toml"
    path.write_text('name = "grid"\nduration = 2400.0\n[world]\nnetwork = "manhattan"\n'
                    'blocks = [6, 6]\nblock = 200.0\nspeed = 10.0\n[fleet]\nagents = 6\n'
                    '[tasks]\nsource = "poisson"\nrate = 0.02\nmax_wait = 180.0\n'
                    '[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\nbatch_window = 10.0\n'
                    '[sweep]\nallocator = ["fcfs", "hungarian"]\nseed = [0, 1]\n')
    out = d / "out"
    outcomes = sweep(load_scenario(path).runs(), out, workers=1)
    assert all(o.status == "done" for o in outcomes), [o.error for o in outcomes]
    return out


def _not_trivial(path, min_kb=15):
    assert path.stat().st_size > min_kb * 1024, path
    with Image.open(path) as img:
        assert img.width >= 600 and img.height >= 400
        rgb = img.convert("RGB")
        assert len(rgb.getcolors(maxcolors=1 << 16) or range(1 << 16)) > 50  # not uniform
        lo, hi = zip(*rgb.getextrema())
        assert max(hi) - min(lo) > 100


def test_taxi_report_files(road_sweep, tmp_path):
    from analysis.report import ROAD_FIGURES

    files = write_report(road_sweep, tmp_path)
    names = [f.name for f in files]
    assert names[0] == "report.md"
    for name in ("taxi.csv", "runs.csv", "hourly_customers.csv", "hourly_fleet.csv",
                 *ROAD_FIGURES):
        assert name in names and (tmp_path / name).is_file()
    for name in ROAD_FIGURES:
        _not_trivial(tmp_path / name)
    text = (tmp_path / "report.md").read_text()
    assert "Taxi study" in text and "Table I" not in text  # no paper tables for taxis
    for col in ("rejectionRate", "wait_p90", "utilization", "emptyRatio", "vkm_per_ride"):
        assert col in text
    # the study opens with a few lines, then its table; each column's meaning is a short item
    # of a list below the table
    study = text.split("## Taxi study")[1]
    opening = study.split("\n| allocator |")[0]
    assert len(opening.split()) < 80, opening
    glossary = [ln for ln in study.split("\n| allocator |")[1].splitlines()
                if ln.startswith("- ")]
    assert len(glossary) >= 10 and max(len(ln.split()) for ln in glossary) < 40
    assert any(ln.startswith("- utilization: ") for ln in glossary)
    with open(tmp_path / "taxi.csv", newline="") as f:
        taxi = {r["allocator"]: r for r in csv.DictReader(f)}
    assert set(taxi) == {"fcfs", "hungarian"}
    for r in taxi.values():
        assert float(r["detour_ratio_mean"]) == pytest.approx(1.0)  # straight, free flow
        assert 0 < float(r["emptyRatio"]) < 1 and 0 < float(r["utilization"]) <= 1


def test_render_a_taxi_run(road_sweep, tmp_path, cli):
    gif = tmp_path / "taxi.gif"
    proc = cli("render", road_sweep, "--run-id", "grid__fcfs__dijkstra__n6__s0", "--out", gif,
               "--fps", "3", "--seconds", "2", "--size", "320x300")
    assert proc.returncode == 0, proc.stderr
    with Image.open(gif) as img:
        assert img.format == "GIF" and img.size == (320, 300)
        assert 2 <= img.n_frames <= 6
        img.seek(0)
        first = img.convert("RGB").tobytes()
        img.seek(img.n_frames - 1)
        assert img.convert("RGB").tobytes() != first  # taxis moved, the clock ran


def _copy_one_run(sweep_dir, dest, part="allocator=greedy/planner=astar/n_agents=3/seed=0"):
    """A results folder holding one run of ``sweep_dir`` (as ``dispatch run`` of that run
    would write it into another --out)."""
    import shutil

    for table in sweep_dir.iterdir():
        for src in table.glob(f"scenario=*/{part}"):
            shutil.copytree(src, dest / src.relative_to(sweep_dir))
    return dest


def test_a_run_in_two_folders_counts_once(small_sweep, tmp_path, cli):
    """``dispatch report runs/a runs/b`` with a run in both: one row per run id, and a warning
    with the count (it counted twice: N = 3 showed 10 runs and greedy's mean moved)."""
    from analysis.io import open_results

    one = _copy_one_run(small_sweep, tmp_path / "one")
    res = open_results(small_sweep, one)
    assert len(res.summary) == 18 and res.summary["run_id"].is_unique
    assert [d.run_id for d in res.duplicates] == ["tiny__greedy__astar__n3__s0"]
    tasks = res.table("tasks")
    alone = open_results(small_sweep).table("tasks")
    assert len(tasks) == len(alone)
    assert open_results(small_sweep, small_sweep).duplicates == []  # one folder named twice
    proc = cli("report", small_sweep, one, "--out", tmp_path / "rep")
    assert proc.returncode == 0, proc.stderr
    assert "warning" in proc.stderr and "1 run(s) found in more than one folder" in proc.stderr
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "18 runs from" in text and "counted once" in text
    with open(tmp_path / "rep" / "allocators.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {int(r["runs"]) for r in rows} == {3}


def test_taxi_table_adds_up_and_has_intervals_over_seeds(road_sweep, tmp_path):
    """rides + rejections + cut_off + failed = requests per series; the 95 % interval over
    the two seeds of each share and of the mean wait is the Student-t one of the runs' own
    values; the report shows them as mean ± half-width, the shares as percentages with one
    decimal; the trips the run's end cut off are called so, never cancelled."""
    import math as m

    from analysis import metrics as M
    from analysis.io import open_results
    from paired.stats import mean_ci

    res = open_results(road_sweep)
    taxi = M.taxi_metrics(res.summary, res.table("tasks"), res.table("vehicles"))
    for _, r in taxi.iterrows():
        assert r["rides"] + r["rejections"] + r["cut_off"] + r["failed"] == r["requests"]
        assert r["service_rate"] + r["rejectionRate"] + r["cutOffRate"] == pytest.approx(
            1 - r["failed"] / r["requests"])
        runs = res.summary.loc[res.summary["allocator"] == r["allocator"]]
        assert len(runs) == 2
        served = runs["tasks_completed"] / runs["n_tasks"]
        assert r["service_rate_ci95"] == pytest.approx(mean_ci(served)[1])
        assert r["wait_average_ci95"] == pytest.approx(mean_ci(runs["wait_time_mean"])[1])
        assert m.isfinite(r["cutOffRate_ci95"])
    write_report(road_sweep, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "cut_off" in text and "cutOffRate" in text and " ± " in text
    assert "cancel" not in text
    row = next(ln for ln in text.splitlines() if ln.startswith("| hungarian |"))
    header = next(ln for ln in text.splitlines() if ln.startswith("| allocator |"))
    cell = dict(zip([c.strip() for c in header.split("|")], [c.strip() for c in row.split("|")]))
    r = taxi.loc[taxi["allocator"] == "hungarian"].iloc[0]
    assert cell["service_rate"] == (f"{100 * r['service_rate']:.1f} ± "
                                    f"{100 * r['service_rate_ci95']:.1f} %")
    assert cell["utilization"] == f"{100 * r['utilization']:.1f} %"


def test_cli_report_series_filter(road_sweep, tmp_path, cli):
    proc = cli("report", road_sweep, "--series", "hungarian*", "--out", tmp_path / "a")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "a" / "hourly.png").is_file()
    proc = cli("report", road_sweep, "--series", "nosuch*", "--out", tmp_path / "b")
    assert proc.returncode == 2 and "no series matches 'nosuch*'" in proc.stderr
    assert "fcfs" in proc.stderr and "Traceback" not in proc.stderr


def test_a_run_id_shared_by_two_scenario_texts_is_not_a_duplicate(single_run, small_sweep):
    """The single run (tiny, hungarian, N = 3, seed 2, Poisson tasks) and the small sweep's
    run of that id (static tasks) are two runs of two texts: both are read, no warning."""
    from analysis.io import open_results

    res = open_results(single_run, small_sweep)
    assert res.duplicates == [] and len(res.summary) == 19
