"""The house's boundaries (issue 23): the kernel imports no concrete plugin and no analysis;
analysis imports nothing of dispatch (what both need, the paired comparison, is the shared
``paired`` package); a plugin package imports ``dispatch`` (and itself) only. Commands reach the
command line through the entry-point group ``dispatch.commands``."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, fake_distribution

PLUGIN_PACKAGES = ("allocators", "planners", "repositioners", "chargers")


def _imports(package: str) -> list[tuple[str, str]]:
    """``(file, imported module)`` for every import in ``package`` (top level and inside
    functions; relative imports resolved to the package)."""
    out = []
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                out += [(rel, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                out.append((rel, package if node.level else node.module or ""))
    return out


def _top(module: str) -> str:
    return module.partition(".")[0]


def test_kernel_imports_no_plugin_and_no_analysis():
    bad = [(f, m) for f, m in _imports("dispatch") if _top(m) in (*PLUGIN_PACKAGES, "analysis")]
    assert bad == []


def test_analysis_imports_nothing_of_dispatch():
    assert [(f, m) for f, m in _imports("analysis") if _top(m) == "dispatch"] == []


def test_the_shared_comparison_imports_neither_side():
    """paired.compare (allocator order, paired gap) serves dispatch's tables and analysis."""
    imported = {_top(m) for _, m in _imports("paired")}
    assert not imported & {"dispatch", "analysis", *PLUGIN_PACKAGES}
    printed = "dispatch/output/printed.py"
    assert {_top(m) for f, m in _imports("dispatch") if f == printed} >= {"paired"}
    assert "paired" in {_top(m) for f, m in _imports("analysis") if f == "analysis/metrics.py"}


@pytest.mark.parametrize("package", PLUGIN_PACKAGES)
def test_a_plugin_package_imports_dispatch_and_itself_only(package):
    others = {*PLUGIN_PACKAGES, "analysis"} - {package}
    assert [(f, m) for f, m in _imports(package) if _top(m) in others] == []


def test_a_plugin_uses_no_private_name_of_the_kernel():
    """``from dispatch.x import _y`` (or ``STREAM_*`` of the run's wiring) is not API."""
    bad = []
    for package in PLUGIN_PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                        "dispatch") and not node.level:
                    bad += [f"{path.relative_to(ROOT)}: {node.module}.{a.name}"
                            for a in node.names
                            if a.name.startswith("_") or node.module == "dispatch.run.sim"]
    assert bad == []


COMMAND = '''
class Hello:
    """Says hello (a command another package adds)."""

    help = "say hello"

    @staticmethod
    def add_arguments(p):
        p.add_argument("name")

    @staticmethod
    def user_errors():
        return (LookupError,)

    def run(self, args, out):
        if args.name == "nobody":
            raise LookupError("nobody to greet")
        out.print(f"hello {args.name}")
        out.warn("said hello")
        return 0


class Run(Hello):
    """Would shadow dispatch's own run."""
'''


@pytest.fixture(scope="module")
def command_site(tmp_path_factory) -> Path:
    """A folder that, on PYTHONPATH, installs a distribution adding the commands ``hello``
    and ``run`` (the latter is dispatch's own: not added) and a broken one."""
    return fake_distribution(
        tmp_path_factory.mktemp("site"), "my-commands", "my_commands", COMMAND,
        "[dispatch.commands]\nhello = my_commands:Hello\nrun = my_commands:Run\n"
        "broken = my_commands:Missing\n")


def _dispatch(*args, site: Path):
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), str(site),
                                                    env.get("PYTHONPATH", "")) if p)
    return subprocess.run([sys.executable, "-m", "dispatch.run.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=120, cwd=ROOT)


def test_a_registered_command_runs_and_is_listed(command_site):
    proc = _dispatch("hello", "world", site=command_site)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "hello world"
    assert proc.stderr.strip().endswith("warning: said hello")
    proc = _dispatch("hello", "nobody", site=command_site)  # a user error: one line
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "error: nobody to greet"
    proc = _dispatch("plugins", site=command_site)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "dispatch.commands" in out
    for line in ("Says hello (a command another package adds).", "my_commands:Hello",
                 "analysis.commands:Report", "analysis.commands:Render"):
        assert line in out
    assert "BROKEN" in out and "my_commands:Missing" in out
    proc = _dispatch("broken", "x", site=command_site)  # its load error, when it is run
    assert proc.returncode == 2 and "Missing" in proc.stderr


def test_a_command_cannot_shadow_dispatchs_own(command_site, tmp_path):
    proc = _dispatch("run", "--help", site=command_site)
    assert proc.returncode == 0
    assert "--allocator" in proc.stdout  # dispatch's own run
