"""benchmarks/startup.py: the run it times is the 10-request road run, and one measured pair
comes back as the figures it prints."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("startup", ROOT / "benchmarks" / "startup.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_timed_run_is_ten_requests_of_the_shipped_grid(bench, tmp_path):
    """The command it times, run once: the Manhattan scenario's first 100 s, 10 requests, into
    the folder it names."""
    command = bench.run_command(tmp_path / "out")
    assert command[-9:] == ["run", str(ROOT / "scenarios" / "manhattan.toml"), "--allocator",
                            "fcfs", "--duration", "100", "--out", str(tmp_path / "out"),
                            "--overwrite"]
    proc = subprocess.run(command, check=False, capture_output=True, text=True,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT),
                               "COLUMNS": "200"})
    assert proc.returncode == 0, proc.stderr
    assert "10 released" in proc.stdout


def test_one_pair_prints_both_processes_and_the_ratios():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "startup.py"), "--pairs",
                           "1"], check=False, capture_output=True, text=True, cwd=ROOT,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT),
                               "COLUMNS": "200"}, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "dispatch run (whole process)" in proc.stdout
    assert "import numpy, scipy.sparse, pyarrow, simpy" in proc.stdout
    assert "run / yardstick, median of the pairs:" in proc.stdout
