"""A process that runs a small road scenario imports only what the run uses (issue 39's start-up
step): neither torch nor pandas, and no plugin module the run does not name. Which modules a
process ends with is checked, not how long it takes."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from tests.conftest import ROOT

#: runs the command line in this process, then prints the top-level packages it ended with
WRAPPER = """
import json, sys
from dispatch.run.cli import main
rc = main(sys.argv[1:])
print("MODULES " + json.dumps(sorted({m.split(".")[0] for m in sys.modules})))
print("PLUGINS " + json.dumps(sorted(m for m in sys.modules
                                     if m.startswith(("allocators.", "planners.")))))
sys.exit(rc)
"""


def test_a_small_road_run_imports_neither_torch_nor_pandas(tmp_path):
    """``dispatch run`` of the shipped Manhattan scenario, 10 requests (``fcfs``, ``dijkstra``):
    the run finishes, and torch, pandas and the other allocators and planners stay unloaded."""
    proc = subprocess.run(
        [sys.executable, "-c", WRAPPER, "run", str(ROOT / "scenarios" / "manhattan.toml"),
         "--allocator", "fcfs", "--duration", "100", "--out", str(tmp_path / "out")],
        capture_output=True, text=True, cwd=tmp_path, timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "200"})
    assert proc.returncode == 0, proc.stderr
    assert "10 released" in proc.stdout
    lines = dict(line.split(" ", 1) for line in proc.stdout.splitlines()
                 if line.startswith(("MODULES ", "PLUGINS ")))
    modules, plugins = json.loads(lines["MODULES"]), json.loads(lines["PLUGINS"])
    assert "torch" not in modules and "pandas" not in modules
    assert [m for m in plugins if m.partition(".")[2].split(".")[0] not in
            ("fcfs", "road", "_road_fast")] == []
