"""Work bounds (dispatch.budget): the fuzzed runs that ran past 30 s without a word are
refused by ``dispatch validate`` with the estimate and the bound (``--force`` runs them), the
shipped scenarios are not; a long run says where it is on stderr when not on a terminal."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.conftest import ROOT, write_scenario

PAPER_WORLD = {"size": [50, 50, 30], "cell": 1.0}
PAPER_OBSTACLES = {"count": 10, "min_size": [3, 3, 5], "max_size": [10, 10, 30]}


def dispatch(*args, env=None, timeout=120):
    env = {**os.environ, "COLUMNS": "400", "NO_COLOR": "1", "TERM": "dumb", **(env or {})}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH"))
                                        if p)
    return subprocess.run([sys.executable, "-m", "dispatch.cli", *map(str, args)],
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
    "Poisson 100/s without max_active": dict(
        world=PAPER_WORLD, obstacles=PAPER_OBSTACLES, duration=600.0,
        tasks={"source": "poisson", "rate": 100.0}, dispatch={"batch_window": 5.0}),
}
EXPECT = {
    "5000 static tasks": ("tasks.count", "1.25e+07 task-decisions", "600,000"),
    "100000 static tasks": ("tasks.count", "5e+09 task-decisions", "600,000"),
    "5000 static tasks on 4 vehicles": ("tasks.count", "1.25e+07 task-decisions", "600,000"),
    "5000 static vehicles": ("fleet.agents", "2.5e+07 task-decisions", "on a grid of"),
    "Poisson 100/s without max_active": ("tasks.max_active", "7.2e+06 task-decisions",
                                         "no max_active, ttl or max_wait"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_fuzz_hang_is_refused_at_validate(case, tmp_path):
    path = write_scenario(tmp_path, **CASES[case])
    proc = dispatch("validate", path)
    assert proc.returncode == 2, proc.stdout
    key, amount, bound = EXPECT[case]
    line = proc.stderr.strip()
    assert line.startswith(f"error: {path}: {key}: about"), line
    assert amount in line and bound in line and "use --force to run anyway" in line, line
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
    forced = dispatch("validate", path, "--force")
    assert forced.returncode == 0, forced.stderr


def test_shipped_scenarios_are_within_the_bounds():
    from dispatch.budget import check_work
    from dispatch.errors import ScenarioError
    from dispatch.scenario import load_scenario

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
