"""The view model on taxi views (allocators/magnnet/view_taxi.py): DAgger on decisions of a
road day under a radio range, and the plugin's choice of view weights (``view_weights``)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from allocators.magnnet import view_taxi, views
from allocators.magnnet.allocator import MagnnetAllocator, shipped
from allocators.magnnet.ppo import load_checkpoint
from dispatch.api.problem import AgentView, AllocationProblem, TaskView

ROOT = Path(__file__).resolve().parents[2]
MANHATTAN = ROOT / "scenarios" / "manhattan.toml"


def _decisions():
    return view_taxi.taxi_decisions(MANHATTAN, 30, 100, windows=((0.0, 0.3),), every=1,
                                    radio_range=300.0)


def test_recorded_decisions_are_plain_copies_under_the_range():
    probs = _decisions()
    assert probs
    for p in probs:
        assert not p.agents.lazy and not p.comm.all()
        assert np.isfinite(p.cost).any()
    # an allocator decides a recorded decision after the run moved on
    r = view_taxi.decision_gaps(MagnnetAllocator(view_weights="view"), probs[:3])
    assert len(r["gaps"]) == 3 and 0 < r["pairs"] <= 1


def test_label_with_own_ties_gives_the_view_owner_its_tied_task():
    # two agents at one node (equal costs) and one task: each one's view says "mine"
    agents = tuple(AgentView(i, "ugv", (i, 0, 0), 3.0) for i in range(2))
    tasks = (TaskView(7, "ground", (0, 1, 0), 0.0),)
    p = AllocationProblem(0.0, agents, tasks, np.array([[60.0], [60.0]]),
                          np.ones((2, 2), bool), np.random.default_rng(0))
    alloc = SimpleNamespace(requests=())
    members, t = np.array([0, 1]), np.array([0])
    recs = [(0, members, t, np.array([0, 1]), np.ones(2, bool)),
            (0, members, t, np.array([1, 0]), np.ones(2, bool))]
    plain = views.label(p, alloc, recs)
    assert [s[5][0] for s in plain] == [0, 0]  # the teacher's arbitrary pick, both views
    own = views.label(p, alloc, recs, own_ties=True)
    assert [s[5][0] for s in own] == [0, 1]  # each view: its owner
    assert own[0][4].tolist() == [0, 1] and own[1][4].tolist() == [1, 0]


def test_label_sends_a_teacher_pair_cut_from_the_view_to_the_null_heads():
    # the teacher gives task 0 to agent 0 and task 1 to agent 1; the recorded view (as the
    # model read it) cut the edge (0, 0): agent 0's target is "none of mine", task 0's agent
    # "not in this view"; the uncut pair keeps its labels
    agents = tuple(AgentView(i, "ugv", (i, 0, 0), 3.0) for i in range(2))
    tasks = (TaskView(7, "ground", (0, 1, 0), 0.0), TaskView(8, "ground", (1, 1, 0), 0.0))
    cost = np.array([[10.0, 50.0], [50.0, 10.0]])
    p = AllocationProblem(0.0, agents, tasks, cost, np.ones((2, 2), bool),
                          np.random.default_rng(0))
    alloc = SimpleNamespace(requests=())
    members, t = np.array([0, 1]), np.array([0, 1])
    seen = np.array([[np.inf, 0.5], [0.5, 0.1]])
    full = views.label(p, alloc, [(0, members, t, np.array([0, 1]), np.ones(2, bool))])
    assert full[0][4].tolist() == [0, 1] and full[0][5].tolist() == [0, 1]
    cut = views.label(p, alloc, [(0, members, t, np.array([0, 1]), np.ones(2, bool), seen)])
    assert cut[0][4].tolist() == [2, 1]  # row 0: the null head (index = number of tasks)
    assert cut[0][5].tolist() == [2, 1]  # column 0: the outside head (number of members)
    assert np.isinf(cut[0][0][0, 0])  # the cost is the view's, as the model read it


def test_taxi_stage_trains_on_a_tiny_day_and_the_plugin_loads_it(tmp_path):
    from allocators.magnnet.train import main

    out = tmp_path / "vt"
    rc = main(["--variant", "view", "--taxi", "--taxi-scenario", str(MANHATTAN),
               "--taxi-agents", "30", "--taxi-seeds", "100", "--taxi-val-seed", "110",
               "--taxi-windows", "0-0.3", "--taxi-every", "1", "--taxi-range", "300",
               "--iterations", "1", "--episodes", "2", "--updates", "2", "--threads", "1",
               "--out", str(out)])
    assert rc == 0
    assert (out / "model.pt").is_file() and (out / "loss.png").is_file()
    model, ck = load_checkpoint(out / "model.pt")
    assert model.variant == "view" and ck["extra"]["radio_range"] == 300.0
    alloc = MagnnetAllocator(taxi_view_checkpoint=str(out / "model.pt"))
    assert "model.pt" in alloc.files and "view.pt" in alloc.files
    p = _decisions()[0]
    assert alloc.allocate(p).pairs
    with pytest.raises(SystemExit):  # the evaluation's seeds stay out of training
        main(["--variant", "view", "--taxi", "--taxi-seeds", "2", "--out", str(out)])


def _problem(scale: float) -> AllocationProblem:
    """Eight agents on a line (each hears its neighbours: partial views), six tasks; costs of
    seconds times ``scale``."""
    rng = np.random.default_rng(3)
    n, m = 8, 6
    agents = tuple(AgentView(i, "ugv", (2 * i, 0, 0), 3.0) for i in range(n))
    tasks = tuple(TaskView(j, "ground", (2 * j, 1, 0), 0.0) for j in range(m))
    cost = (np.abs(np.arange(n)[:, None] - np.arange(m)[None, :]) + 1
            + rng.random((n, m))) * scale
    comm = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :]) <= 1
    return AllocationProblem(0.0, agents, tasks, cost, comm, np.random.default_rng(0))


@pytest.mark.parametrize("weights, scale, want", [
    ("auto", 1.0, "view"),     # seconds, as the training instances: view.pt
    ("auto", 60.0, "taxi"),    # minutes, a city's taxis: view_taxi.pt
    ("view", 60.0, "view"),
    ("taxi", 1.0, "taxi"),
])
def test_view_weights_pick_the_model_that_scores_partial_views(weights, scale, want):
    from allocators.magnnet.allocator import load_model

    plain = load_model(shipped("view"), "magnnet", ("view",))[0]  # the cached view.pt model
    alloc = MagnnetAllocator(view_weights=weights, view_hops=2)
    if weights == "auto":  # the shipped pair: two files, two models
        assert alloc.view_model is not alloc.taxi_view_model
        assert {"view.pt", "view_taxi.pt"} <= set(alloc.files)
    used = []

    def spy(model, vs):
        vs = list(vs)
        used.extend(["view" if model is plain else "taxi"] * len(vs))
        return views.view_scores_many(model, vs)

    alloc._views_mod = SimpleNamespace(hops_from=views.hops_from, view_request=views.view_request,
                                       view_scores_many=spy)
    alloc.allocate(_problem(scale))
    assert used and set(used) == {want}


def test_view_weights_must_be_known():
    with pytest.raises(TypeError, match="view_weights"):
        MagnnetAllocator(view_weights="taxis")
