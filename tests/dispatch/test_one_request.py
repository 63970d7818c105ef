"""The one-request decision without the general problem (dispatch.decide.one_request): the
answer every allocator that declares ``one_by_minimum`` gives, and the same results as the
general path on every shipped road scenario."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from allocators.fcfs import FcfsAllocator
from allocators.hungarian import HungarianAllocator
from dispatch.api.problem import AgentView, AgentViews, Allocation, AllocationProblem, TaskView
from dispatch.decide import one_request, pipeline
from dispatch.run.runner import execute
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_determinism import TABLES, bitwise, read_run, without_timing

ROOT = Path(__file__).resolve().parents[2]
#: the shipped scenarios on road networks
ROAD = sorted(p.name for p in (ROOT / "scenarios").glob("*.toml")
              if "\nnetwork =" in p.read_text())
DECLARED = [FcfsAllocator(), HungarianAllocator()]


def test_declarations():
    """fcfs and hungarian declare it; hungarian with a learned value does not (its costs are
    adjusted), nor does an allocator that says nothing."""
    assert all(a.one_by_minimum for a in DECLARED)
    from allocators.greedy import GreedyAllocator

    assert not GreedyAllocator.one_by_minimum


def column_problem(cost: np.ndarray, ids: np.ndarray) -> AllocationProblem:
    agents = AgentViews.of([AgentView(int(i), "car", 0, 1.0) for i in ids])
    tasks = (TaskView(7, "trip", 0, 0.0),)
    return AllocationProblem.made(0.0, agents, tasks, cost, np.ones((len(ids), len(ids)), bool),
                                  np.random.default_rng(0), max_rounds=1, loss=0.0, latency=0.0,
                                  cell_size=1.0, agent_pos=np.zeros((len(ids), 3)),
                                  task_pos=np.zeros((1, 3)))


@pytest.mark.parametrize("seed", range(200))
def test_decided_is_each_declared_allocators_answer(seed):
    """On random columns (ties, inf entries, all inf) the answer is the one each allocator
    that declares ``one_by_minimum`` gives, value and (row, column) hint alike."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 30))
    cost = rng.integers(0, 5, (n, 1)).astype(float)  # few values: many ties
    cost[rng.random(n) < rng.random()] = np.inf
    ids = np.sort(rng.choice(1000, n, replace=False))
    problem = column_problem(cost, ids)
    d = SimpleNamespace(now=0.0, cost=cost, agents=problem.agents,
                        requests=[SimpleNamespace(id=7)], make=lambda c: problem, n_idle=None)
    got = one_request.decided(d)
    for allocator in DECLARED:
        want = allocator.allocate(problem)
        assert isinstance(want, Allocation)
        assert got.allocation == want, allocator.name
        assert got.allocation.index == want.index, allocator.name
    assert got.problem.n_agents == n and got.problem.n_tasks == 1
    assert got.problem.comm is problem.comm  # anything else: the general problem's


def run_tables(name: str, out: Path, general: bool, monkeypatch, allocator) -> tuple:
    """The tables of the first run of scenario ``name`` (its first 20 simulated minutes;
    ``allocator``: that one instead of the file's) and the one-request decisions it took, on
    the general path or not."""
    monkeypatch.setattr(one_request, "GENERAL", general)
    taken = []
    real = pipeline.decided

    def counted(d):
        taken.append(1)
        return real(d)

    monkeypatch.setattr(pipeline, "decided", counted)
    scenario = load_scenario(ROOT / "scenarios" / name, ignore_limits=True,
                             overrides=[("duration", "1200.0", "test")])
    specs = scenario.runs(allocator=allocator)
    execute(specs[:1], out)
    return read_run(out), len(taken)


@pytest.mark.parametrize("allocator", [None, "fcfs", "hungarian"])
@pytest.mark.parametrize("name", ROAD)
def test_same_results_as_the_general_path(tmp_path, monkeypatch, name, allocator):
    """Every shipped road scenario (its own allocator, fcfs and hungarian; its first 20 simulated
    minutes) gives the same tables on both paths."""
    general, n_general = run_tables(name, tmp_path / "general", True, monkeypatch, allocator)
    fast, n_fast = run_tables(name, tmp_path / "fast", False, monkeypatch, allocator)
    assert n_general == 0
    assert n_fast <= fast["decisions"].column("n_tasks").to_pylist().count(1)
    assert_same_tables(general, fast)


def assert_same_tables(a: dict, b: dict) -> None:
    """Two runs' tables (:func:`read_run`) hold the same values, bit for bit, wall-clock
    columns and ``allocator_info`` (rtv's solver seconds) aside."""
    for table in TABLES:
        x, y = (without_timing(t[table]) for t in (a, b))
        x, y = (t.drop_columns([c for c in ("allocator_info",) if c in t.column_names])
                for t in (x, y))
        assert bitwise(x).equals(bitwise(y)), table


def test_every_one_request_decision_takes_it(tmp_path, monkeypatch):
    """An immediate fcfs run decides each of its one-request decisions on the one-request
    path."""
    tables, n_fast = run_tables("manhattan.toml", tmp_path, False, monkeypatch, "fcfs")
    assert n_fast == tables["decisions"].column("n_tasks").to_pylist().count(1) > 0


def test_a_subclass_that_answers_itself_is_asked_every_time():
    """``one_by_minimum`` is not inherited by a subclass that overrides ``allocate`` (a spy,
    a variant): its own method is asked about one-request decisions too."""
    from allocators.hungarian import HungarianAllocator

    class Own(HungarianAllocator):
        def allocate(self, problem):
            return super().allocate(problem)

    class Same(HungarianAllocator):
        """Hungarian under another name."""

    class Declared(Own):
        one_by_minimum = True

    assert HungarianAllocator.one_by_minimum and Same.one_by_minimum
    assert not Own.one_by_minimum and Declared.one_by_minimum
