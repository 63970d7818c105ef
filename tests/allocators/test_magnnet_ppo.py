"""MAGNNET variant ``ppo`` (issue 33): the attention policy, its PPO trainer (no teacher), the
training environment against the deployed plugin, and its checkpoints."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from allocators.magnnet import attention  # noqa: E402
from allocators.magnnet.attention import AttentionPolicy, act, observe, requests  # noqa: E402
from allocators.magnnet.ppo import PPOConfig, Sampler, collect, save_checkpoint, train  # noqa: E402
from allocators.magnnet.ppo_env import RoundsEnv, play  # noqa: E402
from allocators.magnnet.ppo_run import RECIPE  # noqa: E402
from allocators.magnnet.problems import Pool  # noqa: E402
from dispatch.api.decentralized import WAIT  # noqa: E402
from dispatch.api.problem import AgentView, AllocationProblem, TaskView  # noqa: E402


@pytest.fixture(autouse=True)
def _one_thread():
    """One torch thread (the machine is shared; more threads only contend)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _pool(count: int, n: int, seed: int = 0) -> Pool:
    rng = np.random.default_rng(seed)
    cost = rng.uniform(1.0, 20.0, (count, n, n))
    flies = np.zeros((count, n), bool)
    flies[:, ::2] = True
    cost[:, ~flies[0], 0] = np.inf  # a ground agent cannot reach task 0
    return Pool(cost, rng.uniform(0, 50, (count, n, 3)), rng.uniform(0, 50, (count, n, 3)),
                flies, np.arange(count), np.array([50.0, 50.0, 30.0]))


def _cfg(rounds: int, updates: int, **kw) -> PPOConfig:
    """The ``ppo`` variant's training (:data:`RECIPE`) at a test's scale: ``rounds`` rounds of
    ``n_envs`` decisions per update, ``updates`` updates."""
    n_envs = kw.pop("n_envs")
    return PPOConfig(**{**RECIPE, "lr": 3e-4, "ent_coef": 0.01, "n_envs": n_envs,
                        "batch_size": rounds * n_envs, "total_steps": updates * rounds * n_envs,
                        **kw})


def _model(seed: int = 0, **kw) -> AttentionPolicy:
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return AttentionPolicy(**kw)


class _Uniform(torch.nn.Module):
    """The random policy: every available action equally likely (wait included)."""

    def forward(self, obs):
        avail = obs["available"]
        ok = torch.cat([torch.ones_like(avail[..., :1]), avail], -1)
        logits = torch.zeros(ok.shape).masked_fill(~ok, -1e9)
        return logits, None


def _problem(cost, flies, comm=None) -> AllocationProblem:
    n, m = cost.shape
    agents = tuple(AgentView(i, "uav" if flies[i] else "ugv", (i, 0, 0),
                             5.0 if flies[i] else 3.0) for i in range(n))
    tasks = tuple(TaskView(j, "ground", (j, 1, 0), 0.0) for j in range(m))
    return AllocationProblem(0.0, agents, tasks, cost.copy(),
                             np.ones((n, n), bool) if comm is None else comm,
                             np.random.default_rng(0))


def _plugin(tmp_path, model):
    from allocators.magnnet.allocator import MagnnetAllocator, clear_model_cache

    path = tmp_path / "ppo.pt"
    save_checkpoint(model, path)
    clear_model_cache()
    return MagnnetAllocator(variant="ppo", checkpoint=str(path))


def test_requests_rule():
    """Action 0 waits until the patience round, then rejects; j + 1 requests task j."""
    m = 3
    assert requests(np.array([0, 1, 3]), 0, m).tolist() == [WAIT, 0, 2]
    last = attention.patience(m)
    assert requests(np.array([0, 2]), last - 1, m).tolist() == [WAIT, 1]
    assert requests(np.array([0, 2]), last, m).tolist() == [-1, 1]


def test_attention_is_local_to_radio_range():
    """An agent's scores do not depend on the costs of agents outside its radio range
    (column attention is masked by the adjacency): decentralized execution."""
    model = _model(layers=2)
    rng = np.random.default_rng(1)
    cost = rng.uniform(1, 20, (1, 6, 5))
    comm = np.zeros((1, 6, 6), bool)
    for i in range(5):  # a path 0-1-2-3-4-5: agent 0 hears 2 only through 1
        comm[0, i, i + 1] = comm[0, i + 1, i] = True
    flies = np.ones((1, 6), bool)
    dec, opn = np.ones((1, 6), bool), np.ones((1, 5), bool)
    base, _ = model(observe(cost, dec, opn, comm, flies))
    far = cost.copy()
    far[0, 5] = rng.uniform(1, 20, 5)  # agent 5: four hops from agent 0
    moved, _ = model(observe(far, dec, opn, comm, flies))
    assert torch.allclose(base[0, 0], moved[0, 0])
    assert not torch.allclose(base[0, 4], moved[0, 4])  # its neighbour does see it


def test_training_learns_on_a_tiny_instance():
    """A few seconds of PPO on 3 x 3 decisions: the argmax policy's team return rises above
    the random policy's by a margin (fixed seed)."""
    pool = _pool(32, 3)
    cfg = _cfg(4, 30, n_envs=16, epochs=4, minibatch_size=64, sizes=((3, 3),),
               comm_ranges=None, lr=3e-3, seed=0)
    model = _model(d=16, layers=1, heads=2)
    d = Sampler(pool, np.random.default_rng(99)).draw(64, 3, 3)
    c, f = d.cost, d.flies
    gen = torch.Generator().manual_seed(5)
    _, rand = play(_Uniform(), c, f, greedy=False, generator=gen)
    _, before = play(model, c, f)
    train(model, pool, cfg)
    _, after = play(model, c, f)
    assert after.mean() > rand.mean() + 0.5, (rand.mean(), before.mean(), after.mean())
    assert after.mean() > before.mean() + 0.5


def test_no_teacher_reaches_the_trainer(monkeypatch):
    """PPO alone: the trainer runs with every assignment solver made to raise, and what it
    learns from is the observation, the actions and the rewards (no target, no label)."""
    import scipy.optimize

    import allocators.hungarian as hungarian
    from allocators.magnnet import rules

    def refuse(*a, **k):
        raise AssertionError("an assignment solver reached the PPO trainer")

    monkeypatch.setattr(hungarian, "optimal_pairs", refuse)
    monkeypatch.setattr(scipy.optimize, "linear_sum_assignment", refuse)
    monkeypatch.setattr(rules, "optimal", refuse)
    pool = _pool(8, 4)
    cfg = _cfg(3, 2, n_envs=4, epochs=1, minibatch_size=8, sizes=((3, 3), (4, 4)),
               comm_ranges=(10.0, 30.0), p_range=0.5)
    rows = train(_model(d=8, layers=1, heads=2), pool, cfg)
    assert [r["phase"] for r in rows] == ["ppo", "ppo"]
    env = RoundsEnv(4, 4, 4)
    sampler = Sampler(pool, np.random.default_rng(0))
    sampler.fill(env, np.arange(4))
    batch = collect(_model(d=8, layers=1, heads=2), env, sampler, 3, {}, cfg=cfg,
                    gen=torch.Generator().manual_seed(0))
    assert set(batch) == {"obs", "actions", "logp", "acted", "values", "rewards", "dones",
                          "last_value"}
    assert set(batch["obs"]) == {"pair", "agents", "available", "adjacency", "deciding"}
    assert batch["obs"]["pair"].shape[-1] == attention.PAIR_F


def test_plugin_decides_as_the_training_env(tmp_path):
    """The same observation gives the same requests in the training environment and in the
    deployed plugin, round after round, and a whole decision ends with the same pairs,
    rounds and conflicts (decision rule and conflict rule: shared code)."""
    model = _model(3)
    plugin = _plugin(tmp_path, model)
    pool = _pool(6, 6, seed=3)
    cost, flies = pool.cost, pool.flies
    env = RoundsEnv(6, 6, 6)
    env.load(np.arange(6), cost, flies)
    gen = torch.Generator().manual_seed(0)
    for r in range(3):  # states reached by sampled rounds
        dec = env.deciding()
        with torch.no_grad():
            a, _, _, _ = act(model, env.obs())
        for b in range(6):
            agents = np.flatnonzero(dec[b])
            if agents.size == 0:
                continue
            mine = requests(a[b].numpy(), r, 6)[agents]
            theirs = plugin.choose(_problem(cost[b], flies[b]), agents, ~env.taken[b], r)
            assert mine.tolist() == np.asarray(theirs).tolist()
        with torch.no_grad():
            s, _, _, _ = act(model, env.obs(), greedy=False, generator=gen)
        env.step(s.numpy())
    played, _ = play(model, cost, flies)
    for b in range(6):
        alloc = plugin.allocate(_problem(cost[b], flies[b]))
        pairs = sorted((int(i), int(j)) for i, j in alloc.pairs)
        mine = sorted((i, int(t)) for i, t in enumerate(played.agent_task[b]) if t >= 0)
        assert pairs == mine
        assert set(alloc.conflicted_tasks()) == set(np.flatnonzero(played.conflicted[b]))


def test_checkpoint_loads_weights_only_and_refuses_other_variants(tmp_path):
    from allocators.magnnet.allocator import MagnnetAllocator, clear_model_cache
    from allocators.magnnet.model import MagnnetPolicy, build

    model = _model(d=8, layers=1, heads=2)
    path = tmp_path / "ppo.pt"
    save_checkpoint(model, path)
    ck = torch.load(path, weights_only=True)
    assert ck["config"]["variant"] == "ppo"
    again = build(ck["config"])
    again.load_state_dict(ck["state_dict"])
    clear_model_cache()
    alloc = MagnnetAllocator(variant="ppo", checkpoint=str(path))
    assert alloc.describe()["variant"] == "ppo"
    other = tmp_path / "paper.pt"
    save_checkpoint(MagnnetPolicy(4, 4), other)
    with pytest.raises(ValueError, match=r"kind 'paper'.*'ppo'"):
        MagnnetAllocator(variant="ppo", checkpoint=str(other))
    with pytest.raises(ValueError, match=r"kind 'ppo'.*'paper'"):
        MagnnetAllocator(variant="paper", checkpoint=str(path))
