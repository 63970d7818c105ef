"""Lazy exact costs (``[dispatch] lazy_costs``): decisions on lower bounds, certified optimal.

Independent answers: scipy's ``linear_sum_assignment`` on the full exact matrix (the planner's
distance fields, computed on a copy of the world so that no field reaches the lazy planner),
with a penalty for infeasible pairs large enough that the number of pairs comes first; runs
with the option off; the invariant checks of ``test_invariants.py`` on runs with it on.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

import tests.dispatch.test_invariants as inv
from allocators.hungarian import HungarianAllocator
from dispatch.api.problem import AgentView, AllocationProblem, TaskView
from dispatch.decide.answers import validate
from dispatch.decide.lazy import certify, in_time, resolve_open
from dispatch.errors import ScenarioError
from dispatch.scenario.load import load_scenario
from planners.astar import AStarPlanner
from tests.conftest import write_scenario
from tests.planners.test_astar import random_world

BIG = 1e7  # above any total of finite costs in these worlds (seconds)


def reference(cost: np.ndarray) -> tuple[int, float]:
    """``(pairs, total)`` of a maximum-cardinality, then minimum-cost assignment (scipy)."""
    if not cost.size:
        return 0, 0.0
    r, c = linear_sum_assignment(np.where(np.isfinite(cost), cost, BIG))
    keep = np.isfinite(cost[r, c])
    return int(keep.sum()), float(cost[r[keep], c[keep]].sum())


def lazy_decision(planner, agents, tasks, now: float, deadlines: np.ndarray):
    """What the dispatcher does with lazy costs: bounds, the deadline (exact feasibility per
    task), then the certificate loop with ``hungarian``. Returns ``(pairs, cost matrix,
    exact mask, rounds)``."""
    cost, exact = planner.bounds(agents, tasks)
    cost = np.where(in_time(cost, now, deadlines), cost, np.inf)
    exact = exact | ~np.isfinite(cost)

    def compute(rows, cols):
        return planner.exact(agents, tasks, rows, cols)

    resolve_open(cost, exact, compute, now, deadlines)
    hungarian = HungarianAllocator()

    def ask(c):
        problem = AllocationProblem(now, agents, tasks, np.array(c), np.ones((len(agents),) * 2,
                                    bool), np.random.default_rng(0))
        answer = hungarian.allocate(problem)
        return answer, validate(problem, answer)

    (_, index), rounds, _ = certify(ask, cost, exact, compute, now, deadlines)
    return index, cost, exact, rounds


def random_decision(seed: int):
    rng = np.random.default_rng(seed)
    world = random_world(seed, shape=tuple(int(v) for v in rng.integers(6, 14, 3)),
                         blocked=float(rng.choice([0.1, 0.25, 0.4])))
    nx, ny, nz = world.grid.shape
    n, m = int(rng.integers(1, 12)), int(rng.integers(1, 12))
    agents = []
    for i in range(n):
        flies = bool(rng.random() < 0.7)
        agents.append(AgentView(i, "uav" if flies else "ugv",
                                (int(rng.integers(nx)), int(rng.integers(ny)),
                                 int(rng.integers(nz)) if flies else 0),
                                float(rng.choice([1.0, 3.0, 5.0]))))
    tasks, deadlines = [], []
    now = 10.0
    for j in range(m):
        ground = bool(rng.random() < 0.4)
        d = math.inf if rng.random() < 0.4 else now + float(rng.uniform(0.5, 8.0))
        tasks.append(TaskView(j, "ground" if ground else "air",
                              (int(rng.integers(nx)), int(rng.integers(ny)),
                               0 if ground else int(rng.integers(nz))), 0.0, deadline=d))
        deadlines.append(d)
    return seed, world, tuple(agents), tuple(tasks), now, np.array(deadlines)


@pytest.mark.parametrize("seed", range(60))
def test_lazy_decision_is_optimal_for_the_exact_matrix(seed):
    """Same number of pairs and the same total exact cost (1e-9) as scipy on the full exact
    matrix with the deadlines applied; every chosen pair exact and in time; a task has a
    feasible pair in the lazy matrix iff it has one in the exact matrix."""
    seed, world, agents, tasks, now, deadlines = random_decision(seed)
    exact_cost = AStarPlanner(_copy(world)).costs(agents, tasks)
    exact_cost = np.where(in_time(exact_cost, now, deadlines), exact_cost, np.inf)
    planner = AStarPlanner(world)
    index, cost, exact, rounds = lazy_decision(planner, agents, tasks, now, deadlines)
    want_pairs, want_total = reference(exact_cost)
    assert len(index) == want_pairs
    assert all(exact[i, j] for i, j in index)
    got = np.array([exact_cost[i, j] for i, j in index])
    assert np.isfinite(got).all()
    assert float(got.sum()) == pytest.approx(want_total, rel=1e-9, abs=1e-9)
    np.testing.assert_allclose([cost[i, j] for i, j in index], got, rtol=1e-12)
    assert np.array_equal(np.isfinite(cost).any(axis=0), np.isfinite(exact_cost).any(axis=0))
    assert rounds >= 1


def _copy(world):
    """The same world on a new grid (its own, empty cache)."""
    from dispatch.api.voxels import Grid
    from dispatch.space.world import World

    return World(size=world.size, grid=Grid(np.array(world.grid.occupied), world.grid.cell),
                 boxes=())


def test_lazy_decisions_compute_few_pairs():
    """Over the random decisions, the certificate computes far fewer pairs than the matrix
    has UAV entries (the point of it) and sometimes needs more than one round."""
    computed = entries = 0
    rounds = []
    for seed in range(60):
        seed, world, agents, tasks, now, deadlines = random_decision(seed)
        planner = AStarPlanner(world)
        rounds.append(lazy_decision(planner, agents, tasks, now, deadlines)[3])
        computed += planner.stats.extra["astar_pairs"]
        entries += sum(a.flies for a in agents) * len(tasks)
    assert computed < entries / 3
    assert max(rounds) > 1


# ------------------------------------------------------------------- whole runs


def _lazy(path, on: bool = True):
    text = path.read_text(encoding="utf-8").replace(
        "[dispatch]\n", f"[dispatch]\nlazy_costs = {'true' if on else 'false'}\n", 1)
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("seed", range(6))
def test_first_decision_and_terminal_states_match_exact_costs(tmp_path, seed):
    """A trace released at once (some tasks inside obstacles: unreachable; a short max_wait:
    some rejected), decided once with lazy costs and once without: the same first-decision
    cost (1e-9) and the same tasks unreachable and rejected."""
    rng = np.random.default_rng(seed)
    n = 24
    rows = ["release_time,x,y,z"] + [
        f"0.0,{rng.uniform(0, 11.99)!r},{rng.uniform(0, 11.99)!r},"
        f"{(0.2 if rng.random() < 0.5 else rng.uniform(0, 5.99))!r}" for _ in range(n)]
    out = {}
    for on in (False, True):
        d = tmp_path / str(on)
        d.mkdir()
        (d / "trace.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
        path = write_scenario(d, seed=seed, duration=60.0,
                              obstacles={"count": 6, "min_size": [1, 1, 6],
                                         "max_size": [3, 3, 6]},
                              fleet={"agents": 6, "uav_fraction": 0.5},
                              tasks={"source": "trace", "trace": "trace.csv",
                                     "ground_fraction": None, "max_wait": 2.5},
                              dispatch={"batch_window": 0.5})
        out[on] = inv.run_scenario(_lazy(path, on))
    off, lazy = out[False], out[True]
    assert lazy.summary["first_decision_cost"] == pytest.approx(
        off.summary["first_decision_cost"], rel=1e-9)
    for state in ("unreachable", "rejected"):
        a = set(off.tasks.task_id[off.tasks.state == state])
        b = set(lazy.tasks.task_id[lazy.tasks.state == state])
        assert a == b, state


@pytest.mark.parametrize("seed", range(3))
def test_a_walled_in_pocket_is_unreachable_with_lazy_costs(tmp_path, monkeypatch, seed):
    """Tasks in a free column walled in on every side (no obstacle at their cell: only the
    components tell) end ``unreachable``, as with exact costs; the others are served."""
    from dispatch.api.voxels import Grid
    from dispatch.space import world as sim  # the voxel space's module builds (and caches) worlds
    from dispatch.space.world import World

    real = sim.build_world

    def walled(*args, **kw):
        w = real(*args, **kw)
        occ = np.array(w.grid.occupied)
        occ[4:7, 4:7, :] = True
        occ[5, 5, :] = False  # the pocket
        return World(size=w.size, grid=Grid(occ, w.grid.cell), boxes=w.boxes)

    monkeypatch.setattr(sim, "build_world", walled)
    sim.world_for.cache_clear()
    rows = ["release_time,x,y,z", "0.0,5.5,5.5,0.5", "0.0,5.5,5.5,3.5", "1.0,1.5,1.5,0.5",
            "1.0,10.5,9.5,2.5", "2.0,5.5,5.5,2.5"]
    states = {}
    try:
        for on in (False, True):
            d = tmp_path / str(on)
            d.mkdir()
            (d / "trace.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
            path = write_scenario(d, seed=seed, duration=120.0,
                                  world={"physics": False},
                                  obstacles={"count": 2, "min_size": [1, 1, 1],
                                             "max_size": [2, 2, 2]},
                                  fleet={"agents": 4, "uav_fraction": 0.5},
                                  tasks={"source": "trace", "trace": "trace.csv",
                                         "ground_fraction": None})
            r = inv.run_scenario(_lazy(path, on))
            if (r.vehicles.x0.between(5, 6) & r.vehicles.y0.between(5, 6)).any():
                pytest.skip("a vehicle starts in the pocket")
            states[on] = dict(zip(r.tasks.task_id, r.tasks.state))
    finally:
        sim.world_for.cache_clear()
    assert states[True] == states[False]
    assert [states[True][t] for t in sorted(states[True])] == [
        "unreachable", "unreachable", "completed", "completed", "unreachable"]


@pytest.fixture(scope="module")
def lazy_runs(tmp_path_factory):
    """The invariant module's random scenarios (hungarian) with lazy costs on."""
    out = {}
    for source in inv.SOURCES:
        for seed in inv.SEEDS:
            d = tmp_path_factory.mktemp(f"lazy_{source}_{seed}")
            path = _lazy(inv.random_scenario(d, source, "hungarian", seed))
            out[(source, "hungarian", seed)] = inv.run_scenario(path)
    return out


LAZY_CASES = [(s, "hungarian", seed) for s in inv.SOURCES for seed in inv.SEEDS]
CHECKS = [inv.test_every_task_ends_in_exactly_one_terminal_state,
          inv.test_no_task_is_held_by_two_vehicles, inv.test_a_vehicle_serves_one_task_at_a_time,
          inv.test_summary_counts_add_up, inv.test_vehicles_move_by_legal_timed_steps,
          inv.test_ugvs_stay_on_the_ground_and_serve_ground_tasks]


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__[5:] for c in CHECKS])
def test_lazy_runs_keep_every_invariant(lazy_runs, check):
    for case in LAZY_CASES:
        check(lazy_runs, case)
    states = set().union(*(set(r.tasks.state) for r in lazy_runs.values()))
    assert {"completed", "expired", "unreachable"} <= states


def test_lazy_costs_must_be_a_boolean(tmp_path):
    path = write_scenario(tmp_path, dispatch={"lazy_costs": "yes"})
    with pytest.raises(ScenarioError, match="lazy_costs.*true or false") as e:
        load_scenario(path)
    assert "\n" not in str(e.value)


def test_lazy_costs_without_support_fall_back_with_a_warning(tmp_path, caplog):
    """``greedy`` does not minimize the total cost: the run uses exact costs (the same
    result as without the option) and says so."""
    results = []
    for on in (False, True):
        d = tmp_path / str(on)
        d.mkdir()
        path = write_scenario(d, dispatch={"allocator": "greedy", "lazy_costs": on})
        with caplog.at_level(logging.WARNING, logger="dispatch.decide.planner_costs"):
            results.append(inv.run_scenario(path))
    assert "lazy_costs is on but" in caplog.text
    assert results[0].summary["total_cost"] == results[1].summary["total_cost"]


def test_check_planner_checks_the_bounds():
    """``check_planner`` passes ``astar``'s bounds and catches bounds above the costs and
    exact marks on entries that are not exact."""
    from dispatch.checks.planners import check_planner

    assert check_planner(AStarPlanner).ok

    class TooHigh(AStarPlanner):
        def bounds(self, agents, tasks):
            lower, known = super().bounds(agents, tasks)
            return lower * 1.5 + 0.1, known

    class FalselyExact(AStarPlanner):
        def bounds(self, agents, tasks):
            lower, known = super().bounds(agents, tasks)
            return lower * 0.5, np.ones_like(known)

    for cls, why in ((TooHigh, "above its cost"), (FalselyExact, "marked exact")):
        report = check_planner(cls)
        assert not report.ok
        assert why in str(report)
