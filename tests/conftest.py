"""Shared fixtures: tiny scenario files that run in well under a second.

``write_scenario(directory, **overrides)`` writes a TOML scenario into ``directory`` and returns
its path. The default is a 12 x 12 x 6 m world of 1 m cells with 3 small obstacles, 3 vehicles
and static tasks. Each keyword names a section (``world``, ``obstacles``, ``fleet``, ``tasks``,
``dispatch``, ``sweep``) or a root key (``name``, ``seed``, ``duration``, ...); a section given as
a dict is merged into the default one, and a value of ``None`` removes that key.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DISPATCH_EXE = Path(sys.executable).with_name("dispatch")

TINY_WORLD = {"size": [12, 12, 6], "cell": 1.0}
TINY_OBSTACLES = {"count": 3, "min_size": [1, 1, 1], "max_size": [3, 3, 6]}
TINY_FLEET = {"agents": 3, "uav_fraction": 0.5, "uav_speed": 5.0, "ugv_speed": 3.0}
TINY_TASKS = {"source": "static", "ground_fraction": 0.5}
TINY_DISPATCH = {"allocator": "hungarian", "planner": "astar"}


@pytest.fixture(autouse=True, scope="session")
def _private_cache_dir(tmp_path_factory):
    """The session's own disk cache (``DISPATCH_CACHE_DIR``: road hierarchies): tests neither
    read what an earlier process cached nor write into the user's home."""
    old = os.environ.get("DISPATCH_CACHE_DIR")
    os.environ["DISPATCH_CACHE_DIR"] = str(tmp_path_factory.mktemp("dispatch-cache"))
    yield
    if old is None:
        os.environ.pop("DISPATCH_CACHE_DIR", None)
    else:
        os.environ["DISPATCH_CACHE_DIR"] = old


def toml_value(v) -> str:
    """A TOML literal for a str, bool, int, float or list of those (enough for scenarios)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (str, Path)):
        s = str(v).replace("\\", "\\\\").replace('"', '\\"')
        return f'"{s}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML literal for {v!r}")


def _section(lines: list[str], header: str, table: dict) -> None:
    lines.append(f"[{header}]")
    lines.extend(f"{k} = {toml_value(v)}" for k, v in table.items() if v is not None)
    lines.append("")


def _merge(default: dict, override) -> dict | None:
    if override is None:
        return None
    out = dict(default)
    out.update(override)
    return out


def scenario_text(
    *,
    name: str = "tiny",
    seed: int = 0,
    duration: float = 300.0,
    world: dict | None = None,
    obstacles: dict | None = None,
    fleet: dict | None = None,
    tasks: dict | None = None,
    dispatch: dict | None = None,
    sweep: dict | None = None,
    extra: str = "",
    **root,
) -> str:
    """The TOML text of a tiny scenario (see the module docstring)."""
    lines = [f"name = {toml_value(name)}", f"seed = {seed}", f"duration = {duration!r}"]
    lines += [f"{k} = {toml_value(v)}" for k, v in root.items() if v is not None]
    lines.append("")
    _section(lines, "world", _merge(TINY_WORLD, world or {}))
    _section(lines, "world.obstacles", _merge(TINY_OBSTACLES, obstacles or {}))
    _section(lines, "fleet", _merge(TINY_FLEET, fleet or {}))
    _section(lines, "tasks", _merge(TINY_TASKS, tasks or {}))
    _section(lines, "dispatch", _merge(TINY_DISPATCH, dispatch or {}))
    if sweep:
        _section(lines, "sweep", sweep)
    if extra:
        lines.append(extra)
    return "\n".join(lines) + "\n"


def write_scenario(directory: Path, filename: str = "tiny.toml", **kw) -> Path:
    """Write a tiny scenario (keywords as :func:`scenario_text`) and return its path."""
    path = Path(directory) / filename
    path.write_text(scenario_text(**kw), encoding="utf-8")
    return path


@pytest.fixture
def tiny_scenario(tmp_path) -> Path:
    """The default tiny scenario: 3 vehicles, 3 static tasks, hungarian + astar."""
    return write_scenario(tmp_path)


@pytest.fixture
def make_scenario(tmp_path):
    """A factory: ``make_scenario(filename="tiny.toml", **overrides) -> Path`` in tmp_path."""

    def make(filename: str = "tiny.toml", **kw) -> Path:
        return write_scenario(tmp_path, filename, **kw)

    return make


def run_cli(*args, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run the installed ``dispatch`` console script (falling back to ``python -m
    dispatch.run.cli``)
    with a wide terminal, so that rich does not wrap long messages."""
    cmd = [str(DISPATCH_EXE)] if DISPATCH_EXE.exists() else \
        [sys.executable, "-m", "dispatch.run.cli"]
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
    return subprocess.run(
        [*cmd, *map(str, args)], capture_output=True, text=True, cwd=cwd or ROOT, env=env,
        timeout=timeout,
    )


@pytest.fixture
def cli():
    """``cli(*args) -> CompletedProcess`` of the ``dispatch`` command (see :func:`run_cli`)."""
    return run_cli


def fake_distribution(site: Path, dist: str, module: str, source: str, entry_points: str) -> Path:
    """Make ``site`` (a folder to put on PYTHONPATH) hold an installed distribution ``dist``:
    the module ``module`` with ``source`` and the ``entry_points.txt`` text ``entry_points``
    (what ``pip install`` of a plugin package leaves, without installing anything)."""
    (site / f"{module}.py").write_text(source, encoding="utf-8")
    info = site / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)
    return site


#: Raw data the shipped files and some checks were made from: kept beside a checkout of the
#: workspace (``../shared/data``), never shipped. Tests that read it skip without it.
SHARED_DATA = ROOT.parent / "shared" / "data"


def missing_data(path: Path, what: str) -> str:
    """The reason a test that reads ``path`` (under :data:`SHARED_DATA`) skips: what it needs,
    where, and that a clone lacks it by design (nothing to install)."""
    return (f"needs {what} at {path}: raw data kept beside the workspace's checkout in "
            "../shared/data, not shipped with the repository (nothing to install; the "
            "shipped files hold what the other tests need)")
