"""A value's reward (``value_reward``): the assignment maximises worth, not the count of pairs.

The answers are checked against a brute force over every matching (small matrices), against
hand-computed worths on a two-pair problem, and on a simulated hour: every pair chosen by
worth is worth something, and a reward below some pickups leaves those requests for later.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from allocators.hungarian import HungarianAllocator, gated_pairs
from learning.value_train import scenario_for
from tests.learning.test_lookahead_value import MANHATTAN, _zero_file
from tests.learning.test_value import _problem, _value


def _best_by_enumeration(score: np.ndarray) -> float:
    """The least total of negative finite scores over every matching (0: the empty one)."""
    n, m = score.shape
    best = 0.0
    for k in range(1, min(n, m) + 1):
        for rows in itertools.combinations(range(n), k):
            for cols in itertools.permutations(range(m), k):
                s = score[list(rows), list(cols)]
                if np.all(np.isfinite(s)) and np.all(s < 0):
                    best = min(best, float(s.sum()))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_gated_pairs_is_the_maximum_weight_matching(seed):
    rng = np.random.default_rng(seed)
    n, m = rng.integers(1, 5, size=2)
    score = rng.uniform(-10.0, 6.0, (n, m))
    score[rng.uniform(size=(n, m)) < 0.2] = np.inf
    pairs = gated_pairs(score)
    assert len({a for a, _ in pairs}) == len(pairs) == len({t for _, t in pairs})
    assert all(np.isfinite(score[a, t]) and score[a, t] < 0 for a, t in pairs)
    got = sum(float(score[a, t]) for a, t in pairs)
    assert got == pytest.approx(_best_by_enumeration(score))


def test_gated_pairs_may_serve_fewer_for_more_worth():
    # the maximum-cardinality answer pairs both (total -1 - 1 = -2); by worth one pair of -9 wins
    score = np.array([[-9.0, -1.0], [-1.0, np.inf]])
    assert gated_pairs(score) == [(0, 0)]
    assert gated_pairs(np.array([[0.0, 3.0], [np.inf, 1.0]])) == []
    assert gated_pairs(np.zeros((0, 3))) == []


def test_a_reward_leaves_a_pair_worth_nothing_and_keeps_one_worth_something(tmp_path):
    """One vehicle, two requests: request 1's trip ends where the value is three requests
    (weight 100 s), request 2's where it is zero. Worth = reward - adjusted cost."""
    v = _value(weight=100.0)
    v.save(tmp_path / "v.npz")
    p = _problem([[500.0, 90.0]])
    adjusted = v.adjusted(p)
    assert adjusted[0, 1] == pytest.approx(90.0)
    assert adjusted[0, 0] > 200.0  # 500 s less at most 300 s of value
    # reward 120 s: request 2 is worth 30 s, request 1 nothing (its adjusted cost is > 200 s)
    h = HungarianAllocator(value=str(tmp_path / "v.npz"), value_reward=120.0)
    assert h.allocate(p).pairs == ((10, 2),)
    # reward 80 s: neither is worth its pickup: the vehicle stays free, both wait
    h = HungarianAllocator(value=str(tmp_path / "v.npz"), value_reward=80.0)
    assert h.allocate(p).pairs == ()
    # without a reward the most requests are served whatever they cost
    assert HungarianAllocator(value=str(tmp_path / "v.npz")).allocate(p).pairs == ((10, 2),)


def test_a_reward_needs_a_value_and_is_a_positive_number(tmp_path):
    with pytest.raises(TypeError, match="needs a value file"):
        HungarianAllocator(value_reward=100.0)
    _value().save(tmp_path / "v.npz")
    for bad in (0.0, -5.0, True, "300"):
        with pytest.raises(TypeError, match="value_reward must be a number"):
            HungarianAllocator(value=str(tmp_path / "v.npz"), value_reward=bad)
    from allocators.rtv import RtvAllocator

    with pytest.raises(TypeError, match="needs a value file"):
        RtvAllocator(value_reward=100.0)


def _tasks(sc, allocator, params):
    from dispatch.run.runner import run_one

    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(params.items())))
    res = run_one(sc.runs(allocator=allocator, agents=25, seed=3)[0])
    return res.tables["tasks"].to_pandas(), res.summary


@pytest.mark.parametrize("allocator,seats", [("hungarian", 1), ("rtv", 3)])
def test_with_a_zero_value_and_a_reward_no_chosen_pickup_costs_more_than_it(tmp_path,
                                                                        allocator, seats):
    """A zero value with reward R: a single request is taken only where its cost (the pickup
    drive, or with plans the route's cost) is under R, so a small R leaves some requests the
    plain run assigns at once for later batches: their assignments differ."""
    sc = scenario_for(MANHATTAN, 30.0, hours=0.4, capacity=seats)
    sc = replace(sc, dispatch=replace(sc.dispatch, objective="pickup_time"))
    zero = str(_zero_file(tmp_path, sc, seats + 1 if seats > 1 else 1))
    plain, _ = _tasks(sc, allocator, {})
    reward = 90.0
    gated, s1 = _tasks(sc, allocator, {"value": zero, "value_reward": reward})
    assert s1["tasks_completed"] > 0
    if allocator == "hungarian":  # one seat: a pair's cost is its pickup's drive
        assert plain["cost"].max() >= reward
        assert gated["cost"].dropna().max() < reward
    assert not np.array_equal(plain["assigned_at"].to_numpy(), gated["assigned_at"].to_numpy(),
                              equal_nan=True)


def test_training_from_a_start_value_with_a_reward_is_recorded_and_deterministic(tmp_path):
    """Policy iteration resumed from a file, its days run by worth: the file names the reward
    and the start, the days differ from the plain ones (the gate leaves some requests), and
    the same arguments write the same bytes."""
    from learning.value import ZoneValue
    from learning.value_train import train

    kw = {"agents": 20, "seeds": (100,), "zone": 1000.0, "hours": 0.25, "log": lambda s: None}
    plain = train(MANHATTAN, tmp_path / "plain.npz", **kw)
    assert "reward" not in plain.meta  # (older files' bytes as before)
    a = train(MANHATTAN, tmp_path / "a.npz", reward=60.0, start=tmp_path / "plain.npz", **kw)
    train(MANHATTAN, tmp_path / "b.npz", reward=60.0, start=tmp_path / "plain.npz", **kw)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    got = ZoneValue.load(tmp_path / "a.npz")
    assert got.meta["reward"] == 60.0 and got.meta["start"] == "plain.npz"
    assert a.meta["days"][0]["served"] != plain.meta["days"][0]["served"]
