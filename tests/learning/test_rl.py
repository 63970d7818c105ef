"""learning.rl: the Gymnasium and PettingZoo environments over the simulator's decisions."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")

from allocators.hungarian import HungarianAllocator
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from learning.rl import DispatchEnv, FleetEnv, pairs_from_choices

ROOT = Path(__file__).resolve().parents[2]
MANHATTAN = ROOT / "scenarios" / "manhattan.toml"
#: summary columns that are wall-clock times or name the decider
WALL = {"allocator", "alloc_seconds", "cost_seconds", "decide_seconds",
        "first_decision_seconds", "agent_seconds", "allocator_info"}


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def test_dispatch_env_passes_gymnasium_checker():
    """The checker passes; its only remarks are that some Box bounds are infinite, which they
    are by design (the clock, waits, slack and costs have no upper bound): expected here, so
    the test output shows no warning (gymnasium writes it with raw colour codes)."""
    import warnings

    from gymnasium.utils.env_checker import check_env

    env = DispatchEnv(MANHATTAN, seed=0, batch_window=30.0, max_tasks=16)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    said = {str(w.message) for w in caught}
    assert said and all("maximum value is infinity" in m for m in said), said


def test_fleet_env_passes_pettingzoo_parallel_api_test():
    from pettingzoo.test import parallel_api_test

    env = FleetEnv(MANHATTAN, seed=0, batch_window=30.0, max_tasks=8)
    parallel_api_test(env, num_cycles=300)


def _trajectory(seed: int, steps: int = 40):
    env = DispatchEnv(MANHATTAN, seed=seed, batch_window=30.0, max_tasks=16)
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(7)
    out = [obs]
    for _ in range(steps):
        obs, r, term, trunc, _ = env.step(env.action_space.sample())
        out.append((obs, r))
        if term or trunc:
            break
    return out


def test_same_seed_same_trajectory():
    from gymnasium.utils.env_checker import data_equivalence

    a, b = _trajectory(3), _trajectory(3)
    assert len(a) == len(b) > 1
    assert data_equivalence(a, b)  # (this scenario's trace and start file fix the day)


def test_stepping_hungarian_reproduces_a_hungarian_run():
    env = DispatchEnv(MANHATTAN, seed=0, batch_window=30.0, max_tasks=64)
    env.reset()
    hungarian = HungarianAllocator()
    done, steps, total = False, 0, 0.0
    while not done:
        problem = env.problem
        assert problem.n_tasks <= 64 and problem.n_agents <= env.max_agents
        _, r, term, trunc, _ = env.step(env.action_of(hungarian.allocate(problem)))
        done, steps, total = term or trunc, steps + 1, total + r
    assert env.problem is None and steps > 50
    sc = load_scenario(MANHATTAN)
    sc = replace(sc, dispatch=replace(sc.dispatch, batch_window=30.0),
                 sweep=replace(sc.sweep, allocator=()))
    ref = run_one(sc.runs(allocator="hungarian", seed=0)[0]).summary
    got = env.summary
    assert got["allocator"] == "rl"
    differ = {k: (got.get(k), v) for k, v in ref.items()
              if k not in WALL and not _same(got.get(k), v)}
    assert not differ
    assert got["tasks_completed"] > 0 and total > 0


def test_choices_settle_conflicts_by_cost_and_ignore_infeasible_pairs():
    env = DispatchEnv(MANHATTAN, seed=0, batch_window=30.0, max_tasks=16)
    env.reset()
    p = env.problem
    assert p.n_agents >= 2 and p.n_tasks >= 1
    c = np.asarray(p.cost[:, 0])
    order = np.argsort(c)
    choice = np.zeros(p.n_agents, np.int64)
    choice[order[:2]] = 1  # both ask for request 0: the cheaper wins
    alloc = pairs_from_choices(p, choice)
    assert alloc.pairs == ((int(p.agent_ids[order[0]]), int(p.task_ids[0])),)
    choice[:] = p.n_tasks + 5  # out of range: ignored
    assert pairs_from_choices(p, choice).pairs == ()


def test_fleet_env_local_views_and_masks():
    env = FleetEnv(MANHATTAN, seed=0, batch_window=30.0, max_tasks=8)
    obs, infos = env.reset()
    p = env.problem
    idle = {f"vehicle_{a}" for a in p.agent_ids.tolist()}
    for name in env.agents:
        o, mask = obs[name], infos[name]["action_mask"]
        assert env.observation_space(name).contains(o)
        assert o[2] == (1.0 if name in idle else 0.0)
        if name not in idle:
            assert mask.tolist() == [1] + [0] * 8
    # every idle vehicle asks for its cheapest request: one winner per request
    actions = {}
    for name in env.agents:
        mask = infos[name]["action_mask"]
        own = obs[name][7:15]
        ok = mask[1:].astype(bool)
        actions[name] = int(np.argmin(np.where(ok, own, np.inf))) + 1 if ok.any() else 0
    _, rewards, term, _, _ = env.step(actions)
    assert set(rewards) == set(env.agents) and not any(term.values())
