"""MAGNNET's one PPO trainer: each environment's training is reproducible by seed, the
advantages follow the definitions of team and per-agent credit, the warm start learns from
its teacher, and settings that do not go together are refused."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from allocators.magnnet.attention import AttentionPolicy  # noqa: E402
from allocators.magnnet.game import BatchedGame  # noqa: E402
from allocators.magnnet.model import MagnnetPolicy  # noqa: E402
from allocators.magnnet.ppo import PPOConfig, Sampler, advantages, collect, train  # noqa: E402
from allocators.magnnet.ppo_warm import bc_update, optimal_targets  # noqa: E402
from allocators.magnnet.problems import Pool  # noqa: E402


@pytest.fixture(autouse=True)
def _quiet_torch():
    """One torch thread, and the global generator (the game environment seeds and draws from
    it, as the paper's trainer did) restored after each test."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    with torch.random.fork_rng():
        yield
    torch.set_num_threads(threads)


def _pool(count: int = 24, n: int = 6, seed: int = 0) -> Pool:
    rng = np.random.default_rng(seed)
    cost = rng.uniform(1.0, 20.0, (count, n, n))
    flies = np.zeros((count, n), bool)
    flies[:, ::2] = True
    return Pool(cost, rng.uniform(0, 50, (count, n, 3)), rng.uniform(0, 50, (count, n, 3)),
                flies, np.arange(count), np.array([50.0, 50.0, 30.0]))


def _model(env: str, seed: int = 0, agent_values: bool = False):
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        if env == "game":
            return MagnnetPolicy(3, 3, mlp=16, agent_values=agent_values)
        return AttentionPolicy(d=8, layers=1, heads=2)


def _cfg(env: str, **kw) -> PPOConfig:
    base = {"lr": 3e-3, "n_envs": 6, "batch_size": 24, "minibatch_size": 8, "epochs": 2,
            "total_steps": 72, "sizes": ((3, 3),)}
    if env == "rounds":
        base.update(env="rounds", credit="agent", sizes=((3, 3), (4, 4)),
                    comm_ranges=(10.0, 30.0), p_range=0.5)
    return PPOConfig(**{**base, **kw})


def _run(env: str, seed: int, **kw):
    model = _model(env, agent_values=kw.get("credit") == "agent")
    rows = train(model, _pool(), _cfg(env, seed=seed, **kw))
    logged = [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]
    return model.state_dict(), logged


@pytest.mark.parametrize("env,kw", [("game", {}), ("game", {"credit": "agent"}),
                                    ("game", {"bc_updates": 2, "critic_warmup": 1}),
                                    ("rounds", {})])
def test_tiny_training_is_deterministic_by_seed(env, kw):
    """Two runs with one seed end with the same weights and log the same rows; another seed
    trains to other weights."""
    a, rows_a = _run(env, 1, **kw)
    b, rows_b = _run(env, 1, **kw)
    c, _ = _run(env, 2, **kw)
    assert [r["phase"] for r in rows_a].count("ppo") == 3
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert rows_a == rows_b
    assert any(not torch.equal(a[k], c[k]) for k in a)


def _hand_batch(rewards, values, dones, last, acted):
    t = torch.tensor
    return {"rewards": t(rewards), "values": t(values), "dones": t(dones),
            "last_value": t(last), "acted": t(acted)}


def test_team_credit_advantage_is_gae_of_the_team_reward_normalized_over_all_steps():
    # two rounds of one game, the game ends after the second: no bootstrap past it
    batch = _hand_batch([[1.0], [2.0]], [[0.5], [0.25]], [[0.0], [1.0]], [0.7],
                        [[[True, True]], [[True, False]]])
    adv, ret = advantages(batch, PPOConfig(gamma=0.9, gae_lambda=0.8))
    # t=1: 2 - 0.25 = 1.75; t=0: 1 + 0.9 * 0.25 - 0.5 + 0.9 * 0.8 * 1.75 = 1.985
    raw = np.array([1.985, 1.75])
    assert ret.tolist() == pytest.approx([1.985 + 0.5, 1.75 + 0.25])
    want = (raw - raw.mean()) / (raw.std(ddof=1) + 1e-8)
    assert adv.tolist() == pytest.approx(want.tolist(), rel=1e-5)


def test_agent_credit_advantage_is_each_agents_gae_normalized_over_decisions_taken():
    # agent 0 acts in both rounds, agent 1 only in the first (it left with its task)
    batch = _hand_batch([[[1.0, 3.0]], [[2.0, 0.5]]], [[[0.5, 1.0]], [[0.25, 0.0]]],
                        [[0.0], [1.0]], [[0.7, 0.7]], [[[True, True]], [[True, False]]])
    adv, ret = advantages(batch, PPOConfig(credit="agent", gamma=0.9, gae_lambda=0.8))
    # agent 0 as the team case above; agent 1: t=1: 0.5 - 0 = 0.5;
    # t=0: 3 + 0.9 * 0 - 1 + 0.72 * 0.5 = 2.36
    raw = np.array([[1.985, 2.36], [1.75, 0.5]])
    np.testing.assert_allclose(ret.numpy(), raw + [[0.5, 1.0], [0.25, 0.0]], rtol=1e-6)
    taken = np.array([1.985, 2.36, 1.75])  # the acted entries only set the scale
    want = (raw - taken.mean()) / (taken.std(ddof=1) + 1e-8)
    np.testing.assert_allclose(adv.numpy(), want, rtol=1e-5)


def test_warm_start_learns_the_teachers_targets():
    """Imitation updates change the starting weights and lower the cross-entropy to the
    optimal assignment on held-out states; a run without them starts PPO from the initial
    weights."""
    pool = _pool(40, 6)
    game = BatchedGame(16, 3, 3)
    Sampler(pool, np.random.default_rng(5)).fill(game, np.arange(16))
    obs, tgt = game.obs(), optimal_targets(game)
    mask = tgt >= 0

    def ce(model):
        with torch.no_grad():
            logits, _ = model(obs)
        return float(torch.nn.functional.cross_entropy(logits[mask], tgt[mask]))

    model = _model("game")
    start = {k: v.clone() for k, v in model.state_dict().items()}
    before = ce(model)
    rows = train(model, pool, _cfg("game", bc_updates=30, bc_lr=1e-2, total_steps=0))
    assert [r["phase"] for r in rows] == ["bc"] * 30
    assert any(not torch.equal(start[k], v) for k, v in model.state_dict().items())
    assert ce(model) < before - 0.1
    untouched = _model("game")
    train(untouched, pool, _cfg("game", total_steps=0))
    assert all(torch.equal(start[k], v) for k, v in untouched.state_dict().items())


def test_warm_start_update_takes_one_cross_entropy_step():
    """bc_update returns the loss of the teacher's targets on the visited states and steps the
    optimizer once."""
    pool = _pool(40, 6)
    game = BatchedGame(8, 3, 3)
    sampler = Sampler(pool, np.random.default_rng(1))
    sampler.fill(game, np.arange(8))
    model = _model("game")
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    loss = bc_update(model, opt, game, sampler, steps=2)
    assert np.isfinite(loss) and loss > 0
    assert opt.state_dict()["state"][0]["step"] == 1


@pytest.mark.parametrize("kw,match", [
    ({"env": "voxels"}, "env 'voxels'"),
    ({"env": "rounds", "credit": "team"}, "trains with 'agent'"),
    ({"env": "rounds", "credit": "agent", "bc_updates": 3}, "no teacher"),
    ({"credit": "everyone"}, "credit 'everyone'"),
])
def test_config_refuses_settings_that_do_not_go_together(kw, match):
    with pytest.raises(ValueError, match=match):
        PPOConfig(**kw)


def test_credit_must_match_the_critic():
    """Per-agent credit needs one value per agent; a one-value critic is refused by name."""
    game = BatchedGame(4, 3, 3)
    sampler = Sampler(_pool(), np.random.default_rng(0))
    sampler.fill(game, np.arange(4))
    with pytest.raises(ValueError, match="one value per agent"):
        collect(_model("game"), game, sampler, 2, {}, cfg=PPOConfig(credit="agent"))
    with pytest.raises(ValueError, match="needs a critic with one value "):
        collect(_model("game", agent_values=True), game, sampler, 2, {}, cfg=PPOConfig())


@pytest.mark.parametrize("team_weight", [0.0, 0.5, 1.0])
def test_rounds_reward_mixes_own_and_team_as_configured(team_weight):
    """In the rounds environment each agent trains on ``(1 - w) own + w team / N``: two agents
    win two tasks and a third asks for a task already asked for (a conflict)."""
    from allocators.magnnet.ppo_env import ENVS, RoundsEnv

    cost = np.array([[[2.0, 8.0, 5.0], [6.0, 3.0, 5.0], [1.0, 9.0, 9.0]]])
    env = RoundsEnv(1, 3, 3)
    env.load([0], cost, np.ones((1, 3), bool))
    probe = RoundsEnv(1, 3, 3)
    probe.load([0], cost, np.ones((1, 3), bool))
    actions = np.array([[1, 2, 1]])  # agents 0 and 2 ask for task 0 (2 wins), 1 for task 1
    own, _, _ = probe.step(actions)
    cfg = PPOConfig(env="rounds", credit="agent", team_weight=team_weight)
    run = ENVS["rounds"].running(env)
    r, acted, _, _ = ENVS["rounds"].step(env, torch.from_numpy(actions), cfg, run)
    want = (1 - team_weight) * own + team_weight * own.sum() / 3
    np.testing.assert_allclose(r.numpy(), want.astype(np.float32), rtol=1e-6)
    assert acted.all() and run[0] == pytest.approx(own.sum())
    assert own[0, 0] < 0 < own[0, 2]  # both asked for task 0 and paid; only the winner won
