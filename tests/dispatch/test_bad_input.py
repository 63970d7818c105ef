"""Bad input in one line (exit 2, no traceback) and output safety: plugin parameters the
constructor rejects, checkpoints that are not checkpoints, undecodable or unreadable files,
resource limits and ``--ignore-limits``, sanitised output folders, no silent overwrite (a run
already there is shown, not rerun; ``--overwrite`` reruns it), two scenarios in one folder."""

from __future__ import annotations

import pytest

from dispatch.config.scenario import Limits, safe_name
from dispatch.errors import ScenarioError
from dispatch.run import cli
from dispatch.scenario.load import load_scenario
from tests.conftest import ROOT, write_scenario

CHECKPOINTS = ROOT / "allocators" / "magnnet" / "checkpoints"


def validate(path, *extra, capsys):
    code = cli.main(["validate", str(path), *extra])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, " ".join((out + err).split()), err


def one_line_error(path, capsys, *extra, cmd="validate"):
    code = cli.main([cmd, str(path), *extra])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert "Traceback" not in out + err
    assert len(err.strip().splitlines()) == 1, err
    return err.strip()


@pytest.mark.parametrize("dispatch,words", [
    ({"planner": "rstar", "params": "w = 0.5"}, ["planner 'rstar'", "w = 0.5", "must be >= 1"]),
    ({"planner": "rrt_star", "params": "max_iterations = 0"},
     ["planner 'rrt_star'", "max_iterations = 0", "ValueError"]),
    ({"planner": "reservation", "params": "retry_after = 0"},
     ["planner 'reservation'", "retry_after = 0", "must be > 0"]),
    ({"planner": "rrt_star", "params": "seed = -1"}, ["planner 'rrt_star'", "seed = -1"]),
    ({"planner": "astar", "params": "bogus = 1"},
     ["dispatch.planner_params.bogus", "planner 'astar' takes no parameter 'bogus'"]),
])
def test_planner_parameters_rejected_at_validate(tmp_path, capsys, dispatch, words):
    path = write_scenario(tmp_path, dispatch={"planner": dispatch["planner"]},
                          extra=f"[dispatch.planner_params]\n{dispatch['params']}\n")
    err = one_line_error(path, capsys)
    for w in words:
        assert w in err


@pytest.mark.parametrize("allocator,checkpoint,words", [
    ("magnnet", "text", "is not a MAGNNET checkpoint"),
    ("magnnet", 3, "must be the path of a model.pt"),
    ("magnnet", "missing", "no such file"),
    ("magnnet", str(CHECKPOINTS / "paper_n4.pt"), "model of kind 'paper'"),
])
def test_checkpoint_checked_when_built(tmp_path, capsys, allocator, checkpoint, words):
    (tmp_path / "notes.pt").write_text("not a checkpoint\n", encoding="utf-8")
    value = {"text": str(tmp_path / "notes.pt"), "missing": str(tmp_path / "nope.pt")}.get(
        checkpoint, checkpoint)
    lit = repr(value) if isinstance(value, int) else f'"{value}"'
    path = write_scenario(tmp_path, dispatch={"allocator": allocator},
                          extra=f"[dispatch.allocator_params]\ncheckpoint = {lit}\n")
    err = one_line_error(path, capsys)
    assert f"allocator '{allocator}'" in err and words in err


def test_good_checkpoint_validates(tmp_path, capsys):
    path = write_scenario(tmp_path, dispatch={"allocator": "magnnet"},
                          extra=f'[dispatch.allocator_params]\ncheckpoint = '
                                f'"{CHECKPOINTS / "match.pt"}"\n')
    code, text, _ = validate(path, capsys=capsys)
    assert code == 0, text


# ----------------------------------------------------------------------------- files


def test_dev_zero_is_refused_without_reading(capsys):
    err = one_line_error("/dev/zero", capsys)
    assert "not a regular scenario file" in err


def test_folder_is_refused(tmp_path, capsys):
    assert "is a folder" in one_line_error(tmp_path, capsys)


@pytest.mark.parametrize("encoding,words", [
    ("utf-16", "UTF-16 LE text"), ("utf-16-be-bom", "UTF-16 BE text"),
    ("utf-32", "UTF-32 LE text"), ("latin-1", "is not UTF-8 text"),
])
def test_encodings_in_one_line(tmp_path, capsys, encoding, words):
    text = 'name = "caf\u00e9"\n'
    data = ("\ufeff" + text).encode("utf-16-be") if encoding == "utf-16-be-bom" else \
        text.encode(encoding)
    path = tmp_path / "enc.toml"
    path.write_bytes(data)
    err = one_line_error(path, capsys)
    assert "<encoding>" in err and words in err and "save it as UTF-8" in err


def test_utf8_bom_is_accepted(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbfname = 'bom'\n")
    assert load_scenario(path).name == "bom"


def test_deep_nesting_and_huge_integer(tmp_path, capsys):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n", encoding="utf-8")
    assert "nested too deeply" in one_line_error(path, capsys)
    path.write_text("seed = " + "9" * 5000 + "\n", encoding="utf-8")
    assert "<syntax>" in one_line_error(path, capsys)


def test_file_size_limits_and_ignore_limits(tmp_path, capsys, monkeypatch):
    from dispatch.scenario import load as scenario
    path = write_scenario(tmp_path, tasks={"source": "trace", "trace": "t.csv",
                                           "ground_fraction": None})
    (tmp_path / "t.csv").write_text("t,x,y,z\n0,1.5,1.5,0.5\n", encoding="utf-8")
    monkeypatch.setattr(scenario, "LIMITS", Limits(file_bytes=50, input_bytes=10))
    assert "MiB is refused" in one_line_error(path, capsys)
    monkeypatch.setattr(scenario, "LIMITS", Limits(input_bytes=10))
    err = one_line_error(path, capsys)
    assert "t.csv" in err and "--ignore-limits" in err
    code, text, _ = validate(path, "--ignore-limits", capsys=capsys)
    assert code == 0, text


# ----------------------------------------------------------------------------- limits


@pytest.mark.parametrize("kw,key", [
    ({"world": {"size": [5000, 5000, 30]}, "obstacles": {"count": 0}}, "world.cell"),
    ({"tasks": {"source": "periodic", "interval": 1e-9}}, "tasks.interval"),
    ({"tasks": {"source": "poisson", "rate": 1e9}}, "tasks.rate"),
    ({"duration": 1e12, "tasks": {"source": "periodic", "interval": 2.0, "max_active": 5}},
     "tasks.interval"),
    ({"tasks": {"count": 10**6}}, "tasks.count"),
    ({"sweep": {"seed": list(range(20_000))}}, "sweep"),
])
def test_resource_limits_refuse_then_ignore_limits(tmp_path, capsys, kw, key):
    path = write_scenario(tmp_path, **kw)
    err = one_line_error(path, capsys)
    assert f": {key}: " in err and "use --ignore-limits to run anyway" in err
    # --ignore-limits skips the bound (validate builds the plugins: cheap for these)
    if key not in ("world.cell",):
        code, text, _ = validate(path, "--ignore-limits", capsys=capsys)
        assert code == 0, text


def test_periodic_capped_by_count_is_within_limits(tmp_path, capsys):
    path = write_scenario(tmp_path, duration=1e12,
                          tasks={"source": "periodic", "interval": 2.0, "count": 10})
    assert validate(path, capsys=capsys)[0] == 0


def test_absurd_cell_is_refused_even_past_the_limits(tmp_path, capsys):
    path = write_scenario(tmp_path, world={"size": [50, 50, 30], "cell": 1e-300})
    err = one_line_error(path, capsys, "--ignore-limits")
    assert "world.cell" in err and "per axis" in err and len(err) < 300


@pytest.mark.parametrize("where", ["seed", "sweep", "override"])
def test_seed_must_fit_in_int64(tmp_path, capsys, where):
    big = 2**63
    kw = {"seed": big} if where == "seed" else {"sweep": {"seed": [0, big]}} \
        if where == "sweep" else {}
    path = write_scenario(tmp_path, **kw)
    extra = ("--seed", str(big), "--out", str(tmp_path / "o")) if where == "override" else ()
    err = one_line_error(path, capsys, *extra, cmd="run" if extra else "validate")
    assert not (tmp_path / "o").exists()
    assert str(big - 1) in err or "2^63" in err


def test_manhattan_grid_limit(tmp_path, capsys):
    path = tmp_path / "grid.toml"
    path.write_text('[world]\nnetwork = "manhattan"\nblocks = [100000, 100000]\n'
                    '[fleet]\nagents = 3\n', encoding="utf-8")
    err = one_line_error(path, capsys)
    assert "world.blocks" in err and "10,000,000,000 intersections" in err


# ----------------------------------------------------------------------------- output safety


@pytest.mark.parametrize("name,want", [
    ("../../etc/evil", "etc_evil"), ("/abs/path", "abs_path"), ("..", "scenario"),
    ("a b/c", "a_b_c"), ("ok-name_1.2", "ok-name_1.2"), ("...hidden", "hidden"),
    ("x/../y", "x_._y"),
])
def test_safe_name(name, want):
    assert safe_name(name) == want


def test_scenario_name_is_sanitised_for_paths(tmp_path):
    path = write_scenario(tmp_path, name="../../outside")
    sc = load_scenario(path)
    assert "/" not in sc.name and ".." not in sc.name
    from dispatch.run.runner import default_out

    out = default_out(sc.runs()[0])
    assert out.parts[0] == "runs" and len(out.parts) == 2


def _marker_mtime(out):
    [marker] = (out / "_runs").rglob("done.json")
    return marker.stat().st_mtime_ns


def test_run_shows_a_run_already_there_then_overwrite_reruns_it(tmp_path, capsys):
    """The same command twice: the second exits 0, runs nothing (the folder's files are not
    touched), shows the stored summary and says where it is; --overwrite runs it again."""
    path = write_scenario(tmp_path)
    out = tmp_path / "out"
    assert cli.main(["run", str(path), "--out", str(out)]) == 0
    first = capsys.readouterr().out
    stamp = _marker_mtime(out)
    assert cli.main(["run", str(path), "--out", str(out)]) == 0
    again = capsys.readouterr().out
    assert _marker_mtime(out) == stamp
    assert "already in" in again and str(out) in again and "--overwrite" in again
    assert "run(s) in" not in again  # nothing was run
    # the stored summary is shown as the fresh one was: the same table rows
    rows = [line for line in first.splitlines() if "hungarian" in line]
    assert rows and all(r in again for r in rows)
    assert cli.main(["run", str(path), "--out", str(out), "--overwrite"]) == 0
    assert "1 run(s) in" in capsys.readouterr().out and _marker_mtime(out) != stamp


def test_run_refuses_other_results_of_the_same_run(tmp_path, capsys):
    """Another version of the scenario (same run id, other settings) is not silently
    replaced: one line naming the run and --overwrite."""
    path = write_scenario(tmp_path)
    out = tmp_path / "out"
    assert cli.main(["run", str(path), "--out", str(out)]) == 0
    capsys.readouterr()
    err = one_line_error(path, capsys, "--out", str(out), "--set", "fleet.uav_speed=2.0", cmd="run")
    assert "already holds other results" in err and "--overwrite" in err
    assert cli.main(["run", str(path), "--out", str(out), "--set", "fleet.uav_speed=2.0",
                     "--overwrite"]) == 0


@pytest.mark.parametrize("cmd", ["run", "validate", "sweep"])
def test_old_force_flag_names_the_two_flags(tmp_path, capsys, cmd):
    path = write_scenario(tmp_path)
    with pytest.raises(SystemExit) as e:
        cli.main([cmd, str(path), "--force"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--overwrite" in err and "--ignore-limits" in err


def test_two_scenarios_share_one_folder(tmp_path, capsys):
    from analysis.io import open_results

    a = write_scenario(tmp_path, "a.toml", name="alpha")
    b = write_scenario(tmp_path, "b.toml", name="2024")  # a name that looks like a number
    out = tmp_path / "shared"
    assert cli.main(["run", str(a), "--out", str(out)]) == 0
    assert cli.main(["run", str(b), "--out", str(out)]) == 0
    capsys.readouterr()
    assert (out / "summary" / "scenario=alpha").is_dir()
    assert (out / "summary" / "scenario=2024").is_dir()
    res = open_results(out)
    summary = res.summary
    assert sorted(summary["scenario"]) == ["2024", "alpha"]
    assert summary["scenario"].map(type).eq(str).all()
    for run_id in summary["run_id"]:
        assert len(res.run(run_id)["tasks"]) == 3
        assert res.metadata(run_id)["dispatch.run_id"] == run_id


def test_old_hive_folders_without_scenario_still_read(tmp_path, capsys):
    """Folders written before the scenario was a partition: the scenario is in the summary."""
    import shutil

    import pyarrow.parquet as pq

    from analysis.io import open_results
    from dispatch.run.runner import read_table

    path = write_scenario(tmp_path)
    new = tmp_path / "new"
    assert cli.main(["run", str(path), "--out", str(new)]) == 0
    capsys.readouterr()
    old = tmp_path / "old"
    for table_dir in (new).iterdir():
        if table_dir.name.startswith("_"):
            continue
        for f in table_dir.rglob("part-0.parquet"):
            rel = f.relative_to(table_dir / "scenario=tiny")
            target = old / table_dir.name / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            if table_dir.name == "summary":  # the old layout kept the scenario in the file
                t = read_table(f, {"scenario": "tiny", "allocator": "hungarian",
                                   "planner": "astar", "n_agents": 3, "seed": 0}, "summary")
                t = t.drop_columns(["allocator", "planner", "n_agents", "seed"])
                pq.write_table(t, target)
            else:
                shutil.copy(f, target)
    got, want = open_results(old), open_results(new)
    assert list(got.summary["scenario"]) == ["tiny"]
    assert got.run_ids() == want.run_ids()
    run_id = got.run_ids()[0]
    assert len(got.run(run_id)["events"]) == len(want.run(run_id)["events"])
    assert got.metadata(run_id)["dispatch.run_id"] == run_id


def test_scenario_error_is_one_line_for_huge_values(tmp_path):
    path = write_scenario(tmp_path, sweep={"agents": [[1] * 1000]})
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert len(str(info.value)) < 400


@pytest.mark.parametrize("row,words", [("1,99999999", "has no node 99999999"),
                                       ("1,-5", "has no node -5")])
def test_start_file_rows_checked_at_validate(tmp_path, capsys, row, words):
    (tmp_path / "fleet.csv").write_text(f"vehicle_id,node\n0,3\n{row}\n", encoding="utf-8")
    path = tmp_path / "roads.toml"
    path.write_text('[world]\nnetwork = "manhattan"\nblocks = [4, 4]\n'
                    '[fleet]\nstart = "fleet.csv"\n', encoding="utf-8")
    err = one_line_error(path, capsys)
    assert "fleet.csv" in err and "row 2" in err and words in err


def test_voxel_start_outside_the_world_checked_at_validate(tmp_path, capsys):
    (tmp_path / "fleet.csv").write_text("vehicle_id,x,y,z\n0,0.5,0.5,0.5\n1,1e300,0.5,0.5\n"
                                        "2,2.5,0.5,0.5\n", encoding="utf-8")
    path = write_scenario(tmp_path, obstacles={"count": 0}, fleet={"start": "fleet.csv"})
    err = one_line_error(path, capsys)
    assert "fleet.csv" in err and "outside the world" in err
