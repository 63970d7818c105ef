"""Scenario files: bad ones get one clear ScenarioError (file, dotted key, reason); good ones
load and expand into the runs their sweep declares."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dispatch.errors import ScenarioError
from dispatch.run import cli
from dispatch.scenario.load import load_scenario
from tests.conftest import ROOT, scenario_text, write_scenario

SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))


def load_error(path: Path) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    return info.value


def assert_names(err: ScenarioError, file: Path, key: str, reason: str) -> None:
    """The message names the file, the key and the reason; the attributes agree."""
    msg = str(err)
    assert file.name in msg, msg
    assert key in msg, msg
    assert reason in msg, msg
    assert Path(err.file).name == file.name
    assert err.key == key
    assert reason in err.reason
    # one error, not a chain of tracebacks: nothing is chained as the explicit cause
    assert err.__cause__ is None


def assert_in_trace(err: ScenarioError, trace: Path, where: str, reason: str) -> None:
    """A trace's error names the scenario file and ``tasks.trace``, then the trace, ``where``
    in it (a row, ``<header>``; ``<file>``: the file as a whole) and the reason."""
    msg = str(err)
    assert err.key == "tasks.trace" and Path(err.file).suffix == ".toml", msg
    assert f"tasks.trace: {trace.name}" in msg, msg
    assert where == "<file>" or f"{trace.name}: {where}: " in msg, msg
    assert reason in err.reason, msg
    assert err.__cause__ is None


# ----------------------------------------------------------------------------- bad files

BAD_SCENARIOS = {
    # id: (keywords for scenario_text, dotted key, reason fragment)
    "unknown root key": (dict(agentz=3), "agentz", "unknown key"),
    "unknown nested key": (dict(fleet={"agentz": 3}), "fleet.agentz", "unknown key"),
    "unknown doubly nested key": (dict(obstacles={"colour": "red"}), "world.obstacles.colour",
                                  "unknown key"),
    "agents not an integer": (dict(fleet={"agents": "ten"}), "fleet.agents",
                              "must be an integer"),
    "agents a float": (dict(fleet={"agents": 2.5}), "fleet.agents", "must be an integer"),
    "size of two": (dict(world={"size": [1, 2]}), "world.size", "list of 3 numbers"),
    "size with a string": (dict(world={"size": [12, "12", 6]}), "world.size",
                           "list of 3 numbers"),
    "negative speed": (dict(fleet={"uav_speed": -1.0}), "fleet.uav_speed", "must be > 0"),
    "zero ground speed": (dict(fleet={"ugv_speed": 0}), "fleet.ugv_speed", "must be > 0"),
    "fraction above one": (dict(fleet={"uav_fraction": 1.5}), "fleet.uav_fraction",
                           "must be <= 1"),
    "negative seed": (dict(seed=-1), "seed", "must be >= 0"),
    "zero duration": (dict(duration=0.0), "duration", "must be > 0"),
    "too many obstacles": (dict(obstacles={"count": 100}), "world.obstacles.count",
                           "do not fit"),
    "min larger than max": (dict(obstacles={"min_size": [4, 1, 1]}), "world.obstacles.min_size",
                            "larger than max_size"),
    "size not whole cells": (dict(world={"cell": 5.0}), "world.size", "whole number"),
    "periodic without interval": (dict(tasks={"source": "periodic"}), "tasks.interval",
                                  "is required"),
    "poisson without rate": (dict(tasks={"source": "poisson"}), "tasks.rate", "is required"),
    "unknown source": (dict(tasks={"source": "sometimes"}), "tasks.source", "must be one of"),
    "interval on a static source": (dict(tasks={"interval": 2.0}), "tasks.interval",
                                    "only used when"),
    "trace without file": (dict(tasks={"source": "trace"}), "tasks.trace", "is required"),
    "non-positive ttl": (dict(tasks={"ttl": 0.0}), "tasks.ttl", "must be > 0"),
    "too many agents": (dict(fleet={"agents": 500}), "fleet.agents", "distinct free cells"),
    "sweep agents below one": (dict(sweep={"agents": [2, 0]}), "sweep.agents", "must be >= 1"),
    "sweep allocator not names": (dict(sweep={"allocator": [1, 2]}), "sweep.allocator",
                                  "list of names"),
    "batch window negative": (dict(dispatch={"batch_window": -0.5}), "dispatch.batch_window",
                              "must be >= 0"),
}


@pytest.mark.parametrize("kw,key,reason", BAD_SCENARIOS.values(), ids=BAD_SCENARIOS.keys())
def test_bad_scenario_names_file_key_and_reason(tmp_path, kw, key, reason):
    path = write_scenario(tmp_path, "bad_scenario.toml", **kw)
    assert_names(load_error(path), path, key, reason)


def test_section_that_is_not_a_table(tmp_path):
    path = tmp_path / "flat.toml"
    path.write_text('name = "flat"\nfleet = 3\n', encoding="utf-8")
    assert_names(load_error(path), path, "fleet", "must be a table")


def test_toml_syntax_error(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text(scenario_text().replace("[fleet]", "[fleet"), encoding="utf-8")
    err = load_error(path)
    line = scenario_text().splitlines().index("[fleet]") + 1
    assert_names(err, path, f"line {line}, column 7", "TOML syntax: Expected ']'")
    assert err.__suppress_context__  # the TOMLDecodeError is not shown as a second traceback


def test_missing_scenario_file(tmp_path):
    path = tmp_path / "nowhere.toml"
    assert_names(load_error(path), path, "<file>", "cannot be read")


# ----------------------------------------------------------------------------- traces


def trace_scenario(tmp_path: Path, trace_name: str) -> Path:
    return write_scenario(tmp_path, "traced.toml",
                          tasks={"source": "trace", "trace": trace_name, "ground_fraction": None})


def write_csv(path: Path, rows: list[str], header: str = "release_time,x,y,z") -> Path:
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


def test_good_trace_loads_sorted(tmp_path):
    write_csv(tmp_path / "trace.csv", ["2.0,1.5,1.5,0.5", "0.5,3.0,4.0,2.5", "1.0,11.9,0,5.9"])
    sc = load_scenario(trace_scenario(tmp_path, "trace.csv"))
    assert sc.tasks.trace == (tmp_path / "trace.csv").resolve()
    trips = sc.tasks.trips
    assert list(trips.t) == [0.5, 1.0, 2.0]
    assert (trips.t[0], *trips.origin[0]) == (0.5, 3.0, 4.0, 2.5)
    assert list(trips.row) == [2, 3, 1] and trips.dest is None


@pytest.mark.parametrize(
    "row,reason",
    [
        ("3.0,12.0,1.0,0.5", "x = 12.0 is outside the world"),
        ("3.0,1.0,-0.5,0.5", "y = -0.5 is outside the world"),
        ("3.0,1.0,1.0,6.0", "z = 6.0 is outside the world"),
    ],
    ids=["x at the far edge", "negative y", "z above the roof"],
)
def test_trace_task_outside_world_names_row(tmp_path, row, reason):
    trace = write_csv(tmp_path / "outside.csv", ["0.0,1.5,1.5,0.5", "1.0,2.5,2.5,0.5", row])
    err = load_error(trace_scenario(tmp_path, "outside.csv"))
    assert_in_trace(err, trace, "row 3", reason)


def test_trace_non_numeric_cell_names_row(tmp_path):
    trace = write_csv(tmp_path / "words.csv", ["0.0,1.5,1.5,0.5", "1.0,two,2.5,0.5"])
    err = load_error(trace_scenario(tmp_path, "words.csv"))
    assert_in_trace(err, trace, "row 2", "x is not a number")
    assert "'two'" in str(err)


def test_trace_empty_cell_names_row(tmp_path):
    trace = write_csv(tmp_path / "holes.csv", ["0.0,1.5,1.5,0.5", "1.0,1.5,,0.5"])
    assert_in_trace(load_error(trace_scenario(tmp_path, "holes.csv")), trace, "row 2",
                 "y is not a number")


def test_trace_negative_time(tmp_path):
    trace = write_csv(tmp_path / "early.csv", ["-1.0,1.5,1.5,0.5"])
    assert_in_trace(load_error(trace_scenario(tmp_path, "early.csv")), trace, "row 1", "negative")


def test_trace_missing_column(tmp_path):
    trace = write_csv(tmp_path / "flat.csv", ["0.0,1.5,1.5"], header="release_time,x,y")
    assert_in_trace(load_error(trace_scenario(tmp_path, "flat.csv")), trace, "<header>",
                 "missing column(s): z")


def test_trace_file_missing(tmp_path):
    err = load_error(trace_scenario(tmp_path, "absent.csv"))
    assert_in_trace(err, tmp_path / "absent.csv", "<file>", "not found")


def test_trace_wrong_suffix(tmp_path):
    trace = tmp_path / "trace.txt"
    trace.write_text("release_time,x,y,z\n0,1,1,0\n", encoding="utf-8")
    assert_in_trace(load_error(trace_scenario(tmp_path, "trace.txt")), trace, "<file>",
                 ".csv or .parquet")


def test_trace_parquet_outside_world(tmp_path):
    trace = tmp_path / "trace.parquet"
    pq.write_table(pa.table({"t": [0.0, 1.0], "x": [1.5, 1.5], "y": [1.5, 30.0],
                             "z": [0.5, 0.5]}), trace)
    assert_in_trace(load_error(trace_scenario(tmp_path, "trace.parquet")), trace, "row 2",
                 "y = 30.0 is outside the world")


def test_trace_parquet_that_is_not_parquet(tmp_path):
    trace = tmp_path / "fake.parquet"
    trace.write_bytes(b"this is not parquet")
    assert_in_trace(load_error(trace_scenario(tmp_path, "fake.parquet")), trace, "<file>",
                 "cannot be read as a table")


# ----------------------------------------------------------------------------- CLI path


def test_cli_validate_bad_file_exits_2_without_traceback(tmp_path, capsys):
    path = write_scenario(tmp_path, "bad_cli.toml", fleet={"agentz": 3})
    assert cli.main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    text = " ".join((out + err).split())  # rich may wrap long lines
    assert "Traceback" not in out + err
    assert "bad_cli.toml" in text
    assert "fleet.agentz" in text
    assert "unknown key" in text


def test_cli_validate_bad_file_subprocess(tmp_path, cli):
    path = write_scenario(tmp_path, "bad_sub.toml", fleet={"agents": "ten"})
    proc = cli("validate", path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stdout + proc.stderr
    assert "bad_sub.toml" in proc.stderr
    assert "fleet.agents" in proc.stderr
    assert "must be an integer" in proc.stderr


def test_cli_validate_missing_trace_row(tmp_path, capsys):
    write_csv(tmp_path / "outside.csv", ["0.0,1.5,1.5,0.5", "1.0,99,2.5,0.5"])
    path = trace_scenario(tmp_path, "outside.csv")
    assert cli.main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    text = " ".join((out + err).split())
    assert "Traceback" not in out + err
    assert "outside.csv" in text and "row 2" in text and "outside the world" in text


def test_cli_validate_bad_override(tmp_path, capsys):
    path = write_scenario(tmp_path)
    # a bad override of ``run`` is a ScenarioError too, caught before anything is written
    assert cli.main(["run", str(path), "--agents", "0", "--out", str(tmp_path / "o")]) == 2
    out, err = capsys.readouterr()
    text = " ".join((out + err).split())
    assert "--agents" in text and "must be >= 1" in text
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- good files


def test_shipped_scenarios_exist():
    names = {p.name for p in SCENARIOS}
    assert {"paper_static.toml", "paper_dynamic.toml"} <= names


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
def test_shipped_scenario_validates(path, capsys):
    sc = load_scenario(path)
    assert sc.name == path.stem
    assert sc.text == path.read_text(encoding="utf-8")
    assert cli.main(["validate", str(path)]) == 0
    out, _ = capsys.readouterr()
    assert "ok" in out and f"{len(sc.runs())} run(s)" in out


def test_validate_line_survives_long_paths(tmp_path, capsys):
    """The status line is one line however long the path (CI clones live deep in the tree)."""
    deep = tmp_path.joinpath(*["a_rather_long_folder_name"] * 6)
    deep.mkdir(parents=True)
    path = deep / "paper_static.toml"
    path.write_text((ROOT / "scenarios" / "paper_static.toml").read_text(encoding="utf-8"),
                    encoding="utf-8")
    assert cli.main(["validate", str(path)]) == 0
    out, _ = capsys.readouterr()
    line = out.strip()
    assert "\n" not in line
    assert str(path) in line and f"{len(load_scenario(path).runs())} run(s)" in line


def test_paper_static_sweep_expansion():
    sc = load_scenario(ROOT / "scenarios" / "paper_static.toml")
    assert sc.sweep.allocator == ("hungarian", "magnnet", "local_hungarian", "greedy", "random")
    assert sc.sweep.agents == (4, 8, 12, 20)
    n_seeds = len(sc.sweep.seed)
    assert n_seeds >= 1
    runs = sc.runs()
    assert len(runs) == len(sc.sweep.allocator) * 4 * n_seeds
    assert len({r.run_id for r in runs}) == len(runs)
    assert {(r.allocator, r.agents, r.seed) for r in runs} == {
        (a, n, s) for a in sc.sweep.allocator for n in sc.sweep.agents for s in sc.sweep.seed
    }
    assert {r.planner for r in runs} == {"astar"}
    # M = N for a static source without a count
    assert all(r.n_static_tasks == r.agents for r in runs)


def test_overrides_replace_sweep_dimension():
    sc = load_scenario(ROOT / "scenarios" / "paper_static.toml")
    n_seeds = len(sc.sweep.seed)
    assert len(sc.runs(agents=5)) == len(sc.sweep.allocator) * n_seeds
    assert {r.agents for r in sc.runs(agents=5)} == {5}
    only_greedy = sc.runs(allocator="greedy")
    assert len(only_greedy) == 4 * n_seeds and {r.allocator for r in only_greedy} == {"greedy"}
    one_seed = sc.runs(seed=77)
    assert len(one_seed) == len(sc.sweep.allocator) * 4 and {r.seed for r in one_seed} == {77}
    single = sc.runs(allocator="random", planner="astar", agents=3, seed=1)
    assert [(r.allocator, r.planner, r.agents, r.seed) for r in single] == [
        ("random", "astar", 3, 1)]
    assert single[0].fleet.agents == 3


def test_no_sweep_is_one_run(tiny_scenario):
    sc = load_scenario(tiny_scenario)
    assert not sc.sweep.declared
    runs = sc.runs()
    assert [(r.allocator, r.planner, r.agents, r.seed) for r in runs] == [
        ("hungarian", "astar", 3, 0)]


def test_override_too_many_agents(tiny_scenario):
    sc = load_scenario(tiny_scenario)
    with pytest.raises(ScenarioError) as info:
        sc.runs(agents=10_000)
    assert "--agents" in str(info.value) and tiny_scenario.name in str(info.value)


def test_sweep_too_many_agents_names_the_sweep_key(tmp_path):
    path = tmp_path / "big_sweep.toml"
    path.write_text('[world]\nsize = [12, 12, 6]\n[world.obstacles]\ncount = 1\n'
                    'max_size = [3, 3, 6]\n[sweep]\nagents = [4, 500]\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert "sweep.agents" in str(info.value) and "500 vehicles" in str(info.value)


def test_defaults_fill_missing_sections(tmp_path):
    path = tmp_path / "bare.toml"
    path.write_text('name = "bare"\n', encoding="utf-8")
    sc = load_scenario(path)
    assert sc.world.size == (50.0, 50.0, 30.0)
    assert sc.fleet.agents == 8
    assert sc.tasks.source == "static"
    assert sc.dispatch.allocator == "hungarian"
    assert len(sc.runs()) == 1


def test_scenario_is_frozen(tiny_scenario):
    sc = load_scenario(tiny_scenario)
    with pytest.raises(AttributeError):
        sc.fleet.agents = 4  # type: ignore[misc]


# ----------------------------------------------------------------------------- regressions
# Each of these once failed: a kernel bug found while writing these tests.


def test_obstacle_wider_than_world_is_a_scenario_error(tmp_path):
    from dispatch.run.runner import run_one

    path = write_scenario(tmp_path, obstacles={"count": 1, "max_size": [20, 3, 6]})
    try:
        specs = load_scenario(path).runs(seed=0)
    except ScenarioError as e:
        assert "world.obstacles.max_size" in str(e)
        return
    run_one(specs[0])  # or the world clips the sizes and the run succeeds


def test_validated_obstacles_build_for_every_seed(tmp_path):
    from dispatch.errors import WorldError
    from dispatch.space.world import world_for

    path = write_scenario(tmp_path, obstacles={"count": 2, "min_size": [5, 5, 1],
                                               "max_size": [5, 5, 1]})
    try:
        sc = load_scenario(path)
    except ScenarioError:
        return
    failed = []
    for seed in range(20):
        try:
            world_for(sc.world, seed)
        except WorldError:
            failed.append(seed)
    assert not failed, f"validated, but obstacles cannot be placed for seeds {failed}"


def test_trace_csv_with_byte_order_mark(tmp_path):
    (tmp_path / "bom.csv").write_bytes(b"\xef\xbb\xbfrelease_time,x,y,z\n0,1.5,1.5,0.5\n")
    sc = load_scenario(trace_scenario(tmp_path, "bom.csv"))
    assert (sc.tasks.trips.t.tolist(), sc.tasks.trips.origin.tolist()) == ([0.0], [[1.5, 1.5, 0.5]])
