"""MAGNNET: environment conformance, batched = PettingZoo, GAE, learning, decentralization,
shipped checkpoints."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("pettingzoo")

from allocators.magnnet import rules  # noqa: E402
from allocators.magnnet.env import MagnnetEnv, random_instance, random_pool  # noqa: E402
from allocators.magnnet.game import BatchedGame, global_obs  # noqa: E402
from allocators.magnnet.model import MagnnetPolicy  # noqa: E402
from allocators.magnnet.ppo import PPOConfig, gae, train  # noqa: E402


def test_parallel_api():
    from pettingzoo.test import parallel_api_test

    parallel_api_test(MagnnetEnv(4), num_cycles=40)
    parallel_api_test(MagnnetEnv(6, comm_range=20.0), num_cycles=40)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_equals_pettingzoo(seed):
    n = 5
    rng = np.random.default_rng(seed)
    insts = [random_instance(rng, n, n) for _ in range(3)]
    envs = [MagnnetEnv(n) for _ in insts]
    for e, inst in zip(envs, insts):
        e.reset(seed=seed, options={"instance": inst})
    bg = BatchedGame(3, n, n)
    c, a, t, f, s = zip(*insts)
    bg.load(np.arange(3), np.stack(c), np.stack(a), np.stack(t), np.stack(f), s[0])
    done = np.zeros(3, bool)
    for _ in range(30):
        if done.all():
            break
        bo = bg.obs()
        acts = np.zeros((3, n), np.int64)
        for b, e in enumerate(envs):
            if done[b]:
                continue
            g = global_obs(e.game)
            for k in ("agents", "cost", "available", "tasks", "adjacency"):
                np.testing.assert_allclose(bo[k][b].numpy().astype(float), g[k].astype(float),
                                           atol=1e-6, err_msg=k)
            for ag in e.agents:
                i = int(ag.split("_")[1])
                mask = np.flatnonzero(g["available"][i])
                acts[b, i] = 0 if rng.random() < 0.2 or not mask.size else 1 + rng.choice(mask)
        r, team, acted, ended, bdone, _ = bg.step(torch.from_numpy(acts))
        for b, e in enumerate(envs):
            if done[b]:
                continue
            live = list(e.agents)
            _, rew, term, trunc, info = e.step({ag: acts[b, int(ag.split("_")[1])]
                                                for ag in live})
            for ag in live:
                i = int(ag.split("_")[1])
                assert rew[ag] == pytest.approx(float(r[b, i]), abs=1e-5)
                assert (term[ag] or trunc[ag]) == bool(ended[b, i])
                assert info[ag]["team_reward"] == pytest.approx(float(team[b]), abs=1e-4)
            assert bool(bdone[b]) == e.game.done
            np.testing.assert_array_equal(bg.agent_task[b].numpy(), e.game.agent_task)
            done[b] = e.game.done
    assert done.all()


def test_gae_hand_computed():
    r = torch.tensor([1.0, 0.0, 2.0])
    v = torch.tensor([0.5, 0.2, 1.0])
    d = torch.tensor([0.0, 1.0, 0.0])
    adv, ret = gae(r, v, d, torch.tensor(3.0), gamma=0.9, lam=0.5)
    # t=2: delta = 2 + .9*3 - 1 = 3.7 ; adv = 3.7
    # t=1: terminal: delta = 0 - .2 = -.2 ; adv = -.2
    # t=0: delta = 1 + .9*.2 - .5 = .68 ; adv = .68 + .9*.5*(-.2) = .59
    assert adv.tolist() == pytest.approx([0.59, -0.2, 3.7])
    assert ret.tolist() == pytest.approx([1.09, 0.0, 4.7])


def test_training_raises_reward():
    torch.set_num_threads(1)
    torch.manual_seed(0)  # the initial weights come from torch's global generator
    pool = random_pool(0, 100, 3)
    model = MagnnetPolicy(3, 3, mlp=32)
    cfg = PPOConfig(lr=3e-3, total_steps=256 * 12, batch_size=256, n_envs=32, epochs=4, seed=0,
                    sizes=((3, 3),))
    rows = train(model, pool, cfg)
    ret = [r["charts/episode_return"] for r in rows]
    assert np.mean(ret[-3:]) > np.mean(ret[:3]) + 0.3


def _obs_np(model_obs):
    return {k: torch.as_tensor(v)[None] for k, v in model_obs.items() if k not in
            ("self", "action_mask")}


def _model(cls, n):
    from allocators.magnnet.model import NB_FEATURES

    return {"paper": lambda: MagnnetPolicy(n, n),
            "paper_nb": lambda: MagnnetPolicy(n, n, task_features=NB_FEATURES)}[cls]()


@pytest.mark.parametrize("cls", ["paper", "paper_nb"])
def test_action_ignores_agents_beyond_two_hops(cls):
    """Agents on a line 0-1-2-3-4-5: agent 0's logits do not change when agent 3, 4 or 5
    changes (position, costs, status), and do change when agent 2 changes."""
    n = 6
    torch.manual_seed(0)
    model = _model(cls, n)
    assert model.variant == cls
    rng = np.random.default_rng(0)
    cost, apos, tpos, flies, size = random_instance(rng, n, n)
    comm = np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)

    def logits_of(cost, apos):
        env = MagnnetEnv(n)
        env.reset(options={"instance": (cost, apos, tpos, flies, size)})
        env.game.comm = comm
        with torch.no_grad():
            lg, _ = model(_obs_np(global_obs(env.game)))
        return lg[0, 0]

    base = logits_of(cost, apos)
    for far in (3, 4, 5):
        c2, a2 = cost.copy(), apos.copy()
        c2[far] = rng.uniform(1, 20, n)
        a2[far] = rng.uniform(0, 30, 3)
        torch.testing.assert_close(logits_of(c2, a2), base)
    c2 = cost.copy()
    c2[2] = rng.uniform(1, 20, n)
    assert not torch.allclose(logits_of(c2, apos), base)


@pytest.mark.parametrize("cls", ["paper", "paper_nb"])
def test_allocator_is_local_and_valid(cls):
    """The plugin's choices on a problem equal each agent's own local-view computation."""
    from allocators.magnnet.allocator import observe
    from allocators.magnnet.game import local_obs
    from tests.allocators.helpers import make_problem

    torch.manual_seed(1)
    model = _model(cls, 6)
    cost = np.random.default_rng(3).uniform(1, 20, (6, 6))
    p = make_problem(cost)
    comm = np.eye(6, dtype=bool) | np.eye(6, k=1, dtype=bool) | np.eye(6, k=-1, dtype=bool)
    obs = observe(p, np.arange(6), np.ones(6, bool), np.array([50, 50, 30], np.float32))
    obs["adjacency"] = torch.from_numpy(comm.astype(np.float32))[None]
    with torch.no_grad():
        full, _ = model(obs)
    g = {k: v[0].numpy() for k, v in obs.items()}
    for i in range(6):
        loc = local_obs(g, i, 6)
        with torch.no_grad():
            lg, _ = model(_obs_np(loc))
        torch.testing.assert_close(lg[0, i], full[0, i])


def _shipped(name):
    from allocators.magnnet.allocator import CHECKPOINTS

    path = CHECKPOINTS / name
    if not path.exists():
        pytest.skip(f"no shipped checkpoint {name}")
    return path


@pytest.mark.parametrize("n", [4, 8])
def test_shipped_checkpoints_load_and_beat_random(n):
    from allocators.magnnet.ppo import load_checkpoint
    from allocators.randomized import RandomAllocator
    from dispatch.api.registry import load
    from tests.allocators.helpers import assert_valid, make_problem, total_cost

    for name in (f"paper_n{n}.pt", f"paper_nb_n{n}.pt"):
        ck = torch.load(_shipped(name), weights_only=True)
        assert ck["config"]["n_agents"] == n
        load_checkpoint(_shipped(name))
    rng = np.random.default_rng(123)
    allocs = {v: load("allocator", "magnnet")(v) for v in ("match", "paper", "paper_nb")}
    allocs["random"] = RandomAllocator()
    wins = dict.fromkeys(allocs, 0.0)
    for k in range(10):
        cost, *_ = random_instance(rng, n, n)
        for name, alloc in allocs.items():
            p = make_problem(cost, seed=k)
            a = alloc.allocate(p)
            assert_valid(p, a)
            wins[name] += total_cost(p, a) + 100.0 * (n - len(a.pairs))
    for v in ("match", "paper", "paper_nb"):
        assert wins[v] < wins["random"], v


def test_neighbour_task_features_hand_computed():
    """Agent 0 of three on a complete graph, costs (scaled) rows [1, 2], [3, 1.5], [2, 4]."""
    from allocators.magnnet.model import neighbour_task_features

    cost = torch.tensor([[[1.0, 2.0], [3.0, 1.5], [2.0, 4.0]]])
    obs = {"cost": cost, "available": torch.ones(1, 3, 2, dtype=torch.bool),
           "adjacency": torch.ones(1, 3, 3), "agents": torch.ones(1, 3, 5)}
    f = neighbour_task_features(obs)[0, 0]
    # task 0: others 3, 2 -> margin 1-2=-1, none cheaper, second-min 3-1=2, cheapest other
    # (agent 2, best other task 4) regret 4-2=2, own regret 1-2=-1
    assert f[0].tolist() == pytest.approx([-1.0, rules.COST_CAP, 0.0, 2.0, 2.0, -1.0])
    # task 1: others 1.5, 4 -> margin .5, agent 1 cheaper with slack 0, one cheaper,
    # second-min 4-2=2, agent 1's regret 3-1.5=1.5, own regret 2-1=1
    assert f[1].tolist() == pytest.approx([0.5, 0.0, 0.1, 2.0, 1.5, 1.0])


def test_deferring_teacher_is_optimal_and_conflict_free():
    """Following :func:`optimal_targets` with ``defer`` reaches the optimum without conflicts."""
    from allocators.magnnet.ppo_warm import optimal_targets

    pool = random_pool(5, 16, 6)
    g = BatchedGame(16, 6, 6)
    g.load(np.arange(16), pool.cost, pool.agent_pos, pool.task_pos, pool.flies,
           pool.world_size)
    over = torch.zeros(16, dtype=torch.bool)
    for _ in range(g.max_rounds):
        a = optimal_targets(g, defer=True).clamp(min=0)
        a[over] = 0
        over |= g.step(a)[4]
        if over.all():
            break
    assert over.all()
    assert not g.conflicted.any()
    torch.testing.assert_close(g.totals(), g.opt_total)


def test_evaluate_plays_the_pool():
    from allocators.magnnet.ppo import evaluate

    pool = random_pool(2, 8, 4)
    r = evaluate(_model("paper_nb", 4), pool)
    assert 0.0 <= r["conflict_free"] <= 1.0 and 0.0 <= r["complete"] <= 1.0
    assert np.isnan(r["gap"]) or r["gap"] >= -1e-9


def test_rules_bonus():
    assert rules.team_bonus(3, 10.0, 3, 10.0) == pytest.approx(rules.R_TEAM)
    assert rules.team_bonus(2, 10.0, 3, 10.0) == 0.0


@pytest.mark.slow
def test_train_cli_smoke(tmp_path, monkeypatch):
    """`dispatch train magnnet` end to end on a tiny pool: checkpoint, Parquet log, figures."""
    import pyarrow.parquet as pq

    from dispatch.run.cli import main

    monkeypatch.setenv("MAGNNET_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    assert main(["train", "magnnet", "--agents", "4", "--steps", "512", "--bc-updates", "2",
                 "--pool", "3", "--envs", "8", "--out", str(out)]) == 0
    for name in ("model.pt", "log.parquet", "reward.png", "entropy.png"):
        assert (out / name).exists()
    log = pq.read_table(out / "log.parquet").to_pydict()
    assert sum(ph != "val" for ph in log["phase"]) == 2 + 1
    assert "val" in log["phase"]
    torch.load(out / "model.pt", weights_only=True)
