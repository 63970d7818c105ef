"""``dispatch new allocator NAME`` writes a whole plugin package that pip installs and that
passes ``dispatch check NAME``, its own tests and a run beside a built-in."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.conftest import ROOT, write_scenario


def _env(*paths):
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
    env["PYTHONPATH"] = os.pathsep.join(str(p) for p in (ROOT, *paths,
                                                         os.environ.get("PYTHONPATH")) if p)
    return env


def _dispatch(*args, env):
    return subprocess.run([sys.executable, "-m", "dispatch.run.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)


def test_new_allocator_installs_and_passes_check(tmp_path):
    env = _env()
    proc = _dispatch("new", "allocator", "cheapest_first", "--out", tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    root = tmp_path / "dispatch-cheapest-first"
    assert {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()} == {
        "pyproject.toml", "README.md", "dispatch_cheapest_first/__init__.py",
        "dispatch_cheapest_first/allocator.py", "tests/test_cheapest_first.py"}
    site = tmp_path / "site"  # pip installs it there (not into the shared environment)
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps",
                          "--no-build-isolation", "--no-index", "--target", str(site), str(root)],
                         capture_output=True, text=True, timeout=300)
    assert pip.returncode == 0, pip.stdout + pip.stderr
    env = _env(site)
    proc = _dispatch("check", "cheapest_first", env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "passes every check" in proc.stdout
    proc = _dispatch("plugins", env=env)
    assert "cheapest_first" in proc.stdout and "Cheapest feasible pair first" in proc.stdout
    tests = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                            str(root / "tests")], capture_output=True, text=True, env=env,
                           timeout=300, cwd=root)
    assert tests.returncode == 0, tests.stdout + tests.stderr
    path = write_scenario(tmp_path, sweep={"allocator": ["hungarian", "cheapest_first"]},
                          extra="[dispatch.allocator_params.cheapest_first]\nmax_pairs = 2\n")
    proc = _dispatch("run", path, "--out", tmp_path / "out", env=env)
    assert proc.returncode == 0, proc.stderr
    assert "cheapest_first" in proc.stdout


def test_new_refuses_bad_names_and_existing_folders(tmp_path):
    env = _env()
    for bad in ("Bad", "1x", "a-b", "hungarian"):
        proc = _dispatch("new", "allocator", bad, "--out", tmp_path, env=env)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, bad
    assert _dispatch("new", "allocator", "mine", "--out", tmp_path, env=env).returncode == 0
    proc = _dispatch("new", "allocator", "mine", "--out", tmp_path, env=env)
    assert proc.returncode == 2 and "exists" in proc.stderr
    assert _dispatch("new", "allocator", "mine", "--out", tmp_path, "--overwrite",
                     env=env).returncode == 0
