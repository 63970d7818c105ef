"""MAGNNET on partial views: the view model, its decision rule, its teacher labels, its DAgger
training, and the unified plugin (variants, loading in the constructor, what it records)."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from allocators.magnnet import allocator as mod  # noqa: E402
from allocators.magnnet.env import random_instance, random_pool  # noqa: E402
from allocators.magnnet.match import MatchPolicy, scores_of  # noqa: E402
from allocators.magnnet.views import (  # noqa: E402
    ViewConfig,
    ViewPolicy,
    label,
    play_problem,
    sub_problem,
    train_views,
    view_loss,
    view_request,
    view_scores,
)
from dispatch.api.decentralized import WAIT  # noqa: E402
from dispatch.errors import AllocationError  # noqa: E402
from tests.allocators.helpers import assert_valid, make_problem  # noqa: E402


def _line(n: int) -> np.ndarray:
    return np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)


def _models(seed: int = 0):
    torch.manual_seed(seed)
    match = MatchPolicy(hidden=8, layers=2).eval()
    view = ViewPolicy(hidden=8, layers=2).eval()
    return match, view


def test_view_model_starts_as_the_match_model():
    """``init_from`` copies the match network and weights the new inputs 0: on any view its
    edge scores are the match model's."""
    match, _ = _models(1)
    view = ViewPolicy(hidden=8, layers=2).init_from(match).eval()
    rng = np.random.default_rng(0)
    for n, m in ((3, 5), (6, 6), (7, 2)):
        cost, *_, flies, _ = random_instance(rng, n, m)
        hop = rng.integers(0, 3, n)
        s, _, _ = view_scores(view, cost, flies, hop, rng.random(n) < 0.7)
        np.testing.assert_allclose(s, scores_of(match, cost, flies), rtol=1e-5, atol=1e-5)


def test_view_request_hand_computed():
    s = np.array([[3.0, 0.0, -np.inf], [0.0, 2.0, 0.0]])
    no = np.full(2, -9.0), np.full(3, -9.0)
    # agent 0: best task 0, and task 0's best agent; both softmaxes ~0.95 >= 0.9
    assert view_request(s, *no, 0, 0.9, False) == 0
    # a confident "outside" head on task 0: agent 0 waits
    assert view_request(s, no[0], np.array([9.0, -9.0, -9.0]), 0, 0.5, False) == WAIT
    # not confident enough: wait; forced: request
    assert view_request(s, *no, 1, 0.99, False) == WAIT
    assert view_request(s, *no, 1, 0.99, True) == 1
    # forced, but the best scorer of task 1 stopped deciding: its other task (2)
    s2 = np.array([[0.0, 5.0, 0.0], [0.0, 2.0, 1.0]])
    assert view_request(s2, *no, 1, 0.5, True, active=np.array([False, True])) == 2
    assert view_request(np.full((1, 2), -np.inf), no[0][:1], no[1][:2], 0, 0.5, False) == -1


def test_teacher_labels_are_the_optimal_assignment_of_what_remains():
    """Round 1 after agent 0 won task 0: the teacher solves agents {1, 2} x tasks {1, 2};
    inactive rows and taken tasks point at the null heads."""
    from dispatch.api.problem import Allocation, Bid

    cost = np.array([[1.0, 9.0, 9.0], [9.0, 5.0, 1.0], [9.0, 1.0, 5.0]])
    p = make_problem(cost)
    p = dataclasses.replace(p, agents=tuple(dataclasses.replace(a, id=i)
                                            for i, a in enumerate(p.agents)),
                            tasks=tuple(dataclasses.replace(t, id=j)
                                        for j, t in enumerate(p.tasks)))
    alloc = Allocation(pairs=((0, 0),), requests=(Bid(0, 0, 0, 1.0, True),))
    views = [(1, np.array([0, 1, 2]), np.array([0, 1, 2]), np.array([1, 0, 1]),
              np.array([False, True, True]))]
    (_, _, _, _, rt, ct), = label(p, alloc, views)
    assert rt.tolist() == [3, 2, 1]        # agent 0 done: null; 1 -> task 2; 2 -> task 1
    assert ct.tolist() == [3, 2, 1]        # task 0 taken: outside; task 1 <- 2; task 2 <- 1


def test_decision_ignores_agents_beyond_two_hops():
    """Line 0-1-...-6: agent 0's request (view model, partial views) is the same whatever
    agents 3-6 look like (costs, kind, whether they still decide), and agent 2 matters."""
    match, view = _models(3)
    alloc = mod.MagnnetAllocator.with_models(match, view, view_confidence=0.0)
    n = 7
    rng = np.random.default_rng(4)
    base_cost = rng.uniform(1, 20, (n, n))

    def scores_and_request(cost, deciding=np.arange(n)):
        p = dataclasses.replace(make_problem(cost), comm=_line(n))
        req = int(alloc.choose(p, deciding, np.ones(n, bool), 0)[0])
        members = np.arange(3)
        s, _, _ = view_scores(view, cost[members], np.array([a.flies for a in p.agents])[:3],
                              np.array([0, 1, 2]), np.isin(members, deciding))
        return s[0], req

    s0, base = scores_and_request(base_cost)
    for far in (3, 4, 5, 6):
        c = base_cost.copy()
        c[far] = rng.uniform(0.1, 30, n)
        s, req = scores_and_request(c)
        assert req == base
        np.testing.assert_array_equal(s, s0)
    s, req = scores_and_request(base_cost, np.array([0, 1, 2, 5]))
    assert req == base
    c = base_cost.copy()
    c[2] = rng.uniform(0.1, 30, n)
    assert not np.allclose(scores_and_request(c)[0], s0)


def test_partial_views_with_loss_assign_every_task():
    """Shipped models, 30 % message loss, random sparse graphs and no links at all: valid
    answers, and with N >= M every task assigned."""
    alloc = mod.MagnnetAllocator()
    rng = np.random.default_rng(5)
    for seed in range(12):
        m = int(rng.integers(2, 9))
        n = m + int(rng.integers(0, 3))
        cost, *_ = random_instance(rng, n, m)
        comm = rng.random((n, n)) < (0.0 if seed % 4 == 0 else 0.3)
        comm = comm | comm.T | np.eye(n, dtype=bool)
        p = dataclasses.replace(make_problem(cost, seed=seed), comm=comm, loss=0.3)
        assert len(assert_valid(p, alloc.allocate(p))) == m


def test_dagger_lowers_the_loss_on_a_fixed_seed():
    """Two short DAgger iterations on a tiny pool: valid rounds, views labelled, and the
    imitation loss on the collected views falls."""
    match, view = _models(0)
    pool = random_pool(0, 20, 8)
    cfg = ViewConfig(iterations=2, episodes=6, updates=40, batch=4, lr=3e-3, sizes=(6, 8),
                     ranges=(20.0,), loss_share=0.5, seed=0)

    def make(m):
        return mod.MagnnetAllocator.with_models(match, m, view_hops=2,
                                                view_confidence=cfg.confidence,
                                                view_patience=cfg.patience)

    p = sub_problem(pool, 0, 8, 20.0, 0.0, np.random.default_rng(0))
    alloc, views = play_problem(p, make(view))
    samples = label(p, alloc, views)
    assert samples and all(len(s[4]) == len(s[0]) for s in samples)
    with torch.no_grad():
        before = float(np.mean([view_loss(view, s).item() for s in samples]))
    rows = train_views(view, [pool], cfg, make)
    with torch.no_grad():
        after = float(np.mean([view_loss(view, s).item() for s in samples]))
    assert len([r for r in rows if r["phase"] == "dagger"]) == 80
    assert after < before


def _labelled_views(rng, sizes):
    """Hand-made labelled views of the given ``(n, m)`` sizes: some infeasible edges (one
    row with none), null targets on both sides, inactive agents."""
    out = []
    for n, m in sizes:
        cost = rng.uniform(1, 40, (n, m))
        cost[rng.random((n, m)) < 0.2] = np.inf
        cost[0] = np.inf
        active = rng.random(n) < 0.8
        rt = np.where(active, rng.integers(0, m + 1, n), m)
        out.append((cost, rng.random(n) < 0.5, rng.integers(0, 3, n), active, rt,
                    rng.integers(0, n + 1, m)))
    return out


@pytest.mark.parametrize("waste", [1.0, 1.5, 100.0])
def test_padded_batch_loss_is_the_mean_of_the_per_view_losses(waste):
    """The padded batch (one pass per group of similar views) gives the loss and the gradient
    of the per-view losses, whatever the grouping (``waste`` 100: one padded pass)."""
    from allocators.magnnet.view_batch import batch_loss, prepare

    torch.manual_seed(0)
    model = ViewPolicy(hidden=8, layers=2)
    for prm in model.parameters():  # non-zero everywhere (init zeroes nothing, but be sure)
        prm.data.add_(0.05 * torch.randn_like(prm))
    views = _labelled_views(np.random.default_rng(3),
                            [(2, 1), (5, 5), (3, 7), (12, 9), (1, 4), (8, 8), (20, 3)])
    ref = sum(view_loss(model, v) for v in views) / len(views)
    ref_grad = torch.autograd.grad(ref, list(model.parameters()))
    got = batch_loss(model, [prepare(v) for v in views], waste=waste)
    got_grad = torch.autograd.grad(got, list(model.parameters()))
    assert abs(got.item() - ref.item()) < 1e-5 * abs(ref.item())
    for a, b in zip(got_grad, ref_grad):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)


def test_models_load_in_the_constructor_and_describe_what_ran(monkeypatch):
    """After construction no file is read: a decision works with loading disabled. The
    description names the model, the variant and each file with its SHA-256."""
    mod.clear_model_cache()
    alloc = mod.MagnnetAllocator()

    def no_reads(*a, **k):
        raise AssertionError("a decision read a file")

    monkeypatch.setattr(mod, "_load", no_reads)
    monkeypatch.setattr(torch, "load", no_reads)
    cost = np.random.default_rng(0).uniform(1, 20, (5, 5))
    for comm in (np.ones((5, 5), bool), _line(5)):
        p = dataclasses.replace(make_problem(cost), comm=comm)
        assert len(assert_valid(p, alloc.allocate(p))) == 5
    info = alloc.describe()
    assert info["model"] == "magnnet-match+view" and info["variant"] == "match"
    files = dict(x.split("@") for x in info["checkpoint"].split(","))
    for name, sha in files.items():
        data = (mod.CHECKPOINTS / name).read_bytes()
        assert hashlib.sha256(data).hexdigest()[:16] == sha
    assert set(files) == {"match.pt", "view.pt", "view_taxi.pt"}  # view_weights = "auto"


@pytest.mark.parametrize("variant", ["paper", "paper_nb"])
def test_paper_variants_refuse_sizes_without_a_checkpoint(variant):
    alloc = mod.MagnnetAllocator(variant=variant)
    assert alloc.describe()["variant"] == variant
    assert sorted(alloc.paper) == mod.shipped_sizes(variant) == [4, 8, 12, 20]
    for n, m in ((5, 5), (4, 5)):
        with pytest.raises(AllocationError, match="no checkpoint for N="):
            alloc.allocate(make_problem(np.ones((n, m))))
    assert len(alloc.allocate(make_problem(np.random.default_rng(1).uniform(1, 9, (4, 4))))
               .pairs) >= 1


def test_bad_parameters_are_clear_errors():
    with pytest.raises(TypeError, match="variant must be one of match, paper, paper_nb"):
        mod.MagnnetAllocator(variant="auto")
    with pytest.raises(TypeError, match="partial"):
        mod.MagnnetAllocator(partial="edge")
    with pytest.raises(TypeError, match="view_confidence"):
        mod.MagnnetAllocator(view_confidence=-0.1)
    with pytest.raises(TypeError, match="apply to variant 'match' only"):
        mod.MagnnetAllocator(variant="paper", partial="match")
    with pytest.raises(ValueError, match="model of kind 'paper'"):
        mod.MagnnetAllocator(view_checkpoint=str(mod.CHECKPOINTS / "paper_n4.pt"))


def test_run_summary_and_metadata_record_the_model(tmp_path):
    """A run with magnnet: the summary's ``allocator_info`` and the Parquet metadata say which
    model, variant and checkpoint ran; an allocator without ``describe`` records ``{}``."""
    import pyarrow.parquet as pq

    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario
    from tests.conftest import write_scenario

    for allocator, params in (("magnnet", 'variant = "paper"\n'), ("greedy", "")):
        extra = f"[dispatch.allocator_params]\n{params}" if params else ""
        path = write_scenario(tmp_path, f"{allocator}.toml",
                              dispatch={"allocator": allocator},
                              fleet={"agents": 4}, tasks={"source": "static", "count": 4,
                                                          "ground_fraction": 1.0},
                              extra=extra)
        spec = load_scenario(path).runs()[0]
        res = run_one(spec, tmp_path / allocator)
        info = json.loads(res.summary["allocator_info"])
        files = list((tmp_path / allocator).rglob("summary*.parquet")) or \
            list((tmp_path / allocator).rglob("*.parquet"))
        meta = pq.read_schema(files[0]).metadata
        assert json.loads(meta[b"dispatch.allocator_info"]) == info
        if allocator == "magnnet":
            assert info["model"] == "magnnet-paper" and info["variant"] == "paper"
            assert "paper_n4.pt@" in info["checkpoint"]
        else:
            assert info == {}


def _round0(alloc, p) -> dict[int, int]:
    """Agent index -> task index requested in round 0 (ids of make_problem are offsets)."""
    return {q.agent_id - 100: q.task_id - 500 for q in alloc.allocate(p).requests
            if q.round == 0}


def test_flood_spreads_views_one_hop_per_step():
    """Without loss, ``known`` after H steps is exactly "within H hops" (scipy's shortest
    paths); on a line of 5, 3 steps cost 5 + 5 + 5 broadcasts (everyone learns something in
    each of the first two steps); with loss it knows no more, and the same seed repeats."""
    from dispatch.api.comms import hop_distances

    rng = np.random.default_rng(3)
    for _ in range(10):
        n = int(rng.integers(2, 12))
        comm = rng.random((n, n)) < 0.25
        comm = comm | comm.T | np.eye(n, dtype=bool)
        p = dataclasses.replace(make_problem(np.ones((n, n))), comm=comm)
        hd = hop_distances(comm)
        for h in (1, 2, 4):
            known, _ = mod.flood(p, h)
            np.testing.assert_array_equal(known, (hd >= 0) & (hd <= h))
            lossy = [mod.flood(dataclasses.replace(p, loss=0.4, rng=np.random.default_rng(s)),
                               h) for s in (7, 7)]
            assert not (lossy[0][0] & ~known).any()
            np.testing.assert_array_equal(lossy[0][0], lossy[1][0])
    p = dataclasses.replace(make_problem(np.ones((5, 5))), comm=_line(5))
    assert mod.flood(p, 3)[1] == 15


def test_agents_that_know_their_component_request_its_plan():
    """Two components (line 0-1-2, pair 3-4): with view_hops 6 every agent knows its whole
    component, and in round 0 requests its part of the match model's plan of that component
    (computed here directly); what the other component looks like changes nothing. The
    flooding is counted: 6 hops more, and a broadcast per agent with news per step."""
    from allocators.magnnet.match import plan

    match, view = _models(5)
    alloc = mod.MagnnetAllocator.with_models(match, view)
    rng = np.random.default_rng(8)
    cost = rng.uniform(1, 20, (5, 5))
    comm = np.zeros((5, 5), bool)
    comm[:3, :3] = _line(3)
    comm[3:, 3:] = True
    p = dataclasses.replace(make_problem(cost), comm=comm)
    flies = np.array([a.flies for a in p.agents])
    want = plan(match, cost[:3], flies[:3], alloc.confidence)
    got = _round0(alloc, p)
    assert {a: got.get(a) for a in range(3)} == {a: int(t) for a, t in enumerate(want)
                                                 if t >= 0}
    for _ in range(3):
        c = cost.copy()
        c[3:] = rng.uniform(0.1, 30, (2, 5))
        g = _round0(alloc, dataclasses.replace(p, cost=c))
        assert {a: g.get(a) for a in range(3)} == {a: got.get(a) for a in range(3)}
    two = mod.MagnnetAllocator.with_models(match, view, view_hops=2).allocate(p)
    six = alloc.allocate(p)
    _, sent = mod.flood(p, 6)
    # step 1: all send; all learned something, so step 2: all again; there only agents 0 and 2
    # learn (of each other), so step 3: those two; then nobody has news
    assert sent == 5 + 5 + 2
    assert six.hops - 2 * six.rounds == 6 and two.hops == 2 * two.rounds


@pytest.mark.parametrize("end", [0, 11])
@pytest.mark.parametrize("view_hops,claims", [(2, 0), (3, 0), (2, 2), (3, 1)])
def test_requests_ignore_agents_beyond_view_hops_plus_claims(view_hops, claims, end):
    """Line 0-1-...-11 (no agent knows its whole component): the round-0 request of an agent
    at either end is the same whatever agents more than ``view_hops + claims`` hops away look
    like: views reach two hops (the view model; the flooded views only tell an agent whether
    it knows its component), claims travel one hop per exchange, in either direction."""
    match, view = _models(3)
    alloc = mod.MagnnetAllocator.with_models(match, view, view_confidence=0.0,
                                             view_hops=view_hops, claims=claims)
    n = 12
    rng = np.random.default_rng(4)
    cost = rng.uniform(1, 20, (n, n))
    p = dataclasses.replace(make_problem(cost), comm=_line(n))
    base = _round0(alloc, p).get(end)
    for _ in range(4):
        c = cost.copy()
        far = np.arange(view_hops + claims + 1, n)
        far = far if end == 0 else n - 1 - far
        c[far] = rng.uniform(0.1, 30, (far.size, n))
        assert _round0(alloc, dataclasses.replace(p, cost=c)).get(end) == base


@pytest.mark.parametrize("params,msg", [({"view_hops": 1}, "view_hops must be an integer >= 2"),
                                        ({"view_hops": 2.5}, "view_hops must be"),
                                        ({"claims": -1}, "claims must be a non-negative")])
def test_bad_rule_parameters(params, msg):
    with pytest.raises(TypeError, match=msg):
        mod.MagnnetAllocator(**params)
