"""A sweep killed (SIGKILL) at random moments leaves every file it has written readable, and
resumed it ends with the same results as a sweep never interrupted (wall-clock columns aside).

The sweep runs in a subprocess with small chunks (its recorders write a chunk file every 100
rows instead of 10 000), so that the kills also land while chunks, final files and completion
markers are being written. The kill moments are drawn from a seeded generator over the
length of an uninterrupted sweep."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from soak.invariants import same_tables
from tests.conftest import ROOT

SCENARIO = f"""name = "kill_sweep"
seed = 0
duration = 2400.0
[world]
network = "manhattan"
blocks = [20, 20]
block = 200.0
speed = 10.0
[fleet]
agents = 30
[tasks]
source = "trace"
trace = "{ROOT / 'scenarios' / 'data' / 'manhattan_trips.csv'}"
max_wait = 600.0
[dispatch]
planner = "dijkstra"
[sweep]
allocator = ["fcfs", "hungarian"]
seed = [0, 1]
"""
#: the sweep, its recorders flushing a chunk every 100 rows; "ready" once it is imported
DRIVER = (
    "import sys\n"
    "import dispatch.run.runner as r\n"
    "made = r.make_recorder\n"
    "r.make_recorder = lambda spec, out, **kw: made(spec, out, flush_rows=100)\n"
    "from dispatch.run.cli import main\n"
    "import dispatch.run.sim\n"
    "print('ready', flush=True)\n"
    "sys.exit(main(['sweep', sys.argv[1], '--out', sys.argv[2], '--workers', '1']))\n")
KILLS = 4
TEMP = ".tmp-"  # a writer's temporary name (``.<name>.tmp-<pid>``), renamed into place


def _sweep(scenario: Path, out: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, str(scenario), str(out)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout.readline() == b"ready\n"  # imported: the sweep starts now
    return proc


def _files(out: Path) -> list[Path]:
    return sorted(p for p in out.rglob("*") if p.is_file())


def _all_readable(out: Path) -> int:
    """Every file the sweep has written (its temporary names aside) opens: Parquet files and
    chunks as tables, JSON as JSON. Returns how many were read."""
    n = 0
    for p in _files(out):
        if TEMP in p.name:
            continue
        if p.name.endswith((".parquet", ".parquet.chunk")):
            pq.read_table(p)
        elif p.suffix == ".json":
            json.loads(p.read_text(encoding="utf-8"))
        else:
            raise AssertionError(f"unexpected file {p.relative_to(out)}")
        n += 1
    return n


def _results(out: Path) -> dict[str, object]:
    """The results folder: each table file (relative path -> its table) and each completion
    marker without its wall-clock figures (the run's ``seconds``; its files' sizes, which the
    wall-clock columns change: the files it names are kept)."""
    got: dict[str, object] = {}
    for p in _files(out):
        rel = str(p.relative_to(out))
        if p.suffix == ".json":
            marker = json.loads(p.read_text())
            marker.pop("seconds")
            marker["files"] = sorted(marker["files"])
            got[rel] = marker
        else:
            got[rel] = pq.read_table(p).to_pandas()
    return got


def test_killed_sweep_stays_readable_and_resumes_to_the_same_results(tmp_path):
    scenario = tmp_path / "kill_sweep.toml"
    scenario.write_text(SCENARIO)
    whole = tmp_path / "whole"
    proc = _sweep(scenario, whole)
    start = time.monotonic()
    assert proc.wait(timeout=200) == 0, proc.stderr.read().decode()
    length = time.monotonic() - start  # (the sweep itself, its imports aside)

    cut = tmp_path / "cut"
    rng = np.random.default_rng(20261206)
    moments = np.sort(rng.uniform(0.0, length, KILLS))
    killed = 0
    for moment in moments:
        proc = _sweep(scenario, cut)
        try:
            proc.wait(timeout=float(moment))
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            killed += 1
        if cut.exists():
            _all_readable(cut)
    assert killed >= 1  # (a kill that came after the sweep ended checks the same)
    proc = _sweep(scenario, cut)
    assert proc.wait(timeout=200) == 0, proc.stderr.read().decode()

    a, b = _results(whole), _results(cut)
    assert sorted(a) == sorted(b)  # the same files, and no temporary one left behind
    assert not [k for k in b if TEMP in k]
    for rel in a:
        if rel.endswith(".json"):
            assert a[rel] == b[rel], rel
        else:
            assert same_tables({rel: a[rel]}, {rel: b[rel]}) == [], rel


def test_soak_resumed_after_a_cut_line_keeps_one_whole_line_a_run(tmp_path, monkeypatch):
    """``dispatch soak``'s ``results.jsonl``: a line cut by a kill is dropped on resume (the
    file rewritten without it, so the next line appended starts on its own line) and that run
    runs again; every line parses and each run has one."""
    from soak import sweep
    from soak.runner import Outcome

    ran: list[str] = []

    def fake(case, folder, **kw) -> Outcome:  # (the file's handling is tested, not the runs)
        ran.append(folder.name)
        return Outcome("ok", seconds=0.5)

    monkeypatch.setattr(sweep, "run_case", fake)
    sweep.soak(4, 9, tmp_path, twice_every=0)
    lines = (tmp_path / "results.jsonl").read_text().splitlines()
    assert len(lines) == 4 and ran == ["9_0", "9_1", "9_2", "9_3"]
    # killed while writing the third line: the fourth never came
    (tmp_path / "results.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:17])
    ran.clear()
    tally = sweep.soak(4, 9, tmp_path, twice_every=0)
    assert ran == ["9_2", "9_3"] and tally.runs == 4 and tally.status["ok"] == 4
    again = (tmp_path / "results.jsonl").read_text()
    assert again.endswith("\n")
    rows = [json.loads(line) for line in again.splitlines()]
    assert [r["run"] for r in rows] == ["9_0", "9_1", "9_2", "9_3"]
    assert rows == [json.loads(line) for line in lines]
    assert not [p for p in tmp_path.iterdir() if TEMP in p.name]
