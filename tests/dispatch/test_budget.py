"""Work bounds (dispatch.scenario.budget): the fuzzed runs that ran past 30 s without a word are
refused by ``dispatch validate`` with the estimate and the bound (``--ignore-limits`` runs
them), the shipped scenarios are not; a long run says where it is on stderr when not on a
terminal."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import ROOT, write_scenario

PAPER_WORLD = {"size": [50, 50, 30], "cell": 1.0}
PAPER_OBSTACLES = {"count": 10, "min_size": [3, 3, 5], "max_size": [10, 10, 30]}


def dispatch(*args, env=None, timeout=120):
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb", **(env or {})}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                        if p)
    return subprocess.run([sys.executable, "-m", "dispatch.run.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=ROOT)


CASES = {
    "5000 static tasks": dict(world=PAPER_WORLD, obstacles=PAPER_OBSTACLES,
                              tasks={"count": 5000}, fleet={"agents": 8}),
    "100000 static tasks": dict(world=PAPER_WORLD, obstacles=PAPER_OBSTACLES,
                                tasks={"count": 100000}, fleet={"agents": 8}),
    "5000 static tasks on 4 vehicles": dict(world=PAPER_WORLD, obstacles=PAPER_OBSTACLES,
                                            tasks={"count": 5000}, fleet={"agents": 4}),
    "5000 static vehicles": dict(world={"size": [200, 200, 30], "cell": 1.0},
                                 obstacles=PAPER_OBSTACLES, fleet={"agents": 5000}),
    "Poisson 100/s without max_active, a decision per release": dict(
        world=PAPER_WORLD, obstacles=PAPER_OBSTACLES, duration=600.0,
        tasks={"source": "poisson", "rate": 100.0}),
}
CUT_NOTE = ("past 2,000 open tasks a decision considers each vehicle's 32 nearest and the "
            "oldest, at most {}, after a scan of all of them")
EXPECT = {
    # M static tasks on fewer vehicles: M^2 / 2 up to 2,000 open, the cut's candidates past it
    "5000 static tasks": ("tasks.count", "3.32e+06 task-decisions", CUT_NOTE.format(264)),
    "100000 static tasks": ("tasks.count", "2.78e+08 task-decisions", CUT_NOTE.format(264)),
    "5000 static tasks on 4 vehicles": ("tasks.count", "2.92e+06 task-decisions",
                                        CUT_NOTE.format(132)),
    "5000 static vehicles": ("fleet.agents", "2.5e+07 task-decisions", "on a grid of"),
    "Poisson 100/s without max_active, a decision per release": (
        "tasks.max_active", "9.76e+07 task-decisions (about 60,000 decisions over up to 60,000 "
        "open tasks (no max_active, ttl or max_wait", "or a batch window"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_fuzz_hang_is_refused_at_validate(case, tmp_path):
    path = write_scenario(tmp_path, **CASES[case])
    proc = dispatch("validate", path)
    assert proc.returncode == 2, proc.stdout
    key, amount, bound = EXPECT[case]
    line = proc.stderr.strip()
    assert line.startswith(f"error: {path}: {key}: about"), line
    assert amount in line and bound in line and "use --ignore-limits to run anyway" in line, line
    assert len(line.splitlines()) == 1


def test_crowded_with_tiny_retry_after_is_refused(tmp_path):
    text = (ROOT / "scenarios" / "crowded.toml").read_text().replace(
        'planner = "reservation"', 'planner = "reservation"\n[dispatch.planner_params]\n'
        'retry_after = 1e-9')
    path = tmp_path / "crowded.toml"
    path.write_text(text)
    proc = dispatch("validate", path)
    assert proc.returncode == 2
    assert (f"{path}: dispatch.planner_params: planner 'reservation': retry_after = 1e-09 s "
            "lets 12 vehicles make up to 3.6e+12 retries in 300 s (more than 2,000,000)") \
        in proc.stderr
    ok = tmp_path / "ok.toml"
    ok.write_text(text.replace("retry_after = 1e-9", "retry_after = 0.01"))
    assert dispatch("validate", ok).returncode == 0


def test_rrt_star_with_huge_max_iterations_is_refused(tmp_path):
    path = write_scenario(tmp_path, dispatch={"planner": "rrt_star"},
                          extra="[dispatch.planner_params]\nmax_iterations = 10000000\n")
    proc = dispatch("validate", path)
    assert proc.returncode == 2
    assert ("dispatch.planner_params: planner 'rrt_star': about 6e+07 tree iterations (2 trees "
            "x 3 tasks x max_iterations = 10,000,000; more than 60,000") in proc.stderr
    forced = dispatch("validate", path, "--ignore-limits")
    assert forced.returncode == 0, forced.stderr


# the fuzz run's overload family (2026-11-27): thousands of open tasks, 4 vehicles, batched 5 s
POISSON_OVERLOAD = dict(world=PAPER_WORLD, obstacles=PAPER_OBSTACLES, duration=120.0,
                        fleet={"agents": 4},
                        tasks={"source": "poisson", "rate": 100.0, "ttl": 120.0},
                        dispatch={"batch_window": 5.0})


def voxel_trace(path, rows: int, seconds: float) -> None:
    """A trace of ``rows`` trips spread evenly over ``seconds`` in the paper's world."""
    rng = np.random.default_rng(0)
    xyz = rng.integers((50, 50, 30), size=(rows, 3)) + 0.5
    t = np.arange(rows) * (seconds / rows)
    path.write_text("t,x,y,z\n" + "".join(f"{a:.4f},{x},{y},{z}\n"
                                           for a, (x, y, z) in zip(t, xyz.tolist())))


def test_the_overloaded_batch_is_counted_with_the_candidate_cut(tmp_path):
    """Poisson 100/s living 120 s on 4 vehicles batched 5 s: up to 12,000 open tasks, but a
    decision past 2,000 considers 132 of them (dispatch.decide.candidates), so the run is within the
    bound (it used to reach 85 of 120 simulated seconds in 5 minutes)."""
    from dispatch.scenario.budget import task_decisions
    from dispatch.scenario.load import load_scenario

    path = write_scenario(tmp_path, **POISSON_OVERLOAD)
    work, how = task_decisions(load_scenario(path).runs()[0])
    # 500, 1,000, 1,500 and 2,000 open at the first four decisions, then 132 of up to 12,000
    # at each of the other 20, plus their scans (20 open tasks scanned count as one)
    assert how.startswith("about 24 decisions over up to 12,000 open tasks")
    assert "at most 132" in how
    scans = sum(min(500 * k, 12_000) for k in range(5, 25)) / 20
    assert work == pytest.approx(5_000 + 20 * 132 + scans)
    assert dispatch("validate", path).returncode == 0


def test_a_trace_of_many_trips_is_counted(tmp_path):
    """A 50,000-row trace over 120 s on 4 vehicles (the fuzz run's had 200,000): batched 5 s
    it is within the bound (the cut), decided at every release it is refused with the numbers
    (a trace used to count nothing)."""
    voxel_trace(tmp_path / "trips.csv", 50_000, 120.0)
    kw = dict(POISSON_OVERLOAD, tasks={"source": "trace", "trace": "trips.csv",
                                       "max_wait": 120.0, "ground_fraction": None})
    batched = write_scenario(tmp_path, "batched.toml", **kw)
    proc = dispatch("validate", batched)
    assert proc.returncode == 0, proc.stderr
    at_once = write_scenario(tmp_path, "at_once.toml", **dict(kw, dispatch={}))
    proc = dispatch("validate", at_once)
    assert proc.returncode == 2
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f"error: {at_once}: tasks.trace: about 7.07e+07 task-decisions "
                           "(about 50,000 decisions over up to 50,000 open tasks "
                           "(released and not yet expired by ttl or max_wait)"), line
    assert "at most 132" in line and "or a batch window" in line


def test_rrt_star_with_a_tiny_step_is_refused(tmp_path):
    """``step = 1e-6`` keeps each tree within millimetres of its goal: every node is every new
    node's rewiring neighbour (an iteration tests them all) and a start the goal does not see
    spends every growth round: 16 trees of 3,000 iterations took 81 s for 8 tasks."""
    text = (ROOT / "scenarios" / "paper_static.toml").read_text()
    text = text[: text.index("[sweep]")].replace(
        'planner = "astar"', 'planner = "rrt_star"\n\n[dispatch.planner_params]\nstep = 1e-6')
    path = tmp_path / "rrt.toml"
    path.write_text(text)
    proc = dispatch("validate", path)
    assert proc.returncode == 2
    assert ("dispatch.planner_params: planner 'rrt_star': about 7.2e+07 ray tests (8 tasks x a "
            "UAV and a UGV tree of 4.5e+06 and 4.5e+06: step = 1e-06 m keeps a tree of 3,000 "
            "iterations within 0.003 m of its goal, so every node is a rewiring neighbour of "
            "every new one; more than 15,000,000, about 20 s): raise step") in proc.stderr
    ok = tmp_path / "ok.toml"
    ok.write_text(text.replace("step = 1e-6", "step = 1.0"))
    assert dispatch("validate", ok).returncode == 0
    assert dispatch("validate", path, "--ignore-limits").returncode == 0


def test_shipped_scenarios_are_within_the_bounds():
    from dispatch.errors import ScenarioError
    from dispatch.scenario.budget import check_work
    from dispatch.scenario.load import load_scenario

    def refuse(key, what):
        return ScenarioError("f", key, what)

    for path in sorted((ROOT / "scenarios").glob("*.toml")):
        sc = load_scenario(path)
        check_work(sc, sc.runs(), refuse)  # raises past a bound


def test_a_long_run_says_where_it_is_on_stderr(tmp_path):
    """Not on a terminal (captured), a run prints a line every DISPATCH_HEARTBEAT_S seconds
    (a minute by default) on stderr: its run id, simulated time, tasks released and closed."""
    path = write_scenario(tmp_path, world=PAPER_WORLD, obstacles=PAPER_OBSTACLES,
                          fleet={"agents": 4}, tasks={"count": 300})
    proc = dispatch("run", path, "--out", tmp_path / "out", env={"DISPATCH_HEARTBEAT_S": "0.5"})
    assert proc.returncode == 0, proc.stderr
    beats = [ln for ln in proc.stderr.splitlines() if ln.startswith("[")]
    assert beats, proc.stderr
    assert all("tiny__hungarian__astar__n4__s0: simulated" in ln for ln in beats)
    assert "tasks released" in beats[-1] and "closed" in beats[-1]
    assert "simulated" not in proc.stdout.split("One run")[0]  # stdout keeps the tables only
