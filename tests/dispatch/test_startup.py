"""A process that runs a small road scenario imports only what the run uses: neither torch nor
pandas nor the other heavy packages of the optional extras, no plugin module the run does not
name, no numba (its compiled searches run as plain Python while the process is young:
:mod:`dispatch._compiled`) and no scipy graph module (a grid is strongly connected without it).
Which modules a process ends with is checked, not how long it takes
(``benchmarks/startup.py`` times it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.conftest import ROOT

#: runs the command line in this process, then prints the top-level packages it ended with
WRAPPER = """
import json, sys
from dispatch.run.cli import main
rc = main(sys.argv[1:])
print("MODULES " + json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
print("ALL " + json.dumps(sorted(sys.modules)))
print("PLUGINS " + json.dumps(sorted(m for m in sys.modules
                                     if m.startswith(("allocators.", "planners.")))))
sys.exit(rc)
"""
#: packages a small road run must not import (the extras' heavy ones, and numba)
HEAVY = ("torch", "pandas", "torch_geometric", "ray", "matplotlib", "pybullet", "numba")


def run_in_process(tmp_path, *args) -> tuple[str, dict]:
    """``dispatch run`` of the shipped Manhattan scenario's first 100 s (10 requests, ``fcfs``,
    ``dijkstra``) into ``tmp_path/out``: its printed lines and the module lists."""
    proc = subprocess.run(
        [sys.executable, "-c", WRAPPER, "run", str(ROOT / "scenarios" / "manhattan.toml"),
         "--allocator", "fcfs", "--duration", "100", "--out", str(tmp_path / "out"), *args],
        check=False, capture_output=True, text=True, cwd=tmp_path, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "200"})
    assert proc.returncode == 0, proc.stderr
    lines = dict(line.split(" ", 1) for line in proc.stdout.splitlines()
                 if line.startswith(("MODULES ", "ALL ", "PLUGINS ")))
    return proc.stdout, {k: json.loads(v) for k, v in lines.items()}


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    """A first run into a new folder, then the same command again (shown from the folder)."""
    tmp = tmp_path_factory.mktemp("startup")
    return run_in_process(tmp), run_in_process(tmp)


def test_a_small_road_run_imports_nothing_heavy(first):
    """The run finishes, and none of :data:`HEAVY`, no scipy graph module (nor the linear
    algebra it brings) and no allocator or planner the run does not name are loaded."""
    (out, mods), _ = first
    assert "10 released" in out
    assert [p for p in HEAVY if p in mods["MODULES"]] == []
    assert [m for m in mods["ALL"] if m.startswith(("scipy.sparse.csgraph",
                                                    "scipy.sparse.linalg"))] == []
    assert [m for m in mods["PLUGINS"] if m.partition(".")[2].split(".")[0] not in
            ("fcfs", "road", "_road_fast")] == []


def test_a_run_shown_from_its_folder_imports_nothing_heavy(first):
    """Asked again, the run is shown from the folder (its stored summary), still without
    pandas (which reading Parquet through ``pyarrow.dataset`` would import)."""
    _, (out, mods) = first
    assert "already in" in out and "not run again" in out
    assert [p for p in HEAVY if p in mods["MODULES"]] == []
    assert "pyarrow.dataset" not in mods["ALL"]
