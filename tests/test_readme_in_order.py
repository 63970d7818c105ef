"""The README, followed in order: every command line of its ``bash`` blocks and every ``python``
snippet runs, one after the other, in a copy of the repository (its tracked files), and exits 0.

The run is marked ``readme`` and left out of the default test command (the lines take minutes:
runs of the paper's scenario, Manhattan hours, a report, a replay, a quick bench); CI runs it
once, after the suite (``.ci/run``: ``bash scripts/test.sh -m readme``). Nothing is shortened:
a line runs as written, with ``dispatch`` the command line of this checkout and ``python`` this
interpreter. The only lines not run are those of :data:`NOT_RUN`, each with its reason, and the
test fails when the README gains or loses one of them, so none is left out silently.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT

#: README lines not run here, and why (each must still be in the README)
NOT_RUN = {
    "bash scripts/test.sh": "the test suite itself, of which this test is a part",
    "bash scripts/docs.sh": "CI builds the docs in its own step after the tests (.ci/run)",
}
#: README lines that set up the environment, replaced by what they run once it exists
SET_UP = {"bash scripts/paper.sh": "scripts/paper.sh"}
#: wall seconds one line may take before the test fails (the longest, the quick bench, takes
#: minutes on 2 shared cores)
LINE_TIMEOUT = 1800


def readme_steps(text: str) -> list[tuple[str, str]]:
    """The README's steps in order: ``("bash", line)`` for each command line of a ``bash``
    block (comment-only and empty lines left out), ``("python", code)`` for each ``python``
    block; other blocks (``text``, output) are not steps."""
    steps = []
    for lang, body in re.findall(r"^```(\w+)\n(.*?)^```", text, flags=re.M | re.S):
        if lang == "python":
            steps.append(("python", body))
        elif lang == "bash":
            for line in body.splitlines():
                if line.strip() and not line.lstrip().startswith("#"):
                    steps.append(("bash", line.strip()))
    return steps


def _command(line: str) -> str:
    """The line without its trailing comment (``# ...`` after two spaces)."""
    return re.split(r"\s+#\s", line, maxsplit=1)[0].strip()


def _script_command(script: Path) -> str:
    """What a set-up script runs once the environment exists: its ``exec .venv/bin/X`` line,
    as the command ``X ...`` (with ``"$@"`` dropped)."""
    [line] = [x for x in script.read_text(encoding="utf-8").splitlines()
              if x.startswith("exec .venv/bin/")]
    return line.removeprefix("exec .venv/bin/").replace(' "$@"', "")


def test_readme_steps_are_found():
    """The parser finds the README's lines (a check on the test itself): the set-up line first,
    the skipped lines present, a python snippet among them."""
    steps = readme_steps((ROOT / "README.md").read_text(encoding="utf-8"))
    lines = [_command(s) for kind, s in steps if kind == "bash"]
    assert lines[0] == "bash scripts/paper.sh"
    assert set(NOT_RUN) <= set(lines), set(NOT_RUN) - set(lines)
    assert any(kind == "python" for kind, _ in steps)
    assert _script_command(ROOT / "scripts/paper.sh") == \
        "dispatch run scenarios/paper_static.toml --overwrite"


def _copy_repo(dest: Path) -> None:
    """The repository's tracked files (a fresh clone's), from git; else the whole tree
    without its outputs."""
    try:
        files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                               check=True).stdout.decode().split("\0")
    except (OSError, subprocess.CalledProcessError):
        shutil.copytree(ROOT, dest, ignore=shutil.ignore_patterns(
            ".git", ".venv", "runs", "bench_out", "docs/_build", "__pycache__"))
        return
    for rel in filter(None, files):
        src = ROOT / rel
        if src.is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / rel)


@pytest.mark.readme
def test_readme_runs_in_order(tmp_path):
    repo = tmp_path / "repo"
    _copy_repo(repo)
    bin_dir = tmp_path / "bin"  # `dispatch` and `python`: this checkout, this interpreter
    bin_dir.mkdir()
    for name, target in (("dispatch", f'"{sys.executable}" -m dispatch.run.cli'),
                         ("python", f'"{sys.executable}"')):
        shim = bin_dir / name
        shim.write_text(f'#!/bin/sh\nexec {target} "$@"\n', encoding="utf-8")
        shim.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONPATH": str(repo), "COLUMNS": "80", "MPLBACKEND": "Agg"}
    steps = readme_steps((repo / "README.md").read_text(encoding="utf-8"))
    done, skipped = [], []
    for kind, step in steps:
        if kind == "bash" and _command(step) in NOT_RUN:
            skipped.append(_command(step))
            continue
        if kind == "bash":
            line = _command(step)
            if line in SET_UP:
                line = _script_command(repo / SET_UP[line])
            argv, shown = ["bash", "-c", line], line
        else:
            argv, shown = [sys.executable, "-c", step], step.splitlines()[0] + " ..."
        started = time.perf_counter()
        proc = subprocess.run(argv, cwd=repo, env=env, capture_output=True, text=True,
                              timeout=LINE_TIMEOUT)
        seconds = time.perf_counter() - started
        assert proc.returncode == 0, (f"README step {shown!r} exited {proc.returncode} after "
                                      f"{seconds:.0f} s:\n{proc.stdout[-3000:]}\n"
                                      f"{proc.stderr[-3000:]}")
        assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
        done.append((shown, seconds))
    assert sorted(skipped) == sorted(NOT_RUN)
    assert len(done) >= 10, done
    print("\n".join(f"{s:7.1f} s  {line}" for line, s in done))


def test_readme_lists_every_howto():
    """Each recipe of docs/howto/ (but the index) is named in the README's list."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    howtos = sorted(p.name for p in (ROOT / "docs" / "howto").glob("*.md") if p.stem != "index")
    missing = [name for name in howtos if f"`{name}`" not in text]
    assert howtos and not missing, missing


def test_readme_says_what_not_when():
    """The README speaks to a user: no issue numbers, development waves or targets met."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    for pattern in (r"\bissue\s+#?\d+", r"\bwaves?\b", r"\btargets?\b.{0,40}\bmet\b",
                    r"\bnot met\b"):
        assert not re.search(pattern, text, flags=re.I), pattern


def test_light_install_extras_exist():
    """Every extra the README's *Light install* names is declared in pyproject.toml."""
    import tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"][
        "optional-dependencies"]
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    light = text[text.index("## Light install"):text.index("## A first run")]
    named = set(re.findall(r'"\.\[([\w,]+)\]"', light))
    named = {e for group in named for e in group.split(",")}
    named |= set(re.findall(r"the `(\w+)`\s+extra", light))
    assert named >= {"analysis", "city", "magnnet", "learning", "ray", "docs"}, named
    assert named <= set(extras), named - set(extras)
