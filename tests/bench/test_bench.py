"""dispatch bench: the suite is fixed; a tiny bench writes bench.csv (exact columns) and
bench.md, is deterministic apart from timings and resumes; intervals and paired differences
equal a hand computation; --against flags a planted change and passes an equal board; wrong
inputs give one error line."""

from __future__ import annotations

import csv
import math

import pytest

from bench import against, stats, suite
from bench.metrics import COLUMNS, TIMING
from bench.run import run_bench
from bench.suite import DELETE, Instance
from bench.table import BenchFileError, read_csv, write_csv
from dispatch.run.cli import main
from tests.conftest import TINY_DISPATCH, TINY_FLEET, TINY_OBSTACLES, TINY_TASKS, TINY_WORLD

# ------------------------------------------------------------------------- the suite is fixed

SUITE_SEEDS = {
    "static_n4": tuple(range(10)), "static_n8": tuple(range(10)),
    "static_n12": tuple(range(10)), "static_n20": tuple(range(10)),
    "static_n50": (0, 1, 2), "static_n100": (0, 1, 2),
    "dynamic_n8": (0, 1, 2), "radio_20m": (0, 1, 2), "radio_10m": (0, 1, 2), "faults": (0, 1, 2),
    "chicago_n500_30s": (0, 1), "chicago_n1000_30s": (0, 1), "nyc_1seat": (0, 1),
    "nyc_4seats": (0, 1), "nyc_ev": (0,), "grid_10k": (0,),
}
QUICK = ["static_n4", "static_n8", "static_n20", "dynamic_n8", "radio_20m", "radio_10m",
         "faults", "chicago_n500_30s", "nyc_1seat", "nyc_4seats", "nyc_ev"]


def test_the_suite_is_fixed():
    assert suite.VERSION == "bench-2026.1"
    assert {i.name: i.seeds for i in suite.SUITE} == SUITE_SEEDS
    assert [i.name for i in suite.instances("all", quick=True)] == QUICK
    assert suite.QUICK_SEEDS == (0, 1)
    assert [i.name for i in suite.instances("robots")] == list(SUITE_SEEDS)[:10]
    by = {i.name: i for i in suite.SUITE}
    assert [by[f"static_n{n}"].document()["fleet"]["agents"] for n in (4, 8, 12, 20, 50, 100)] \
        == [4, 8, 12, 20, 50, 100]
    assert by["radio_10m"].document()["comms"]["range"] == 10.0
    assert by["radio_20m"].document()["comms"]["range"] == 20.0
    assert by["chicago_n1000_30s"].document()["dispatch"]["batch_window"] == 30.0
    assert by["nyc_4seats"].pooled() and by["nyc_ev"].electric()
    assert by["nyc_4seats"].baselines() == ("hungarian", "greedy", "rtv")
    assert by["grid_10k"].document()["fleet"]["agents"] == 10_000
    assert {i.world() for i in suite.SUITE if i.group == "fleets"} == {"road"}
    assert suite.seeds_of(by["static_n4"], k=3) == (0, 1, 2)
    assert suite.seeds_of(by["grid_10k"], k=2) == (0, 1)
    assert suite.seeds_of(by["static_n4"], quick=True) == (0, 1)
    assert suite.seeds_of(by["nyc_ev"], quick=True) == (0,)


def test_instance_texts_read_back_and_params_stay_with_their_allocator():
    import tomllib

    inst = next(i for i in suite.SUITE if i.name == "dynamic_n8")
    plain = tomllib.loads(inst.text())
    mine = tomllib.loads(inst.text(allocator="auction", params={"bundle_size": 2}))
    assert "sweep" not in plain and plain["name"] == "bench_dynamic_n8"
    assert mine["dispatch"]["allocator_params"] == {"auction": {"bundle_size": 2}}
    assert {k: v for k, v in mine["dispatch"].items() if k != "allocator_params"} \
        == plain["dispatch"]
    assert tomllib.loads(inst.text(quick=True))["duration"] == 300.0
    cut = Instance("cut", "robots", "paper_dynamic", {"tasks": {"ttl": DELETE}})
    assert "ttl" not in cut.document()["tasks"] and "ttl" in plain["tasks"]


# ------------------------------------------------------------------------- a tiny bench

TINY_VOXEL = Instance("tiny_voxel", "robots", None, seeds=(0, 1), base={
    "seed": 0, "duration": 600.0, "world": {**TINY_WORLD, "obstacles": TINY_OBSTACLES},
    "fleet": TINY_FLEET, "tasks": TINY_TASKS, "dispatch": TINY_DISPATCH})
TINY_ROAD = Instance("tiny_road", "fleets", None, seeds=(0, 1), base={
    "seed": 0, "duration": 1200.0,
    "world": {"network": "manhattan", "blocks": [4, 4], "block": 200.0, "speed": 10.0},
    "fleet": {"agents": 4},
    "tasks": {"source": "poisson", "rate": 0.02, "count": 20, "max_wait": 600.0},
    "dispatch": {"allocator": "hungarian", "planner": "dijkstra", "batch_window": 30.0}})


@pytest.fixture
def tiny(monkeypatch):
    """The bench's suite replaced by the two tiny instances."""
    monkeypatch.setattr("bench.run.instances", lambda which, quick: [TINY_VOXEL, TINY_ROAD])


def _bench(out, **kw):
    return run_bench(["auction"], out, params={"bundle_size": 2}, workers=1, **kw)


def _untimed(rows):
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def _same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.keys() == y.keys()
        for k in x:
            assert x[k] == y[k] or (isinstance(x[k], float) and math.isnan(x[k])
                                    and math.isnan(y[k])), k


def test_a_tiny_bench_writes_its_files_is_deterministic_and_resumes(tiny, tmp_path, capsys):
    res = _bench(tmp_path / "a")
    rows = res.rows
    # hungarian (reference) first, then the named allocator, then the baselines; 2 seeds each
    assert [(r["instance"], r["allocator"], r["seed"]) for r in rows] == [
        (i, a, s) for i in ("tiny_voxel", "tiny_road")
        for a in ("hungarian", "auction", "greedy") for s in (0, 1)]
    assert all(r["status"] == "ok" for r in rows), [r["status"] for r in rows]
    assert res.counts == {"done": 12, "skipped": 0, "failed": 0, "timeout": 0,
                          "unsupported": 0}
    assert {r["world"] for r in rows if r["instance"] == "tiny_road"} == {"road"}
    assert all(r["gap"] == 0.0 for r in rows if r["allocator"] == "hungarian")
    road = [r for r in rows if r["world"] == "road"]
    assert all(0 <= r["served_share"] <= 1 and r["vehicle_km"] > 0 for r in road)
    assert all(math.isnan(r["vehicle_km"]) for r in rows if r["world"] == "voxel")
    # the named allocator ran with its parameter, the baselines without
    text = next((tmp_path / "a" / "runs" / "summary").glob(
        "scenario=bench_tiny_road/allocator=auction/**/part-0.parquet"))
    import pyarrow.parquet as pq
    meta = pq.read_schema(text).metadata[b"dispatch.scenario"].decode()
    assert "bundle_size = 2" in meta
    # the command writes the files: the same rows, reused (nothing runs again)
    code = main(["bench", "auction", "--param", "bundle_size=2", "--workers", "1",
                 "--out", str(tmp_path / "a")])
    assert code == 0
    assert "0 run, 12 reused" in capsys.readouterr().out
    with (tmp_path / "a" / "bench.csv").open() as f:
        assert tuple(next(csv.reader(f))) == COLUMNS
    _same(_untimed(read_csv(tmp_path / "a" / "bench.csv")), _untimed(rows))
    md = (tmp_path / "a" / "bench.md").read_text()
    assert "## tiny_voxel" in md and "## tiny_road" in md and "Δ vs hungarian" in md
    assert "**" in md and (tmp_path / "a" / "bench.png").stat().st_size > 0
    # resume after a kill: a run whose files are gone is redone, only it
    marker = next((tmp_path / "a" / "runs" / "_runs").glob(
        "scenario=bench_tiny_road/allocator=greedy/**/seed=1/done.json"))
    marker.unlink()
    again = _bench(tmp_path / "a")
    assert again.counts == {"done": 1, "skipped": 11, "failed": 0, "timeout": 0,
                            "unsupported": 0}
    _same(_untimed(again.rows), _untimed(rows))
    # the same bench from scratch gives the same numbers apart from timings
    other = _bench(tmp_path / "b")
    _same(_untimed(other.rows), _untimed(rows))


def test_an_allocator_that_cannot_run_gets_a_row(tiny, tmp_path):
    res = run_bench(["rtv"], tmp_path, workers=1, only=["tiny_voxel"], seeds=1)
    rtv = [r for r in res.rows if r["allocator"] == "rtv"]
    assert len(rtv) == 1 and rtv[0]["status"].startswith("unsupported: ")
    assert "travel_times" in rtv[0]["status"]
    assert [r["status"] for r in res.rows if r["allocator"] != "rtv"] == ["ok", "ok"]


# ------------------------------------------------------------------------- statistics by hand

def _row(inst, alloc, seed, **metrics):
    return {"world": "voxel", "instance": inst, "allocator": alloc, "seed": seed,
            "status": "ok", **metrics}


def test_intervals_and_paired_differences_equal_a_hand_computation():
    ref = [10.0, 12.0, 14.0]
    mine = [11.0, 15.0, 14.5]
    rows = [_row("x", "hungarian", s, served_share=v, cost_per_assignment=v)
            for s, v in enumerate(ref)]
    rows += [_row("x", "greedy", s, served_share=v, cost_per_assignment=v)
             for s, v in enumerate(mine)]
    rows.append({**_row("x", "greedy", 3, served_share=99.0), "status": "failed: boom"})
    ivs = stats.intervals(rows, ["served_share"])
    t2 = 4.302652729911275  # Student t, 97.5 %, 2 degrees of freedom
    # greedy: mean 13.5, sd sqrt(((-2.5)^2 + 1.5^2 + 1^2) / 2) = sqrt(4.75)
    iv = ivs[("x", "greedy", "served_share")]
    assert iv.n == 3 and iv.mean == pytest.approx(13.5)
    assert iv.half == pytest.approx(t2 * math.sqrt(4.75 / 3))
    # differences 1, 3, 0.5: mean 1.5, sd sqrt((0.25 + 2.25 + 1) / 2) = sqrt(1.75)
    d = stats.paired_differences(rows, metrics=["served_share"])[("x", "greedy", "served_share")]
    assert d.mean == pytest.approx(1.5) and d.half == pytest.approx(t2 * math.sqrt(1.75 / 3))
    assert ("x", "hungarian", "served_share") not in stats.paired_differences(rows)
    stats.fill_gaps(rows)
    assert [r["gap"] for r in rows[3:6]] == pytest.approx([0.1, 0.25, 0.5 / 14])
    assert math.isnan(rows[6]["gap"])  # a failed run has no gap


# ------------------------------------------------------------------------- the printed board

def test_the_printed_board_fits_80_columns_and_marks_separated_allocators():
    """Robots and fleets each get a table of at most 80 characters a line, every instance and
    allocator in it, a cell ``mean ± half-width``; ``*`` on greedy where its paired difference
    to hungarian excludes 0 (served share +0.1 on every seed), not where it does not (the
    timing column, equal); an unsupported allocator says so in place of numbers."""
    import io

    from rich.console import Console

    from bench.board import board_tables, interval_note

    rows = [{**r, "world": "road"} for r in _board()]  # x: served 0.5, 0.6, 0.7; greedy +0.1
    rows += [_row("static_n4", a, s, gap=g, conflict_free_share=1.0, ms_per_decision=2.0)
             for a, gaps in (("hungarian", [0.0, 0.0]), ("local_hungarian", [0.1, 0.3]))
             for s, g in enumerate(gaps)]
    rows.append({**_row("x", "rtv", 0), "world": "road", "status": "unsupported: no times"})
    buf = io.StringIO()
    console = Console(file=buf, width=80, force_terminal=False)
    tables = board_tables(rows)
    for title, t in tables:
        console.print(title)
        console.print(t)
    lines = buf.getvalue().splitlines()
    assert len(tables) == 2 and max(len(line) for line in lines) <= 80

    def row(name, n=0):
        return [x for x in lines if x.split()[:1] == [name]][n].split()

    # served %: greedy 70 ± t(2) * 10 / sqrt(3) = 24.8, separated from hungarian (+10 on each
    # seed); its timing equals hungarian's: no star
    assert row("greedy") == ["greedy", "70", "±", "24.8*", "–", "1", "±", "0"]
    assert row("hungarian")[:4] == ["hungarian", "0", "±", "0"]  # robots first: its own gap
    assert row("hungarian", 1)[:4] == ["hungarian", "60", "±", "24.8"]
    # two seeds, gaps 10 % and 30 %: 20 ± 12.7 * 10 = 127, not separated from hungarian's 0
    assert row("local_hungarian")[:4] == ["local_hungarian", "20", "±", "127"]
    assert row("rtv") == ["rtv", "unsupported"]
    assert ["x", "(3", "seeds)"] in [x.split() for x in lines]
    assert ["static_n4", "(2", "seeds)"] in [x.split() for x in lines]
    note = interval_note(rows)
    assert "2 to 3 seed(s)" in note and "12.7 standard errors" in note
    assert max(len(line) for line in note.splitlines()) <= 80


# ------------------------------------------------------------------------- --against

def _board():
    return [_row("x", a, s, served_share=v + (0.1 if a == "greedy" else 0.0),
                 ms_per_decision=1.0)
            for a in ("hungarian", "greedy") for s, v in enumerate([0.5, 0.6, 0.7])]


def test_against_flags_a_planted_regression_and_passes_an_equal_board():
    before = _board()
    assert against.compare(before, _board()) == []
    slower = [{**r, "ms_per_decision": 50.0} for r in _board()]  # timings: another machine
    assert against.compare(before, slower) == []
    worse = _board()
    for r in worse:
        if r["allocator"] == "greedy":
            r["served_share"] -= 0.5  # far beyond the intervals (half-width ~0.25)
    flagged = against.compare(before, worse)
    assert [(d.instance, d.allocator, d.metric) for d in flagged] == [
        ("x", "greedy", "served_share")]
    nudged = _board()
    nudged[3]["served_share"] += 0.01  # inside the intervals
    assert against.compare(before, nudged) == []


def test_against_from_files_round_trip(tmp_path):
    write_csv(_board(), tmp_path / "bench.csv")
    assert against.compare(read_csv(tmp_path / "bench.csv"), _board()) == []
    (tmp_path / "bad.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(BenchFileError, match="bad.csv"):
        read_csv(tmp_path / "bad.csv")


# ------------------------------------------------------------------------- one-line errors

def _error(capsys, argv):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    return err


def test_wrong_inputs_give_one_line(tmp_path, capsys):
    err = _error(capsys, ["bench", "nope", "--out", str(tmp_path)])
    assert "unknown allocator 'nope'" in err and "dispatch new allocator nope" in err
    assert "dispatch new allocator NAME" in _error(capsys, ["bench", "My-Alloc", "--out",
                                                            str(tmp_path)])
    bad = tmp_path / "old.csv"
    bad.write_text("a,b\n1,2\n")
    assert "not a bench.csv" in _error(capsys, ["bench", "greedy", "--against", str(bad),
                                                "--out", str(tmp_path)])
    bad.write_bytes(b"world,instance,allocator,seed,status\nvoxel,x,greedy,zero,ok\n")
    assert "line 2" in _error(capsys, ["bench", "greedy", "--against", str(bad)])
    assert "no such" in _error(capsys, ["bench", "greedy", "--against",
                                        str(tmp_path / "missing.csv")]).lower()
    assert "--param must be KEY=VALUE" in _error(capsys, ["bench", "greedy", "--param", "x",
                                                          "--instance", "static_n4"])
    assert "no instance nope" in _error(capsys, ["bench", "greedy", "--instance", "nope"])


def test_a_run_that_fails_gets_a_row(tiny, tmp_path, monkeypatch):
    import dispatch.run.runner

    def boom(spec, out, flush_rows=0, progress=None):
        raise RuntimeError("planted failure")

    monkeypatch.setattr(dispatch.run.runner, "run_one", boom)
    res = run_bench([], tmp_path, workers=1, only=["tiny_voxel"], seeds=1)
    assert [r["status"] for r in res.rows] == ["failed: RuntimeError: planted failure"] * 2


def test_a_run_past_the_time_limit_is_stopped_and_not_tried_again(tiny, tmp_path, capsys):
    """A run past --time-limit stops at a progress tick and its row says timeout; a later
    call with a limit no longer than the time it ran does not run it again, a longer one
    does (and finishes it)."""
    res = run_bench([], tmp_path, workers=1, only=["tiny_road"], seeds=1, time_limit=0.0)
    assert res.counts == {"done": 0, "skipped": 0, "failed": 0, "timeout": 2,
                          "unsupported": 0}
    assert all(r["status"].startswith("timeout: past its limit of 0 s of wall time")
               and math.isnan(r["served_share"]) for r in res.rows), res.rows
    again = run_bench([], tmp_path, workers=1, only=["tiny_road"], seeds=1, time_limit=0.0)
    assert again.counts["timeout"] == 2 and again.counts["done"] == 0
    assert [r["status"] for r in again.rows] == [r["status"] for r in res.rows]
    longer = run_bench([], tmp_path, workers=1, only=["tiny_road"], seeds=1, time_limit=600.0)
    assert longer.counts["done"] == 2 and all(r["status"] == "ok" for r in longer.rows)
    assert main(["bench", "greedy", "--time-limit", "0", "--out", str(tmp_path)]) == 2
    assert "--time-limit must be > 0 minutes" in capsys.readouterr().err


def test_a_run_stuck_in_one_long_call_is_stopped_by_the_timer(tiny, tmp_path, monkeypatch):
    """No progress tick comes while one call (a decision of thousands of vehicles) runs for
    minutes: the timer stops it there."""
    import time

    import dispatch.run.runner

    slept = []

    def stuck(spec, out, flush_rows=0, progress=None):
        time.sleep(30.0)
        slept.append(spec.run_id)  # (reached only if nothing stopped the call)

    monkeypatch.setattr(dispatch.run.runner, "run_one", stuck)
    res = run_bench([], tmp_path, workers=1, only=["tiny_voxel"], seeds=1, time_limit=0.5)
    assert slept == []  # both calls were stopped inside the sleep
    assert [r["status"] for r in res.rows] == ["timeout: past its limit of 0 s of wall time"] * 2


# ------------------------------------------------------------------------- above the kernel

def test_the_kernel_imports_nothing_of_bench_and_bench_no_plugin():
    import ast

    from tests.conftest import ROOT

    def imports(package):
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Import):
                    yield from ((path.name, a.name.partition(".")[0]) for a in node.names)
                elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                    yield path.name, node.module.partition(".")[0]

    assert [i for i in imports("dispatch") if i[1] == "bench"] == []
    plugins = {"allocators", "planners", "repositioners", "chargers", "analysis", "learning"}
    assert [i for i in imports("bench") if i[1] in plugins] == []


def test_a_named_variant_must_be_declared_or_made_by_params():
    from bench.run import BenchError, check_allocators

    check_allocators(["magnnet:paper", "magnnet:ppo", "greedy"])
    check_allocators(["magnnet:mine"], {"variant": "paper"})
    with pytest.raises(BenchError, match="'magnnet:nope'.*declares the variants match"):
        check_allocators(["magnnet:nope"])


def test_a_network_trained_per_team_size_is_unsupported_on_other_sizes():
    """``magnnet:paper`` ships networks for N = M in {4, 8, 12, 20}: the bench runs it on those
    static instances and reports the others (another size, a dynamic problem) as unsupported,
    naming the sizes, instead of failing at the first decision."""
    from bench.run import plan

    chosen = [i for i in suite.SUITE if i.name in ("static_n8", "static_n50", "dynamic_n8")]
    p = plan(chosen, ["magnnet:paper", "hungarian"], quick=False, seeds=1, params={})
    ran = {(i.name, a) for i, a, _ in p.specs}
    assert {x for x in ran if x[1] == "magnnet:paper"} == {("static_n8", "magnnet:paper")}
    assert {x for x in ran if x[1] == "hungarian"} == {
        ("static_n8", "hungarian"), ("static_n50", "hungarian"), ("dynamic_n8", "hungarian")}
    why = {r["instance"]: r["status"] for r in p.unsupported}
    assert why == {
        "static_n50": "unsupported: magnnet:paper decides static problems of N = M in "
                      "{4, 8, 12, 20} only, not N = 50 agents, M = 50 tasks",
        "dynamic_n8": "unsupported: magnnet:paper decides static problems of N = M in "
                      "{4, 8, 12, 20} only, not poisson tasks"}


def test_the_default_output_folder_is_ignored_by_git():
    """``dispatch bench`` writes ``bench_out/`` by default: git ignores it, so a bench does not
    leave the working tree dirty."""
    import shutil
    import subprocess

    from tests.conftest import ROOT

    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout")
    proc = subprocess.run(["git", "check-ignore", "-q", "bench_out/bench.csv"], cwd=ROOT)
    assert proc.returncode == 0
