"""MAGNNET-match: features, equivariance, mutual-best requests, locality, training, shipped
checkpoint."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from allocators.magnnet import rules  # noqa: E402
from allocators.magnnet.env import random_instance, random_pool  # noqa: E402
from allocators.magnnet.match import (  # noqa: E402
    MatchConfig,
    MatchPolicy,
    edge_features,
    evaluate,
    imitation_loss,
    mutual_best,
    play,
    sample_batch,
    scaled,
    scores_of,
    train,
)
from tests.allocators.helpers import assert_valid, make_problem, total_cost  # noqa: E402


def _model(seed: int = 0) -> MatchPolicy:
    torch.manual_seed(seed)
    return MatchPolicy(hidden=8, layers=2).eval()


def test_edge_features_hand_computed():
    cost = np.array([[10.0, 20.0, 40.0], [30.0, 5.0, np.inf]])
    c, mask = scaled(cost)
    f = edge_features(c, mask, torch.tensor([[True, False]]))[0].numpy()
    # edge (0, 0): c = 1.0; row min 1.0; column min 1.0; best other task 2.0; other agent 3.0
    np.testing.assert_allclose(f[0, 0], [1.0, 0.0, 0.0, -1.0, -2.0, 0.0, 0.0, 1.0], atol=1e-6)
    # edge (1, 1): c = 0.5, its row's best; column min itself; other task 3.0; other agent 2.0
    np.testing.assert_allclose(f[1, 1], [0.5, 0.0, 0.0, -2.5, -1.5, 0.0, 0.0, 0.0], atol=1e-6)
    # edge (0, 2): c = 4.0 capped at COST_CAP; alone in its column (the other agent can't)
    cap = rules.COST_CAP
    np.testing.assert_allclose(f[0, 2, :3], [cap, cap, 0.0], atol=1e-6)
    assert f[0, 2, 5] == 1.0 and f[0, 2, 6] == 0.0
    assert (f[1, 2] == 0).all()  # infeasible edge: all zeros


def test_scores_are_permutation_equivariant():
    model = _model()
    rng = np.random.default_rng(0)
    cost, *_, flies, _ = random_instance(rng, 5, 7)
    cost[1, 3] = np.inf
    s = scores_of(model, cost, flies)
    pa, pt = rng.permutation(5), rng.permutation(7)
    s2 = scores_of(model, cost[np.ix_(pa, pt)], flies[pa])
    np.testing.assert_allclose(s2, s[np.ix_(pa, pt)], rtol=1e-4, atol=1e-4)
    assert s[1, 3] == -np.inf


def test_mutual_best_requests_distinct_tasks_and_always_progress():
    rng = np.random.default_rng(1)
    for _ in range(200):
        n, m = rng.integers(1, 7, 2)
        s = rng.normal(size=(n, m))
        s[rng.random((n, m)) < 0.3] = -np.inf
        req = mutual_best(s, np.arange(n))
        asked = req[req >= 0]
        assert len(set(asked.tolist())) == len(asked)
        for r, j in enumerate(req):
            if j >= 0:
                assert s[r, j] == s[r].max() and s[:, j].argmax() == r
        if np.isfinite(s).any():
            assert len(asked) >= 1  # the best finite entry is always mutual
        forced = mutual_best(s, np.arange(n), force=True)
        assert ((forced >= 0) == np.isfinite(s).any(1)).all()


def _softmax(s, axis):
    e = np.where(np.isfinite(s), np.exp(s - np.nanmax(np.where(np.isfinite(s), s, np.nan),
                                                       axis=axis, keepdims=True)), 0.0)
    return e / e.sum(axis=axis, keepdims=True)


def test_confident_pairs_go_first():
    """With a confidence threshold only pairs the model is sure of request, as long as the
    view has one; otherwise every mutual-best pair requests (no round without progress)."""
    rng = np.random.default_rng(3)
    seen_both = [False, False]
    for _ in range(300):
        n, m = rng.integers(2, 7, 2)
        s = rng.normal(scale=3.0, size=(n, m))
        plain = mutual_best(s, np.arange(n), confidence=0.0)
        sure = mutual_best(s, np.arange(n), confidence=0.8)
        pr, pc = _softmax(s, 1), _softmax(s, 0)
        confident = [r for r in range(n) if plain[r] >= 0
                     and pr[r, plain[r]] >= 0.8 and pc[r, plain[r]] >= 0.8]
        if confident:
            assert sorted(np.flatnonzero(sure >= 0).tolist()) == confident
            seen_both[0] = True
        else:
            np.testing.assert_array_equal(sure, plain)
            seen_both[1] = True
        assert ((sure >= 0) <= (plain >= 0)).all() and (sure[sure >= 0] == plain[sure >= 0]).all()
    assert all(seen_both)


def test_allocator_is_conflict_free_on_complete_graphs():
    """Every agent shares the one view: no task is ever requested twice; N >= M assigns all."""
    from dispatch.api.registry import load

    alloc = load("allocator", "magnnet")()
    rng = np.random.default_rng(2)
    for k, (n, m) in enumerate(itertools.product((1, 3, 8), (1, 4, 8))):
        cost, *_ = random_instance(rng, n, m)
        if k % 2:
            cost[rng.random(cost.shape) < 0.2] = np.inf
        p = make_problem(cost, seed=k)
        a = alloc.allocate(p)
        pairs = assert_valid(p, a)
        assert not a.conflicted_tasks()
        from allocators.hungarian import optimal_pairs

        assert len(pairs) == len(optimal_pairs(cost)) or np.isinf(cost).any()


def test_patience_never_forces_agents_that_hear_everyone():
    """On a complete graph an agent knows its view is everyone's: no forced requests, so no
    conflicts, even with ``patience = 0``."""
    from dispatch.api.registry import load

    alloc = load("allocator", "magnnet")(patience=0)
    rng = np.random.default_rng(8)
    for k in range(5):
        cost, *_ = random_instance(rng, 12, 12)
        p = make_problem(cost, seed=k)
        a = alloc.allocate(p)
        assert len(assert_valid(p, a)) == 12 and not a.conflicted_tasks()


def test_action_ignores_agents_beyond_two_hops():
    """Line 0-1-2-3-4-5: agent 0's request is a function of agents 0-2 only (match model on
    partial views; the view model has its own test in test_views.py)."""
    from allocators.magnnet import allocator as mod

    model = _model(3)
    alloc = mod.MagnnetAllocator(partial="match")
    alloc.model = model
    n = 6
    comm = np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)
    rng = np.random.default_rng(4)
    base_cost = rng.uniform(1, 20, (n, n))

    def request_of_0(cost):
        p = dataclasses.replace(make_problem(cost), comm=comm)
        return int(alloc.choose(p, np.arange(n), np.ones(n, bool), 0)[0])

    base = request_of_0(base_cost)
    for far in (3, 4, 5):
        for _ in range(5):
            c = base_cost.copy()
            c[far] = rng.uniform(0.1, 30, n)
            assert request_of_0(c) == base
    # what agent 0 computes does depend on agent 2 (its second hop): its scores change
    view = np.arange(3)
    s0 = scores_of(model, base_cost[view], np.zeros(3, bool))
    c = base_cost.copy()
    c[2] = rng.uniform(0.1, 30, n)
    assert not np.allclose(scores_of(model, c[view], np.zeros(3, bool))[0], s0[0])


def test_no_communication_still_assigns_everything():
    """Range so small nobody talks: every agent's view is itself, it requests its best task,
    the conflict rule settles the rest; nothing is lost."""
    from dispatch.api.registry import load

    alloc = load("allocator", "magnnet")()
    rng = np.random.default_rng(5)
    cost, *_ = random_instance(rng, 8, 6)
    p = dataclasses.replace(make_problem(cost), comm=np.eye(8, dtype=bool))
    a = alloc.allocate(p)
    assert len(assert_valid(p, a)) == 6


def test_imitation_training_learns_on_a_fixed_seed():
    """A few seconds of training on a tiny random pool lower the loss and the gap."""
    pool = random_pool(0, 40, 6)
    val = random_pool(1, 20, 6)
    cfg = MatchConfig(updates=150, batch=16, hidden=16, layers=2, max_size=6, val_every=150,
                      lr=5e-3)
    model = MatchPolicy(cfg.hidden, cfg.layers)
    torch.manual_seed(0)
    before = evaluate(model.eval(), val)["val/gap"]
    rng = np.random.default_rng(9)
    probe = sample_batch([pool], rng, 64, 6, 1.0)
    with torch.no_grad():
        loss0 = float(imitation_loss(model(*probe[:3]), *probe[3:]))
    rows = train(model, [pool], cfg, val_pool=val)
    with torch.no_grad():
        loss1 = float(imitation_loss(model(*probe[:3]), *probe[3:]))
    assert loss1 < 0.7 * loss0
    after = [r for r in rows if r["phase"] == "val"][-1]["val/gap"]
    assert after < before
    assert len([r for r in rows if r["phase"] == "imitation"]) == cfg.updates


def test_play_matches_the_plugin():
    """The trainer's evaluation plays the same rounds as the plugin on a complete graph."""
    from allocators.magnnet import allocator as mod

    model = _model(6)
    alloc = mod.MagnnetAllocator()
    alloc.model = model
    rng = np.random.default_rng(7)
    for _ in range(5):
        cost, *_, flies, _ = random_instance(rng, 6, 6)
        p = make_problem(cost)
        a = alloc.allocate(p)
        total, assigned, rounds = play(model, cost, np.array([ag.flies for ag in p.agents]))
        assert assigned == len(a.pairs) and rounds == a.rounds
        assert total == pytest.approx(total_cost(p, a))


def test_shipped_checkpoint_loads_and_beats_greedy():
    from allocators.greedy import GreedyAllocator
    from allocators.magnnet.allocator import CHECKPOINTS, MagnnetAllocator
    from allocators.magnnet.ppo import load_checkpoint

    path = CHECKPOINTS / "match.pt"
    ck = torch.load(path, weights_only=True)
    assert ck["config"]["variant"] == "match"
    assert load_checkpoint(path)[0].variant == "match"
    rng = np.random.default_rng(11)
    ours = greedy = best = 0.0
    for k in range(20):
        cost, *_ = random_instance(rng, 10, 10)
        p = make_problem(cost, seed=k)
        a = MagnnetAllocator().allocate(p)
        assert len(assert_valid(p, a)) == 10 and not a.conflicted_tasks()
        ours += total_cost(p, a)
        greedy += total_cost(p, GreedyAllocator().allocate(make_problem(cost, seed=k)))
        best += rules.optimal(cost)[1]
    assert ours < greedy
    assert ours < 1.10 * best


def test_bad_parameters_are_clear_errors(tmp_path):
    from allocators.magnnet.allocator import MagnnetAllocator

    with pytest.raises(TypeError, match="patience"):
        MagnnetAllocator(patience=-1)
    with pytest.raises(TypeError, match="confidence"):
        MagnnetAllocator(confidence=1.5)
    # a checkpoint is checked when the allocator is built, not in its first decision
    with pytest.raises(ValueError, match="no such file"):
        MagnnetAllocator(checkpoint=str(tmp_path / "none.pt"))
    (tmp_path / "text.pt").write_text("not a model\n", encoding="utf-8")
    with pytest.raises(ValueError, match="not a MAGNNET checkpoint"):
        MagnnetAllocator(checkpoint=str(tmp_path / "text.pt"))


def test_sparse_scores_equal_the_dense_network_on_sparse_problems():
    """Large sparse problems are scored edge by edge (match.sparse_scores): the same scores as
    the dense network on every feasible edge (up to float sums) and the same requests."""
    import torch

    from allocators.magnnet import match
    from allocators.magnnet.allocator import MagnnetAllocator

    model = MagnnetAllocator(partial="match").model
    rng = np.random.default_rng(3)
    for n, m, density in [(300, 12, 0.05), (120, 30, 0.2), (60, 1, 0.3), (40, 60, 0.1)]:
        cost = rng.uniform(20.0, 600.0, (n, m)) / 40.0
        cost[rng.random((n, m)) > density] = np.inf
        cost[0, 0] = 1.0  # at least one edge
        flies = rng.random(n) < 0.5
        c, mask = match.scaled(cost)
        with torch.no_grad():
            dense = model(c, mask, torch.from_numpy(flies)[None])[0].numpy().astype(float)
        dense = np.where(mask[0].numpy(), dense, -np.inf)
        sparse = match.sparse_scores(model, cost, flies)
        f = np.isfinite(dense)
        assert np.array_equal(f, np.isfinite(sparse))
        assert np.abs(dense[f] - sparse[f]).max() < 1e-3
        rows = np.arange(n)
        assert np.array_equal(match.mutual_best(dense, rows), match.mutual_best(sparse, rows))


def test_taxi_scale_views_are_rescaled_and_cut_to_candidates_paper_views_untouched():
    """cost_scale/candidates "auto": a view of paper-scale costs (seconds) is fed as it is; a
    view whose median cost exceeds TRAIN_MAX_S (taxis minutes away) is rescaled to the
    training median, and each task keeps only the edges of its CANDIDATES cheapest agents
    (checked against a per-column sort)."""
    from allocators.magnnet import allocator as mod

    alloc = mod.MagnnetAllocator(partial="match")
    rng = np.random.default_rng(2)
    paper = rng.uniform(1.0, 25.0, (20, 20))
    same, keep = alloc._costs(paper)
    assert keep is None and np.array_equal(same, paper)
    taxi = rng.uniform(60.0, 600.0, (50, 6))
    taxi[rng.random(taxi.shape) < 0.3] = np.inf
    cost, keep = alloc._costs(taxi)
    scale = mod.TRAIN_MEDIAN_S / np.median(taxi[np.isfinite(taxi)])
    for j in range(taxi.shape[1]):
        col = taxi[:, j]
        cheapest = np.argsort(col, kind="stable")[:mod.CANDIDATES]
        cheapest = cheapest[np.isfinite(col[cheapest])]
        assert set(np.flatnonzero(np.isfinite(cost[:, j]))) == set(cheapest.tolist())
        assert np.allclose(cost[cheapest, j], col[cheapest] * scale)
    assert np.array_equal(keep, np.isfinite(cost).any(axis=1))
    raw, keep = mod.MagnnetAllocator(partial="match", cost_scale=1, candidates=0)._costs(taxi)
    assert keep is None and np.array_equal(raw, taxi)
    for bad in ({"cost_scale": 0}, {"cost_scale": "big"}, {"candidates": -1},
                {"candidates": 2.5}):
        with pytest.raises(TypeError):
            mod.MagnnetAllocator(partial="match", **bad)
