"""A small road run as a user waits for it: the whole ``dispatch run`` process against the
import of the libraries any such run needs, timed in turn in one call.

The run: the shipped Manhattan scenario's first 100 simulated seconds (10 requests, 50 taxis,
``fcfs``, ``dijkstra``) into a fresh folder (``--overwrite``), by the installed ``dispatch``
command where there is one beside this Python (else ``python -m dispatch.run.cli``), with this
checkout first on ``PYTHONPATH``. The yardstick: ``python -c "import numpy, scipy.sparse,
pyarrow, simpy"``. After one unmeasured run of each (which also writes the bytecode caches a
user's later runs read), ``--pairs`` pairs run in turn (run, yardstick, run, ...); printed are
each command's median wall and CPU seconds (user + system, from the operating system's
accounting of the finished child) and the medians of the pairs' ratios, run over yardstick:
the figure to quote (a loaded machine slows both alike). Usage:
``.venv/bin/python benchmarks/startup.py [--pairs 7]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
YARDSTICK = [sys.executable, "-c", "import numpy, scipy.sparse, pyarrow, simpy"]


def run_command(out: Path) -> list[str]:
    """The ``dispatch run`` command line of the small road run, writing into ``out``."""
    script = Path(sys.executable).parent / "dispatch"
    head = [str(script)] if script.exists() else [sys.executable, "-m", "dispatch.run.cli"]
    return head + ["run", str(ROOT / "scenarios" / "manhattan.toml"), "--allocator", "fcfs",
                   "--duration", "100", "--out", str(out), "--overwrite"]


def timed(command: list[str], env: dict) -> tuple[float, float]:
    """``(wall, cpu)`` seconds of one run of ``command`` as a child process (its output
    discarded); RuntimeError where it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    proc = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True, env=env, check=False)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(command)} failed: {proc.stderr.strip()[-500:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def measure(pairs: int) -> dict[str, list[tuple[float, float]]]:
    """``{"run": [(wall, cpu), ...], "yardstick": [...]}``, ``pairs`` each, in turn, after one
    unmeasured run of each."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # a user's later runs read the bytecode caches
    with tempfile.TemporaryDirectory() as tmp:
        commands = {"run": run_command(Path(tmp) / "out"), "yardstick": YARDSTICK}
        for command in commands.values():
            timed(command, env)
        got: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
        for _ in range(pairs):
            for name, command in commands.items():
                got[name].append(timed(command, env))
    return got


def main(argv: list[str] | None = None) -> None:
    from rich.console import Console
    from rich.table import Table

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=7, help="measured pairs (default 7)")
    args = p.parse_args(argv)
    got = measure(args.pairs)
    table = Table(title=f"A 10-request road run against the yardstick import, {args.pairs} "
                        "pairs in turn (medians)")
    for col in ("process", "wall s", "CPU s"):
        table.add_column(col, justify="left" if col == "process" else "right")
    for name, label in (("run", "dispatch run (whole process)"),
                        ("yardstick", 'python -c "import numpy, scipy.sparse, pyarrow, simpy"')):
        table.add_row(label, f"{statistics.median(w for w, _ in got[name]):.3f}",
                      f"{statistics.median(c for _, c in got[name]):.3f}")
    console = Console()
    console.print(table)
    pairs = list(zip(got["run"], got["yardstick"], strict=True))
    wall = statistics.median(a[0] / b[0] for a, b in pairs)
    cpu = statistics.median(a[1] / b[1] for a, b in pairs)
    console.print(f"run / yardstick, median of the pairs: {wall:.2f}x wall, {cpu:.2f}x CPU "
                  f"(load average {os.getloadavg()[0]:.1f})", highlight=False)


if __name__ == "__main__":
    main()
