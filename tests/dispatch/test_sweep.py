"""Sweeps: the process pool and local Ray give the same Parquet as a serial run; a sweep resumes
after a kill without redoing finished runs; a failing run is recorded and stops nothing."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from dispatch.output.parquet import SCHEMAS
from dispatch.run.resume import (ERRORS, MARKERS, foreign_runs, is_complete, marker_path,
                                 partition_dir)
from dispatch.run.runner import execute, sweep
from dispatch.scenario.load import load_scenario
from tests.conftest import DISPATCH_EXE, ROOT, write_scenario
from tests.dispatch.test_determinism import assert_same_content, without_timing

SMALL = {"allocator": ["hungarian", "greedy", "random"], "agents": [2, 3], "seed": [0, 1]}


def parquet_files(out: Path) -> dict[str, Path]:
    return {str(p.relative_to(out)): p for p in sorted(out.rglob("*.parquet"))}


def assert_same_outputs(a: Path, b: Path) -> None:
    """Every Parquet file of ``a`` is in ``b`` with the same content (timing columns aside)."""
    fa, fb = parquet_files(a), parquet_files(b)
    assert sorted(fa) == sorted(fb)
    for rel in fa:
        assert_same_content(without_timing(pq.read_table(fa[rel])),
                            without_timing(pq.read_table(fb[rel])), rel)


def markers(out: Path) -> dict[str, int]:
    return {str(p.relative_to(out)): p.stat().st_mtime_ns
            for p in (out / MARKERS).rglob("done.json")} if (out / MARKERS).exists() else {}


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    scenario = write_scenario(d, sweep=SMALL, tasks={"count": 3, "service_time": 0.5})
    specs = load_scenario(scenario).runs()
    assert len(specs) == 12
    serial = d / "serial"
    outcomes = sweep(specs, serial, workers=1)
    assert [o.status for o in outcomes] == ["done"] * 12
    return scenario, specs, serial


def test_sweep_layout_matches_dispatch_run(small, tmp_path):
    """A sweep writes exactly what ``dispatch run`` writes, markers included: a sweep over the
    output of ``dispatch run`` has nothing left to do."""
    _, specs, serial = small
    execute(specs, tmp_path / "run")
    assert_same_outputs(tmp_path / "run", serial)
    assert sorted(markers(tmp_path / "run")) == sorted(markers(serial))
    assert [o.status for o in sweep(specs, tmp_path / "run", workers=1)] == ["skipped"] * 12
    assert len(markers(serial)) == 12
    assert all(is_complete(serial, s) for s in specs)
    marker = json.loads(marker_path(serial, specs[0]).read_text())
    assert marker["run_id"] == specs[0].run_id
    assert sorted(marker["files"]) == sorted(
        f"{t}/scenario=tiny/allocator=hungarian/planner=astar/n_agents=2/seed=0/part-0.parquet" for t in SCHEMAS)
    # readers that know nothing about markers see only the tables
    for name in SCHEMAS:
        assert ds.dataset(serial / name, partitioning="hive").count_rows() >= 0
        assert len(ds.dataset(serial / name, partitioning="hive").files) == 12


def test_process_pool_gives_identical_results(small, tmp_path):
    _, specs, serial = small
    seen = []
    outcomes = sweep(specs, tmp_path / "pool", workers=2, on_done=seen.append)
    assert [o.status for o in outcomes] == ["done"] * 12
    assert sorted(o.run_id for o in seen) == sorted(s.run_id for s in specs)
    assert [o.run_id for o in outcomes] == [s.run_id for s in specs]  # in the order of specs
    assert_same_outputs(serial, tmp_path / "pool")


def test_local_ray_gives_identical_results(small, tmp_path):
    ray = pytest.importorskip("ray", reason="needs ray (the test extra: bash scripts/setup.sh)")
    _, specs, serial = small
    assert not ray.is_initialized()
    outcomes = sweep(specs, tmp_path / "ray", workers=2, ray=True)
    assert [o.status for o in outcomes] == ["done"] * 12
    assert not ray.is_initialized()  # the local Ray it started is shut down again
    assert_same_outputs(serial, tmp_path / "ray")


def test_rerun_skips_complete_runs_and_redoes_damaged_ones(small, tmp_path):
    import shutil

    _, specs, serial = small
    out = tmp_path / "out"
    shutil.copytree(serial, out)
    before = markers(out)
    # a run killed between its tables and its marker; a run whose file was deleted since;
    # a run killed while writing (a temporary file, no marker, one table missing)
    marker_path(out, specs[0]).unlink()
    (out / "events" / "scenario=tiny/allocator=hungarian/planner=astar/n_agents=3/seed=0/part-0.parquet").unlink()
    leaf = out / "tasks" / "scenario=tiny/allocator=random/planner=astar/n_agents=3/seed=1"
    (leaf / "part-0.parquet").unlink()
    (leaf / ".part-0.parquet.tmp-123").write_bytes(b"half")
    marker_path(out, specs[-1]).unlink()
    outcomes = sweep(specs, out, workers=1)
    redone = {o.run_id for o in outcomes if o.status == "done"}
    assert redone == {specs[0].run_id, "tiny__hungarian__astar__n3__s0", specs[-1].run_id}
    assert sum(o.status == "skipped" for o in outcomes) == 9
    after = markers(out)
    assert len(after) == 12
    untouched = set(before) - {str(marker_path(out, s).relative_to(out)) for s in specs
                               if s.run_id in redone}
    assert all(after[m] == before[m] for m in untouched)  # finished runs were not redone
    assert not (leaf / ".part-0.parquet.tmp-123").exists()
    assert_same_outputs(serial, out)
    # skipped runs still report their summary
    assert all(o.summary["run_id"] == o.run_id for o in outcomes)


def test_interrupted_sweep_resumes(small, tmp_path):
    """Stopped after three runs (as by Ctrl-C), the next sweep runs only the other nine."""
    _, specs, serial = small
    out = tmp_path / "out"

    def stop_after_three(outcome, seen=[]):  # noqa: B006 - a counter for this test
        seen.append(outcome)
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweep(specs, out, workers=1, on_done=stop_after_three)
    first = markers(out)
    assert len(first) == 3
    outcomes = sweep(specs, out, workers=2)
    assert [o.status for o in outcomes].count("skipped") == 3
    assert [o.status for o in outcomes].count("done") == 9
    assert {m: t for m, t in markers(out).items() if m in first} == first
    assert_same_outputs(serial, out)


def test_changed_scenario_or_force_redoes_everything(small, tmp_path):
    scenario, specs, _ = small
    out = tmp_path / "out"
    sweep(specs[:2], out, workers=1)
    assert [o.status for o in sweep(specs[:2], out, workers=1)] == ["skipped"] * 2
    assert [o.status for o in sweep(specs[:2], out, workers=1, overwrite=True)] == ["done"] * 2
    changed = scenario.with_name("changed.toml")
    changed.write_text(scenario.read_text().replace("duration = 300.0", "duration = 200.0"))
    specs2 = load_scenario(changed).runs()[:2]
    assert [o.status for o in sweep(specs2, out, workers=1)] == ["done"] * 2
    assert foreign_runs(out, specs2) == []
    assert sorted(foreign_runs(out, specs)) == sorted(s.run_id for s in specs2)


def test_failing_run_is_recorded_and_retried(small, tmp_path, monkeypatch):
    from dispatch.run import runner
    _, specs, serial = small
    out = tmp_path / "out"
    real = runner.run_one
    bad = specs[4].run_id

    def flaky(spec, *args, **kwargs):
        if spec.run_id == bad:
            raise RuntimeError("boom in the planner")
        return real(spec, *args, **kwargs)

    monkeypatch.setattr(runner, "run_one", flaky)
    outcomes = sweep(specs, out, workers=1)
    assert [o.status for o in outcomes].count("done") == 11
    failed = [o for o in outcomes if o.status == "failed"]
    assert [o.run_id for o in failed] == [bad]
    assert failed[0].error == "RuntimeError: boom in the planner"
    errors = ds.dataset(out / ERRORS, partitioning="hive").to_table().to_pylist()
    assert len(errors) == 1
    e = errors[0]
    assert (e["run_id"], e["error_type"], e["message"]) == (bad, "RuntimeError",
                                                            "boom in the planner")
    assert "Traceback" in e["traceback"] and e["allocator"] == specs[4].allocator
    assert not is_complete(out, specs[4])
    leaf = partition_dir(specs[4])
    for name in SCHEMAS:  # nothing half-written of the failed run
        assert not (out / name / leaf / "part-0.parquet").exists(), name

    monkeypatch.setattr(runner, "run_one", real)
    again = sweep(specs, out, workers=1)
    assert [o.run_id for o in again if o.status == "done"] == [bad]
    assert not list((out / ERRORS).rglob("*.parquet"))  # its error is gone once it succeeded
    assert_same_outputs(serial, out)


def _sweep_cli(*args, **kw) -> subprocess.Popen:
    cmd = [str(DISPATCH_EXE)] if DISPATCH_EXE.exists() else [os.sys.executable, "-m",
                                                             "dispatch.run.cli"]
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
    return subprocess.Popen([*cmd, "sweep", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env, **kw)


def test_cli_sweep_killed_then_resumed(tmp_path):
    """``dispatch sweep`` killed with SIGKILL mid-way; the rerun does only what is missing."""
    scenario = write_scenario(
        tmp_path, world={"size": [40, 40, 8]}, obstacles={"count": 6, "max_size": [6, 6, 8]},
        fleet={"agents": 10}, tasks={"ground_fraction": 1.0},
        sweep={"allocator": ["hungarian", "greedy", "random"], "seed": [0, 1, 2, 3]})
    out = tmp_path / "out"
    proc = _sweep_cli(scenario, "--out", out, "--workers", "1")
    deadline = time.monotonic() + 60
    while len(markers(out)) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    finished = markers(out)
    assert 3 <= len(finished) < 12, "the sweep finished before it could be killed"
    proc = _sweep_cli(scenario, "--out", out, "--workers", "2")
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    assert f"{12 - len(finished)} run, {len(finished)} already complete, 0 failed" in stdout
    assert "Table I" in stdout
    final = markers(out)
    assert len(final) == 12
    assert {m: final[m] for m in finished} == finished
    for name in SCHEMAS:
        assert len(ds.dataset(out / name, partitioning="hive").files) == 12
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary files left


def test_cli_sweep_bad_plugin_parameters_stop_before_any_run(make_scenario, tmp_path, cli):
    """A parameter the planner rejects is found when the sweep is checked (each distinct
    plugin is built once), not once per run: one line, exit 2, nothing written."""
    path = make_scenario(sweep={"allocator": ["hungarian", "greedy"], "seed": [0, 1]},
                         extra="[dispatch.planner_params]\nno_such_parameter = 1\n")
    out = tmp_path / "out"
    proc = cli("sweep", path, "--out", out, "--workers", "2")
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "dispatch.planner_params.no_such_parameter: planner 'astar' takes no parameter" \
        in proc.stderr
    assert not out.exists()


def test_cli_sweep_failures_exit_1_and_the_others_go_on(make_scenario, tmp_path, monkeypatch,
                                                         capsys):
    from dispatch.run import cli as cli_module
    from dispatch.run import runner
    path = make_scenario(sweep={"allocator": ["hungarian", "greedy"], "seed": [0, 1]})
    out = tmp_path / "out"
    real = runner.run_one

    def flaky(spec, *args, **kwargs):
        if spec.allocator == "greedy":
            raise RuntimeError("boom in the run")
        return real(spec, *args, **kwargs)

    monkeypatch.setattr(runner, "run_one", flaky)
    assert cli_module.main(["sweep", str(path), "--out", str(out), "--workers", "1"]) == 1
    stdout = " ".join(capsys.readouterr().out.split())
    assert "Traceback" not in stdout
    assert "2 run, 0 already complete, 2 failed" in stdout
    assert stdout.count("failed: tiny__greedy") == 2
    errors = ds.dataset(out / "errors", partitioning="hive").to_table().to_pylist()
    assert len(errors) == 2
    assert {e["error_type"] for e in errors} == {"RuntimeError"}
    assert {e["scenario"] for e in errors} == {"tiny"}  # from the partition path


def test_cli_sweep_bad_arguments(tiny_scenario, cli, tmp_path):
    proc = cli("sweep", tiny_scenario, "--workers", "0", "--out", tmp_path / "x")
    assert proc.returncode == 2 and "--workers" in proc.stderr
    proc = cli("sweep", tiny_scenario, "--allocator", "nosuch", "--out", tmp_path / "x")
    assert proc.returncode == 2 and "nosuch" in proc.stderr
    assert not (tmp_path / "x").exists()


def _pool_sweep_with_workers(tmp_path):
    """A ``dispatch sweep`` on 2 worker processes, returned once both workers are up (the
    parent and its spawned children, as psutil processes)."""
    psutil = pytest.importorskip("psutil", reason="needs psutil (comes with ray: the test extra)")
    scenario = write_scenario(
        tmp_path, world={"size": [40, 40, 8]}, obstacles={"count": 6, "max_size": [6, 6, 8]},
        fleet={"agents": 10}, tasks={"ground_fraction": 1.0},
        sweep={"allocator": ["hungarian", "greedy", "random"], "seed": list(range(40))})
    proc = _sweep_cli(scenario, "--out", tmp_path / "out", "--workers", "2")
    parent = psutil.Process(proc.pid)
    deadline = time.monotonic() + 120
    workers = []
    while time.monotonic() < deadline and proc.poll() is None:
        workers = [c for c in parent.children(recursive=True)
                   if "spawn_main" in " ".join(c.cmdline())]
        if len(workers) >= 2 and len(markers(tmp_path / "out")) >= 1:
            break
        time.sleep(0.05)
    assert proc.poll() is None and len(workers) >= 2, "the pool never ran two workers"
    return proc, parent, parent.children(recursive=True), psutil


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_cli_sweep_terminated_stops_its_workers(tmp_path, sig):
    """SIGTERM (or Ctrl-C's SIGINT) to a pool sweep ends it and its worker processes: none
    is left running (writing the partitions of its run) after the sweep has exited."""
    proc, _parent, children, psutil = _pool_sweep_with_workers(tmp_path)
    proc.send_signal(sig)
    proc.communicate(timeout=60)
    assert proc.returncode != 0
    if sig == signal.SIGTERM:
        assert proc.returncode == 128 + signal.SIGTERM
    _gone, alive = psutil.wait_procs(children, timeout=10)
    assert alive == [], f"processes left running: {[p.pid for p in alive]}"


def test_pool_workers_exit_when_the_sweep_is_killed(tmp_path):
    """Even SIGKILL, which runs no cleanup in the sweep, leaves no worker behind: each worker
    ends itself once its parent is gone."""
    proc, _parent, children, psutil = _pool_sweep_with_workers(tmp_path)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    _gone, alive = psutil.wait_procs(children, timeout=15)
    assert alive == [], f"processes left running: {[p.pid for p in alive]}"


def test_changed_sweep_lists_resume_the_same_runs(tmp_path):
    """A sweep rerun with other [sweep] lists (and other comments) skips the runs it shares
    with the first one and runs only the new ones; runs of values dropped since stay and are
    not counted as another scenario's; a change outside [sweep] still redoes everything."""
    from dispatch.run.resume import run_digest

    first = write_scenario(tmp_path, "a.toml", sweep={"allocator": ["hungarian"], "seed": [0]})
    out = tmp_path / "out"
    specs_a = load_scenario(first).runs()
    assert [o.status for o in sweep(specs_a, out, workers=1)] == ["done"]
    second = tmp_path / "b.toml"
    second.write_text("# the same study, more allocators\n" + first.read_text().replace(
        'allocator = ["hungarian"]', 'allocator = ["greedy", "hungarian"]  # two now'))
    specs_b = load_scenario(second).runs()
    assert run_digest(specs_b[1]) == run_digest(specs_a[0])
    assert run_digest(specs_b[0]) != run_digest(specs_a[0])
    before = markers(out)
    outcomes = sweep(specs_b, out, workers=1)
    assert [(o.run_id, o.status) for o in outcomes] == [
        ("tiny__greedy__astar__n3__s0", "done"), ("tiny__hungarian__astar__n3__s0", "skipped")]
    assert {m: t for m, t in markers(out).items() if m in before} == before  # not redone
    assert foreign_runs(out, specs_b) == []
    assert foreign_runs(out, specs_a) == []  # greedy: the same scenario, not a foreign one
    changed = tmp_path / "c.toml"
    changed.write_text(second.read_text().replace("duration = 300.0", "duration = 200.0"))
    specs_c = load_scenario(changed).runs()
    assert sorted(foreign_runs(out, specs_c)) == sorted(s.run_id for s in specs_b)
    assert [o.status for o in sweep(specs_c, out, workers=1)] == ["done", "done"]


def test_markers_without_run_digest_resume_from_the_runs_own_text(tmp_path):
    """Markers written before run digests (scenario_sha256 only) of another text of the same
    runs: the run's own scenario text (in its Parquet metadata) decides."""
    first = write_scenario(tmp_path, "a.toml", sweep={"allocator": ["hungarian"], "seed": [0]})
    out = tmp_path / "out"
    spec = load_scenario(first).runs()[0]
    sweep([spec], out, workers=1)
    path = marker_path(out, spec)
    old = json.loads(path.read_text())
    for k in ("run_sha256", "base_sha256"):
        del old[k]
    path.write_text(json.dumps(old))
    second = tmp_path / "b.toml"
    second.write_text(first.read_text().replace('seed = [0]', 'seed = [0, 1]'))
    specs = load_scenario(second).runs()
    assert [o.status for o in sweep(specs, out, workers=1)] == ["skipped", "done"]
    assert foreign_runs(out, specs) == []
    third = tmp_path / "c.toml"
    third.write_text(second.read_text().replace("duration = 300.0", "duration = 200.0"))
    assert not is_complete(out, load_scenario(third).runs()[0])
