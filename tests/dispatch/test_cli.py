"""Smoke tests of the ``dispatch`` command line (run in a subprocess, as a user would)."""

from __future__ import annotations

import json

import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from dispatch import __version__
from dispatch.api.registry import available
from dispatch.output.parquet import SCHEMAS
from tests.conftest import write_scenario

#: The partition of the module's single run: every run writes
#: ``OUT/<table>/allocator=…/planner=…/n_agents=…/seed=…/part-0.parquet``.
LEAF = "scenario=tiny/allocator=hungarian/planner=astar/n_agents=3/seed=1"
#: The partition columns, which live in the path, not in the files.
PARTITION = ("scenario", "allocator", "planner", "n_agents", "seed")

#: The documented columns of each table (DESIGN.md / the issue list); tables may hold more.
DOCUMENTED = {
    "summary": ["run_id", "scenario", "allocator", "planner", "n_agents", "n_tasks", "seed",
                "space", "total_cost", "conflict_free_rate", "alloc_seconds", "tasks_completed",
                "tasks_unfinished", "makespan"],
    "tasks": ["run_id", "task_id", "kind", "x", "y", "z", "released_at", "assigned_at",
              "agent_id", "cost", "picked_up_at", "completed_at", "state", "conflicted"],
    "assignments": ["run_id", "decision", "round", "agent_id", "task_id", "cost", "won",
                    "alloc_seconds"],
    "events": ["run_id", "t", "event", "agent_id", "task_id", "x", "y", "z"],
    "vehicles": ["run_id", "agent_id", "kind", "speed", "x0", "y0", "z0", "distance",
                 "empty_distance", "occupied_distance", "busy_seconds"],
    "obstacles": ["run_id", "x0", "y0", "z0", "x1", "y1", "z1"],
}


@pytest.fixture(scope="module")
def single_run(tmp_path_factory):
    """``dispatch run tiny.toml --out DIR --agents 3 --seed 1``, run once for the module."""
    from tests.conftest import run_cli

    d = tmp_path_factory.mktemp("cli_run")
    scenario = write_scenario(d, fleet={"agents": 5}, tasks={"count": 4})
    out = d / "out"
    proc = run_cli("run", scenario, "--out", out, "--agents", 3, "--seed", 1)
    return scenario, out, proc


def test_run_exits_0_and_prints_tables(single_run):
    scenario, out, proc = single_run
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    # one run prints its own summary, not a table of means over one seed
    assert "One run of tiny" in proc.stdout and "mean over" not in proc.stdout
    assert "hungarian / astar, N = 3, seed 1" in proc.stdout
    assert "4 released" in proc.stdout
    assert "1 run(s)" in proc.stdout
    assert str(out) in proc.stdout.replace("\n", "")


@pytest.mark.parametrize("table", list(DOCUMENTED))
def test_run_writes_documented_columns(single_run, table):
    _, out, proc = single_run
    assert proc.returncode == 0, proc.stderr
    path = out / table / LEAF / "part-0.parquet"
    assert path.is_file()
    t = pq.read_table(path)
    cols = t.column_names
    documented = [c for c in DOCUMENTED[table] if c not in PARTITION]  # those are in the path
    missing = [c for c in documented if c not in cols]
    assert not missing, f"{table} lacks {missing}"
    assert not [c for c in PARTITION if c in cols], f"{table} repeats a partition column"
    # the documented columns keep their documented order
    assert [c for c in cols if c in documented] == documented
    # read as a Hive dataset, the partition columns come back from the path
    full = ds.dataset(out / table, partitioning="hive").to_table()
    assert set(DOCUMENTED[table]) | set(PARTITION) <= set(full.column_names)
    assert full.num_rows == t.num_rows
    assert set(t.column("run_id").to_pylist()) <= {"tiny__hungarian__astar__n3__s1"}
    meta = t.schema.metadata
    assert meta[b"dispatch.scenario"].decode() == (out.parent / "tiny.toml").read_text()
    assert meta[b"dispatch.seed"] == b"1"
    assert meta[b"dispatch.version"].decode() == __version__
    if table == "obstacles":
        assert json.loads(meta[b"dispatch.world_size"]) == [12.0, 12.0, 6.0]
        assert float(meta[b"dispatch.cell"]) == 1.0


def test_run_output_content(single_run):
    _, out, _ = single_run
    summary = ds.dataset(out / "summary", partitioning="hive").to_table().to_pylist()
    assert len(summary) == 1
    s = summary[0]
    assert (s["scenario"], s["allocator"], s["planner"], s["n_agents"], s["seed"]) == (
        "tiny", "hungarian", "astar", 3, 1)
    assert s["n_tasks"] == 4
    assert pq.read_table(out / "vehicles" / LEAF / "part-0.parquet").num_rows == 3
    assert pq.read_table(out / "tasks" / LEAF / "part-0.parquet").num_rows == 4
    assert pq.read_table(out / "obstacles" / LEAF / "part-0.parquet").num_rows == 3
    # one file per table, nothing half-written (temporary files, chunks) left behind
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert files == sorted([f"{t}/{LEAF}/part-0.parquet" for t in SCHEMAS]
                           + [f"_runs/{LEAF}/done.json"])


def test_plugins_lists_builtins(cli):
    proc = cli("plugins")
    assert proc.returncode == 0, proc.stderr
    for name in ("hungarian", "greedy", "random", "astar"):
        assert name in proc.stdout
    for name in set(available("allocator")) | set(available("planner")):
        assert name in proc.stdout


def test_unknown_allocator_exits_2_listing_installed(tiny_scenario, cli, tmp_path):
    out = tmp_path / "never"
    proc = cli("run", tiny_scenario, "--allocator", "nosuch", "--out", out)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stdout + proc.stderr
    assert "nosuch" in proc.stderr
    for name in ("hungarian", "greedy", "random"):
        assert name in proc.stderr
    assert not out.exists()


def test_unknown_allocator_in_file(make_scenario, cli):
    path = make_scenario(dispatch={"allocator": "nosuch"})
    proc = cli("validate", path)
    assert proc.returncode == 2
    assert "nosuch" in proc.stderr and "hungarian" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_sweep_prints_all_allocators(make_scenario, cli, tmp_path):
    sweep = {"allocator": ["hungarian", "greedy", "random"], "agents": [2, 3], "seed": [0, 1]}
    path = make_scenario(sweep=sweep)
    out = tmp_path / "sweep_out"
    proc = cli("run", path, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "12 run(s)" in proc.stdout
    # one row per allocator and N, in each of Tables I and III
    rows = [line.split() for line in proc.stdout.splitlines()]
    for alloc in ("hungarian", "greedy", "random"):
        for n in ("2", "3"):
            assert sum(r[:2] == [alloc, n] for r in rows) == 2, (alloc, n, proc.stdout)
    assert (out / "summary" / "scenario=tiny" / "allocator=random" / "planner=astar" / "n_agents=2" / "seed=0"
            / "part-0.parquet").is_file()


def test_validate_good_file(tiny_scenario, cli):
    proc = cli("validate", tiny_scenario)
    assert proc.returncode == 0, proc.stderr
    assert "ok" in proc.stdout and "1 run(s)" in proc.stdout


def test_version(cli):
    proc = cli("--version")
    assert proc.returncode == 0
    assert __version__ in proc.stdout


def test_usage_error_exits_2(cli):
    proc = cli("run")
    assert proc.returncode == 2
    assert "usage" in proc.stderr.lower()


def test_module_entry_point(tiny_scenario, tmp_path):
    """``python -m dispatch.run.cli`` works as well as the console script."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "dispatch.run.cli", "validate",
                           str(tiny_scenario)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "ok" in proc.stdout


# ----------------------------------------------------------------------------- known bugs


def test_negative_seed_override_is_a_clean_error(tiny_scenario, tmp_path, capsys):
    from dispatch.run import cli as cli_module
    out = tmp_path / "neg"
    assert cli_module.main(["run", str(tiny_scenario), "--seed", "-1", "--out", str(out)]) == 2
    assert "--seed" in capsys.readouterr().err
    assert not out.exists()


# ----------------------------------------------------------------------------- the first hour


@pytest.mark.parametrize("flags", [["--debug"], ["-v"]])
def test_logging_flag_before_or_after_the_command(tiny_scenario, flags):
    from dispatch.run.parser import parser

    before = parser().parse_args([*flags, "validate", str(tiny_scenario)])
    after = parser().parse_args(["validate", str(tiny_scenario), *flags])
    neither = parser().parse_args(["validate", str(tiny_scenario)])
    key = "debug" if flags == ["--debug"] else "verbose"
    assert getattr(before, key) and getattr(after, key)
    assert not neither.debug and not neither.verbose


def test_debug_after_the_command_prints_the_traceback(make_scenario, cli):
    path = make_scenario(dispatch={"allocator": "nosuch"})
    proc = cli("validate", path, "--debug")
    assert proc.returncode == 2 and "nosuch" in proc.stderr
    assert "Traceback" in proc.stderr


def test_train_help_lists_the_trainers(cli):
    from importlib.metadata import entry_points

    proc = cli("train", "--help")
    assert proc.returncode == 0, proc.stderr
    names = [ep.name for ep in entry_points(group="dispatch.trainers")]
    assert names
    for name in names:
        assert name in proc.stdout


def test_every_argument_has_help():
    """Every option and positional of every subcommand (this package's and the analysis
    package's) says what it is in --help."""
    import argparse

    from dispatch.run.parser import OWN_COMMANDS, parser
    from dispatch.run.commands import installed

    ours = {n: c for n, c in installed(reserved=OWN_COMMANDS).items()
            if c.target.startswith(("dispatch.", "analysis."))}
    missing = []

    def walk(parser, name):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                shown = {a.dest for a in action._choices_actions}
                for sub, subparser in action.choices.items():
                    if sub in OWN_COMMANDS or sub in ours:
                        if sub not in shown:
                            missing.append(f"{name} {sub}")
                        walk(subparser, f"{name} {sub}")
            elif not action.help or action.help == argparse.SUPPRESS:
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")

    walk(parser(ours), "dispatch")
    assert {"report", "render"} <= set(ours)
    assert missing == []


def test_snap_warning_printed_once_with_duration(tmp_path, caplog, monkeypatch):
    """The scenario is parsed once, ``--duration`` and overrides included: the trips left out
    beyond ``max_snap`` are reported once, and (9 % of the shipped day's trips, ending across
    a river by design) at INFO level, not as a warning."""
    import logging

    from dispatch.run.cli import main
    from dispatch.scenario import notes
    from tests.conftest import ROOT

    monkeypatch.setattr(notes, "SAID", set())  # (another test may have loaded the day)
    caplog.set_level(logging.INFO, logger="dispatch.scenario.load")
    assert main(["run", str(ROOT / "scenarios" / "nyc_manhattan.toml"), "--duration", "30",
                 "--out", str(tmp_path / "out")]) == 0
    left_out = [r for r in caplog.records if "trips left out" in r.getMessage()]
    assert len(left_out) == 1, [r.getMessage() for r in left_out]
    assert left_out[0].levelno == logging.INFO


def test_an_electric_run_prints_its_energy_and_cut_off_trips(tmp_path, cli):
    """``dispatch run`` of an electric scenario cut off by its duration: the summary counts
    the trips still waiting or aboard as cut off (not cancelled) and prints the energy line
    with the summary's figures as written to the Parquet file."""
    from tests.dispatch.test_energy import grid

    p = grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = 150.0\nidle_kwh_per_hour = 0.36\n"
                       "soc0 = 0.5\nreserve = 0.1", [(0.0, 2, 8), (1.0, 3, 9), (2.0, 4, 10)],
             duration=50.0)
    proc = cli("run", p, "--out", tmp_path / "out")
    assert proc.returncode == 0, proc.stderr
    s = ds.dataset(tmp_path / "out" / "summary", partitioning="hive").to_table().to_pylist()[0]
    assert s["tasks_cut_off"] > 0
    text = " ".join(proc.stdout.split())
    assert f"{s['tasks_cut_off']} cut off by the end of the run" in text
    assert "cancel" not in text
    # the auxiliary load, 0.36 kWh/h on every vehicle never plugged in for the run's 50 s, apart
    # from the driving part (a kWh per km is the driving part over the km)
    aux = s["kwh_auxiliary"]
    assert aux == pytest.approx(0.36 * 50 / 3600 * s["n_agents"], rel=1e-9)
    assert 0 < aux < s["kwh_drawn"]
    per = s["kwh_drawn"] / s["n_agents"]
    assert (f"energy {s['kwh_drawn']:,.1f} kWh drawn ({per:.2f} kWh per vehicle; "
            f"{s['kwh_drawn'] - aux:,.1f} kWh driving, {aux:,.1f} kWh the auxiliary load), "
            f"0.0 kWh charged in 0 charges, 0.0 h queued; state of charge lowest "
            f"{100 * s['soc_min']:.1f}%") in text


_WARN_THEN = """
import logging, sys
from dispatch.errors import DispatchError
from dispatch.run import cli

def validate(args, console):
    logging.getLogger("dispatch.scenario.load").warning("11 of 40 trips left out")
    if {refuse}:
        raise DispatchError("shifts.csv: row 2: depot 'nan' is off the network")
    return 0

cli._validate = validate
sys.exit(cli.main(["validate", "any.toml"]))
"""


@pytest.mark.parametrize("refuse", [True, False])
def test_a_refusal_is_one_line_without_the_warnings_before_it(refuse):
    """Warnings logged during the set-up are held back: a refusal part-way through prints its
    one error line alone; a command that goes through prints them as before."""
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", _WARN_THEN.format(refuse=refuse)],
                          capture_output=True, text=True, timeout=120, check=False)
    lines = proc.stderr.strip().splitlines()
    if refuse:
        assert proc.returncode == 2
        assert lines == ["error: shifts.csv: row 2: depot 'nan' is off the network"]
    else:
        assert proc.returncode == 0
        assert lines == ["WARNING dispatch.scenario.load: 11 of 40 trips left out"]
