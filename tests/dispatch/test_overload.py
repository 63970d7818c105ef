"""Overload without a cliff (dispatch.decide.candidates): past CUT_TASKS open tasks a decision
offers
each vehicle its nearest tasks and the oldest, counted in the ``decisions`` table's ``n_cut``;
at or below it nothing changes. The cut against a brute force, and the overloaded batches of
the fuzz run (Poisson and trace, few vehicles) finishing with the cut counted."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from dispatch.decide.candidates import CUT_TASKS, NEAREST, considered, cut, per_vehicle
from dispatch.run.runner import run_one
from dispatch.scenario.load import check_limits, load_scenario
from tests.conftest import write_scenario


class PointSpace:
    """A space whose locations are their own positions (metres)."""

    @staticmethod
    def positions(locs) -> np.ndarray:
        return np.asarray(locs, dtype=float).reshape(-1, 3)


def tasks_at(points) -> list:
    return [SimpleNamespace(id=100 + i, loc=tuple(map(float, p))) for i, p in enumerate(points)]


def agents_at(points) -> list:
    return [SimpleNamespace(loc=tuple(map(float, p))) for p in points]


def brute_force(tasks, agents, keep=()) -> list:
    """Each agent's k nearest by (squared distance, position in the list), the first n, and
    the tasks of ``keep``: in list order."""
    k, n = per_vehicle(len(agents)), len(agents)
    chosen = set(range(n)) | {i for i, t in enumerate(tasks) if t.id in keep}
    for a in agents:
        d2 = [sum((x - y) ** 2 for x, y in zip(t.loc, a.loc)) for t in tasks]
        chosen |= set(sorted(range(len(tasks)), key=lambda i: (d2[i], i))[:k])
    return [tasks[i] for i in sorted(chosen)]


@pytest.mark.parametrize("seed", range(4))
def test_cut_keeps_each_vehicles_nearest_and_the_oldest(seed):
    rng = np.random.default_rng(seed)
    m, n = CUT_TASKS + 1 + int(rng.integers(600)), int(rng.integers(1, 6))
    # integer positions on a small lattice: many ties in distance at the k-th place
    tasks = tasks_at(rng.integers(0, 12, size=(m, 3)))
    agents = agents_at(rng.integers(0, 12, size=(n, 3)))
    keep = {t.id for t in rng.choice(tasks, 5, replace=False)}
    kept, left = cut(tasks, agents, PointSpace(), keep)
    expected = brute_force(tasks, agents, keep)
    assert [t.id for t in kept] == [t.id for t in expected]
    assert left == m - len(kept) > 0
    assert len(kept) <= n * (per_vehicle(n) + 1) + len(keep)
    assert considered(m, n) == min(m, n * (per_vehicle(n) + 1))


def test_cut_leaves_small_decisions_alone():
    rng = np.random.default_rng(7)
    tasks = tasks_at(rng.random((CUT_TASKS, 3)) * 50)
    agents = agents_at(rng.random((4, 3)) * 50)
    kept, left = cut(tasks, agents, PointSpace())
    assert kept is tasks and left == 0  # at the bound: the very list, nothing cut
    assert considered(CUT_TASKS, 4) == CUT_TASKS
    more = tasks + tasks_at(rng.random((1, 3)) * 50)
    many = agents_at(rng.random(((CUT_TASKS + 1) // 2, 3)) * 50)  # 2 n nearest >= every task
    kept, left = cut(more, many, PointSpace())
    assert kept is more and left == 0
    assert per_vehicle(1) == NEAREST and per_vehicle(100) == 200


PAPER_WORLD = {"size": [50, 50, 30], "cell": 1.0}
PAPER_OBSTACLES = {"count": 10, "min_size": [3, 3, 5], "max_size": [10, 10, 30]}


def overload(tmp_path, source: str):
    """The fuzz family shrunk to seconds: thousands of open tasks, 4 vehicles, batched 1 s,
    in a small voxel world (a Poisson stream of 1,000 tasks/s that live 120 s, or a trace of
    as many rows)."""
    if source == "poisson":
        tasks = {"source": "poisson", "rate": 1000.0, "ttl": 120.0}
    else:
        rng = np.random.default_rng(0)
        rows = ["t,x,y,z"] + [f"{i / 1000:.4f},{x + 0.5},{y + 0.5},{z + 0.5}"
                              for i, (x, y, z) in enumerate(zip(rng.integers(12, size=4000),
                                                                rng.integers(12, size=4000),
                                                                rng.integers(6, size=4000)))]
        (tmp_path / "trips.csv").write_text("\n".join(rows) + "\n")
        tasks = {"source": "trace", "trace": "trips.csv", "max_wait": 120.0,
                 "ground_fraction": None}
    return write_scenario(tmp_path, duration=4.0, fleet={"agents": 4}, tasks=tasks,
                          dispatch={"batch_window": 1.0})


@pytest.mark.parametrize("source", ["poisson", "trace"])
def test_an_overloaded_batch_is_decided_over_candidates_and_counts_them(tmp_path, source):
    sc = load_scenario(overload(tmp_path, source))
    specs = sc.runs()
    check_limits(sc, specs)  # within the budget: the cut bounds each decision
    r = run_one(specs[0])
    dec = r.tables["decisions"].to_pandas()
    assert "n_cut" in dec.columns
    cut_rows = dec[dec.n_cut > 0]
    assert len(cut_rows) >= 2, dec[["t", "n_tasks", "n_cut"]]
    assert (cut_rows.n_tasks <= 4 * (per_vehicle(4) + 1)).all()
    # the open tasks a decision saw: those offered plus those left out (and any it found
    # unreachable); past the bound only
    assert (cut_rows.n_tasks + cut_rows.n_cut > CUT_TASKS).all()
    assert (dec[dec.n_cut == 0].n_tasks <= CUT_TASKS).all()  # uncut: the whole problem
    assert (dec[dec.t <= 1.0 + 1e-9].n_cut == 0).all()  # about 1,000 open at t = 1 s
    assert r.summary["decisions"] == len(dec)
