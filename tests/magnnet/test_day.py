"""MAGNNET trained for the day (allocators/magnnet/day.py): PPO on taxi decisions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from allocators.magnnet import day
from allocators.magnnet.allocator import MagnnetAllocator, shipped
from allocators.magnnet.match import scores_of
from allocators.magnnet.ppo import load_checkpoint

ROOT = Path(__file__).resolve().parents[2]
MANHATTAN = ROOT / "scenarios" / "manhattan.toml"


def _decision():
    from dataclasses import replace

    from learning.rl import Decisions, pairs_from_choices
    from learning.value_train import scenario_for

    sc = scenario_for(MANHATTAN, 30.0, hours=0.3)
    sc = replace(sc, fleet=replace(sc.fleet, agents=30))
    run = Decisions(sc, 0)
    run.start()
    while run.problem is not None and not np.isfinite(run.problem.cost).any():
        run.answer(pairs_from_choices(run.problem, np.zeros(run.problem.cost.shape[0], int)))
    return run


def test_the_actor_starts_as_the_imitation_model_scores_the_decision():
    run = _decision()
    problem = run.problem
    model, _ = load_checkpoint(shipped("match"))
    policy = day.DayPolicy(model).eval()
    obs, rows, cols = day.DayTrainer().observe(problem, float(run.env.now))
    with torch.no_grad():
        logits, _ = policy({k: v[None] for k, v in obs.items()})
    _, _, sub = day.DayTrainer().sub_problem(problem)
    ref = scores_of(model, sub, np.zeros(len(rows), bool))
    got = logits[0, : len(rows), 1: len(cols) + 1].numpy()
    fin = np.isfinite(ref)
    assert fin.any()
    assert np.allclose(got[fin], ref[fin], atol=1e-4)
    assert (got[~fin] <= -1e3).all()  # unavailable edges are never sampled
    # every agent acting has a cheapest-candidate edge; the critic sees the whole decision
    assert obs["mask"][: len(rows)].any(dim=1).all()
    assert obs["state"].shape == (day.STATE_FEATURES,)


def test_train_writes_a_match_checkpoint_the_plugin_runs_and_a_curve(tmp_path):
    out = tmp_path / "day"
    rc = day.main(["--scenario", str(MANHATTAN), "--agents", "30", "--hours", "0.3",
                   "--steps", "16", "--batch", "8", "--minibatch", "4", "--epochs", "1",
                   "--critic-warmup", "1", "--value", "", "--threads", "1",
                   "--device", "cpu", "--out", str(out)])
    assert rc == 0
    assert (out / "curve.png").stat().st_size > 0
    rows = (out / "curve.csv").read_text().splitlines()
    assert len(rows) == 3  # header and two updates
    alloc = MagnnetAllocator(checkpoint=str(out / "model.pt"))
    assert "model.pt@" in alloc.describe()["checkpoint"]
    _, ck = load_checkpoint(out / "model.pt")
    assert ck["extra"]["trained"].startswith("PPO for the day")


def test_train_magnnet_hands_variant_day_to_the_day_trainer(monkeypatch):
    from allocators.magnnet import train

    seen = {}
    monkeypatch.setattr(day, "main", lambda argv: seen.setdefault("argv", argv) and 0)
    train.main(["--variant", "day", "--steps", "8"])
    assert seen["argv"] == ["--steps", "8"]
    with pytest.raises(SystemExit):
        train.main(["--variant", "nope"])
