"""A small sweep shared by the analysis tests: 3 allocators x N in {2, 3} x 3 seeds on the tiny
12 x 12 x 6 m world (static tasks, half in the air, 0.5 s of service each), run once per
session in this process."""

from __future__ import annotations

from pathlib import Path

import pytest

from dispatch.run.runner import sweep
from dispatch.scenario.load import load_scenario
from tests.conftest import write_scenario

SWEEP = {"allocator": ["hungarian", "greedy", "random"], "agents": [2, 3], "seed": [0, 1, 2]}


@pytest.fixture(scope="session")
def small_sweep(tmp_path_factory) -> Path:
    """The folder of the small sweep (Hive layout, one partition per run)."""
    d = tmp_path_factory.mktemp("small_sweep")
    scenario = write_scenario(d, sweep=SWEEP, tasks={"count": 4, "service_time": 0.5})
    out = d / "out"
    outcomes = sweep(load_scenario(scenario).runs(), out, workers=1)
    assert all(o.status == "done" for o in outcomes), [o.error for o in outcomes]
    return out


@pytest.fixture(scope="session")
def single_run(tmp_path_factory) -> Path:
    """The folder of one busy dynamic run (``dispatch run``: the same Hive layout as a sweep,
    one partition): Poisson tasks, some expire."""
    from dispatch.run.runner import execute

    d = tmp_path_factory.mktemp("single_run")
    scenario = write_scenario(d, fleet={"agents": 3},
                              tasks={"source": "poisson", "rate": 2.0, "count": 16,
                                     "max_active": 4, "ttl": 2.0, "service_time": 1.0},
                              duration=60.0)
    out = d / "run"
    execute(load_scenario(scenario).runs(seed=2), out)
    return out
