"""What a newcomer trips on (issue 23): a plugin's traceback with -v / --debug, plugin
descriptions (never empty, plain text, targets whole at 80 columns), an unknown allocator
named with its file, key and the close name, and parameters per allocator."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.conftest import ROOT, fake_distribution, write_scenario

PLUGIN = '''
from allocators.greedy import GreedyAllocator


class BoomAllocator(GreedyAllocator):
    """Raises on its first decision (see :func:`_explode`)."""

    def allocate(self, problem):
        return _explode()


def _explode():
    return 1 / 0


class NoDocAllocator(GreedyAllocator):
    pass
'''


@pytest.fixture(scope="module")
def plugin_site(tmp_path_factory) -> Path:
    """A folder that, on PYTHONPATH, installs the distribution ``my-plugins`` with two
    allocators: ``boom`` (raises) and ``nodoc`` (no docstring, nor has its module)."""
    return fake_distribution(
        tmp_path_factory.mktemp("site"), "my-plugins", "my_plugins", PLUGIN,
        "[dispatch.allocators]\nboom = my_plugins:BoomAllocator\n"
        "nodoc = my_plugins:NoDocAllocator\n")


def dispatch(*args, site: Path | None = None, columns: int = 400):
    env = {**os.environ, "COLUMNS": str(columns), "NO_COLOR": "1", "TERM": "dumb"}
    path = [str(ROOT), *([str(site)] if site else []), env.get("PYTHONPATH", "")]
    env["PYTHONPATH"] = os.pathsep.join(p for p in path if p)
    return subprocess.run([sys.executable, "-m", "dispatch.run.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)


def test_a_plugin_that_raises_shows_its_traceback_with_v_or_debug(plugin_site, tmp_path):
    path = write_scenario(tmp_path)
    plain = dispatch("run", path, "--allocator", "boom", "--out", tmp_path / "a",
                     site=plugin_site)
    assert plain.returncode == 2
    assert "Traceback" not in plain.stderr and len(plain.stderr.strip().splitlines()) == 1
    assert "ZeroDivisionError" in plain.stderr and "boom" in plain.stderr
    for flag in ("-v", "--debug"):
        proc = dispatch(flag, "run", path, "--allocator", "boom", "--out", tmp_path / flag,
                        site=plugin_site)
        assert proc.returncode == 2
        assert "Traceback" in proc.stderr, flag
        assert "_explode" in proc.stderr and "my_plugins.py" in proc.stderr, flag
        assert proc.stderr.strip().splitlines()[-1].startswith("error:"), flag


def test_a_failing_run_of_a_sweep_shows_its_traceback_with_v(plugin_site, tmp_path):
    path = write_scenario(tmp_path, sweep={"allocator": ["greedy", "boom"]})
    plain = dispatch("sweep", path, "--workers", "1", "--out", tmp_path / "a", site=plugin_site)
    assert plain.returncode == 1
    assert "failed: tiny__boom__astar__n3__s0: PluginError" in plain.stdout
    assert "Traceback" not in plain.stdout + plain.stderr
    proc = dispatch("-v", "sweep", path, "--workers", "1", "--out", tmp_path / "b",
                    site=plugin_site)
    assert proc.returncode == 1
    assert "Traceback" in proc.stderr and "_explode" in proc.stderr


def test_plugins_descriptions_plain_never_empty_targets_whole(plugin_site):
    proc = dispatch("plugins", site=plugin_site, columns=80)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert max(len(line) for line in out.splitlines()) <= 80
    assert ":func:" not in out and "``" not in out and ":class:" not in out
    assert "scipy.optimize.linear_sum_assignment" in out  # hungarian's, without the role
    assert "NoDocAllocator from my_plugins, no docstring" in out
    assert "Raises on its first decision (see _explode)." in out
    from dispatch.api.registry import available

    for kind in ("allocator", "planner", "repositioner"):
        for target in available(kind).values():
            assert target in out, target  # on one line, not cut with an ellipsis
    assert "…" not in out


def test_plain_strips_sphinx_markup():
    from dispatch.api.registry import plain

    assert plain("via :func:`scipy.optimize.linear_sum_assignment`, see\n  "
                 ":class:`~dispatch.api.contracts.Allocator`, ``problem.rng`` and "
                 ":py:meth:`the rule <a.b>`") == (
        "via scipy.optimize.linear_sum_assignment, see Allocator, problem.rng and the rule")


@pytest.mark.parametrize("where", ["dispatch", "sweep", "option"])
def test_unknown_allocator_names_file_key_and_close_name(where, tmp_path):
    if where == "dispatch":
        path = write_scenario(tmp_path, dispatch={"allocator": "hungrian"})
        proc = dispatch("validate", path)
        key = "dispatch.allocator"
    elif where == "sweep":
        path = write_scenario(tmp_path, sweep={"allocator": ["greedy", "hungrian"]})
        proc = dispatch("validate", path)
        key = "sweep.allocator"
    else:
        path = write_scenario(tmp_path)
        proc = dispatch("run", path, "--allocator", "hungrian", "--out", tmp_path / "o")
        key = "--allocator"
    assert proc.returncode == 2
    assert f"{path}: {key}: unknown allocator 'hungrian' (did you mean 'hungarian'?)" \
        in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


PER_ALLOCATOR = textwrap.dedent('''
    [dispatch.allocator_params.auction]
    bundle_size = 2
    [dispatch.allocator_params."auction:cbaa"]
    bundle_size = 1
''')


def test_parameters_per_allocator_and_named_variants(tmp_path):
    """hungarian (no parameters) beside auction with bundle_size = 2 and the named variant
    auction:cbaa (bundle_size = 1), in one file and one sweep; the flat form still goes to
    every allocator."""
    from dispatch.scenario.load import load_scenario

    path = write_scenario(tmp_path, sweep={"allocator": ["hungarian", "auction", "auction:cbaa"]},
                          extra=PER_ALLOCATOR)
    sc = load_scenario(path)
    specs = {s.allocator: s for s in sc.runs()}
    assert list(specs) == ["hungarian", "auction", "auction:cbaa"]
    assert specs["hungarian"].scenario.dispatch.allocator_params == ()
    assert specs["auction"].scenario.dispatch.allocator_params == (("bundle_size", 2),)
    assert specs["auction:cbaa"].scenario.dispatch.allocator_params == (("bundle_size", 1),)
    assert specs["auction:cbaa"].run_id == "tiny__auction:cbaa__astar__n3__s0"
    proc = dispatch("run", path, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    for name in ("hungarian", "auction", "auction:cbaa"):
        assert any(line.split()[:1] == [name] for line in proc.stdout.splitlines()), name
    from analysis.io import open_results

    summary = open_results(tmp_path / "out").summary
    assert sorted(summary["allocator"]) == ["auction", "auction:cbaa", "hungarian"]

    # the flat form: every allocator gets it (hungarian rejects bundle_size, as before)
    flat = write_scenario(tmp_path, "flat.toml", sweep={"allocator": ["hungarian", "auction"]},
                          extra="[dispatch.allocator_params]\nbundle_size = 2\n")
    proc = dispatch("validate", flat)
    assert proc.returncode == 2 and "dispatch.allocator_params" in proc.stderr
    assert "hungarian" in proc.stderr and "Traceback" not in proc.stderr
    only = write_scenario(tmp_path, "only.toml", dispatch={"allocator": "auction"},
                          extra="[dispatch.allocator_params]\nbundle_size = 2\n")
    sc = load_scenario(only)
    assert sc.runs()[0].scenario.dispatch.allocator_params == (("bundle_size", 2),)


def test_a_variant_without_its_table_or_of_an_unknown_allocator(tmp_path):
    path = write_scenario(tmp_path, sweep={"allocator": ["hungarian", "auction:big"]})
    proc = dispatch("validate", path)
    assert proc.returncode == 2
    assert "sweep.allocator: 'auction:big' names a variant" in proc.stderr
    assert '[dispatch.allocator_params."auction:big"]' in proc.stderr  # not read as markup
    bad = write_scenario(tmp_path, "bad.toml",
                         extra='[dispatch.allocator_params."aukcion:x"]\nbundle_size = 1\n')
    proc = dispatch("validate", bad)
    assert proc.returncode == 2
    assert 'dispatch.allocator_params."aukcion:x": unknown allocator' in proc.stderr
    assert "did you mean 'auction'" in proc.stderr


def test_magnnet_paper_beside_hungarian_validates(tmp_path):
    """The issue's case: hungarian and magnnet variant = paper compared in one file."""
    pytest.importorskip("torch")
    path = write_scenario(tmp_path, fleet={"agents": 4}, tasks={"count": 4},
                          sweep={"allocator": ["hungarian", "magnnet:paper"]},
                          extra='[dispatch.allocator_params."magnnet:paper"]\nvariant = "paper"\n')
    proc = dispatch("validate", path)
    assert proc.returncode == 0, proc.stderr
    assert "2 run(s)" in proc.stdout


def test_no_pybullet_banner_in_any_output(tmp_path):
    """PyBullet's build banner (printed by C code at import, to stdout or stderr by build)
    opens no command's output; C-level prints inside quiet_c_output go nowhere, Python's
    before and after are kept in order."""
    path = write_scenario(tmp_path)
    proc = dispatch("run", path, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    assert "pybullet build time" not in proc.stdout + proc.stderr
    code = textwrap.dedent('''
        import ctypes, sys
        from paired.voxel_bodies import quiet_c_output
        print("before", flush=False)
        with quiet_c_output():
            libc = ctypes.CDLL(None)
            libc.printf(b"C on stdout\\n")
            libc.dprintf(2, b"C on stderr\\n")
            import pybullet
            pybullet.disconnect(pybullet.connect(pybullet.DIRECT))
        print("after")
    ''')
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "before\nafter\n" and proc.stderr == ""


def test_run_duration_overrides_the_file(tmp_path):
    from analysis.io import open_results

    path = write_scenario(tmp_path, duration=300.0,
                          tasks={"source": "periodic", "interval": 2.0, "service_time": 0.5})
    proc = dispatch("run", path, "--duration", "20", "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    res = open_results(tmp_path / "out")
    s = res.summary.iloc[0]
    assert s["sim_time"] <= 20.0 and s["n_tasks"] <= 11
    meta = res.metadata(s["run_id"], "summary")
    assert "duration = 20.0  # dispatch run --duration" in meta["dispatch.scenario"]
    assert "duration = 300.0" not in meta["dispatch.scenario"]
    for bad in ("0", "-5", "nan", "inf"):
        proc = dispatch("run", path, "--duration", bad, "--out", tmp_path / "no")
        assert proc.returncode == 2 and "--duration: must be a number of seconds > 0" \
            in proc.stderr, (bad, proc.stderr)
    nodur = tmp_path / "nodur.toml"  # no duration key: one is added
    nodur.write_text("\n".join(line for line in path.read_text().splitlines()
                               if not line.startswith("duration")))
    proc = dispatch("run", nodur, "--duration", "10", "--out", tmp_path / "out2")
    assert proc.returncode == 0, proc.stderr
    assert open_results(tmp_path / "out2").summary.iloc[0]["sim_time"] <= 10.0


def test_documented_run_counts_match_validate():
    """Every `dispatch run scenarios/X.toml  # ... (N runs)` line of the README, scenarios/README.md
    and the docs pages (the command-line page holds them now) says as many runs as the file
    expands to (paper_static is 200, not 240)."""
    import re

    from dispatch.scenario.load import load_scenario

    pages = [ROOT / "README.md", ROOT / "scenarios" / "README.md",
             *sorted((ROOT / "docs").rglob("*.md"))]
    found = 0
    for page in pages:
        for line in page.read_text(encoding="utf-8").splitlines():
            m = re.match(r"\s*dispatch (?:run|sweep|validate) (scenarios/\S+\.toml)\s+#.*"
                         r"\((\d+) runs?\)", line)
            if m:
                found += 1
                runs = len(load_scenario(ROOT / m.group(1)).runs())
                assert runs == int(m.group(2)), (page, line)
    assert found
