"""MAGNNET's training environment as a PettingZoo ``ParallelEnv``.

Agents are ``"agent_0" .. "agent_{N-1}"``; an agent is live while it decides (unassigned, with
an open task it can serve) and leaves when it wins a task, runs out of options, or the episode
ends (rules and rewards: :mod:`allocators.magnnet.rules`). Each agent observes only its 2-hop
communication neighbourhood (:func:`allocators.magnnet.game.local_obs`), with an
``action_mask``; :meth:`MagnnetEnv.state` is the global view for the centralized critic.

Instances come from a :class:`~allocators.magnnet.problems.Pool` (drawn with the generator
seeded by ``reset(seed=...)``) or, without a pool, are random uniform cost matrices (for tests).
"""

from __future__ import annotations

import functools

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from allocators.magnnet import rules
from allocators.magnnet.game import Game, global_obs, local_obs


def random_instance(rng: np.random.Generator, n: int, m: int):
    """A uniform random instance in a 50 x 50 x 30 m box, costs = distance / speed."""
    size = np.array([50.0, 50.0, 30.0], np.float32)
    flies = np.arange(n) < (n + 1) // 2
    apos = rng.uniform(0, 1, (n, 3)).astype(np.float32) * size
    apos[~flies, 2] = 0.5
    tpos = rng.uniform(0, 1, (m, 3)).astype(np.float32) * size
    tpos[:, 2] = 0.5
    speed = np.where(flies, 5.0, 3.0)
    cost = np.linalg.norm(apos[:, None] - tpos[None], axis=-1) / speed[:, None]
    return cost, apos, tpos, flies, size


class MagnnetEnv(ParallelEnv):
    metadata = {"name": "magnnet_v0", "render_modes": []}

    def __init__(self, n_agents: int, n_tasks: int | None = None, pool=None,
                 comm_range: float | None = None) -> None:
        self.n = n_agents
        self.m = n_tasks if n_tasks is not None else n_agents
        self.pool = pool
        self.comm_range = comm_range
        self.possible_agents = [f"agent_{i}" for i in range(self.n)]
        self.agents: list[str] = []
        self._rng = np.random.default_rng()
        self.game: Game | None = None

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent):
        n, m = self.n, self.m
        return spaces.Dict({
            "agents": spaces.Box(-1.0, 2.0, (n, 5), np.float32),
            "cost": spaces.Box(0.0, rules.COST_CAP, (n, m), np.float32),
            "available": spaces.Box(0, 1, (n, m), np.int8),
            "tasks": spaces.Box(-1.0, 2.0, (m, 4), np.float32),
            "adjacency": spaces.Box(0.0, 1.0, (n, n), np.float32),
            "self": spaces.Box(0.0, 1.0, (n,), np.float32),
            "action_mask": spaces.Box(0, 1, (m + 1,), np.int8),
        })

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent):
        return spaces.Discrete(self.m + 1)

    def _draw(self):
        if self.pool is not None:
            k = int(self._rng.integers(len(self.pool)))
            p = self.pool
            return p.cost[k], p.agent_pos[k], p.task_pos[k], p.flies[k], p.world_size
        return random_instance(self._rng, self.n, self.m)

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        inst = (options or {}).get("instance") or self._draw()
        cost, apos, tpos, flies, size = inst
        comm = None
        if self.comm_range is not None:
            from dispatch.api.comms import comm_graph

            comm = comm_graph(apos, self.comm_range)
        self.game = Game(cost, apos, tpos, flies, size, comm)
        dec = self.game.deciding()
        self.agents = [a for i, a in enumerate(self.possible_agents) if dec[i]]
        return self._obs(), {a: {} for a in self.agents}

    def _obs(self):
        g = global_obs(self.game)
        idx = {a: int(a.split("_")[1]) for a in self.agents}
        return {a: local_obs(g, i, self.m) for a, i in idx.items()}

    def state(self) -> np.ndarray:
        g = global_obs(self.game)
        return np.concatenate([g["agents"].ravel(), g["cost"].ravel(), g["tasks"].ravel()])

    def step(self, actions):
        act = np.zeros(self.n, np.int64)
        for a, v in actions.items():
            act[int(a.split("_")[1])] = int(v)
        live = list(self.agents)
        rew, team, acted, ended, done, trunc = self.game.step(act)
        idx = {a: int(a.split("_")[1]) for a in live}
        rewards = {a: float(rew[i]) for a, i in idx.items()}
        terminations = {a: bool(ended[i]) and not trunc for a, i in idx.items()}
        truncations = {a: bool(trunc) for a in live}
        infos = {a: {"team_reward": team} for a in live}
        self.agents = [a for a in live if not ended[idx[a]]]
        obs_all = global_obs(self.game)
        obs = {a: local_obs(obs_all, idx[a], self.m) for a in live}
        return obs, rewards, terminations, truncations, infos


def random_pool(seed: int, count: int, n: int, m: int | None = None):
    """A :class:`~allocators.magnnet.problems.Pool` of :func:`random_instance` draws (tests)."""
    from allocators.magnnet.problems import Pool

    rng = np.random.default_rng(seed)
    rows = [random_instance(rng, n, m if m is not None else n) for _ in range(count)]
    c, a, t, f, s = zip(*rows)
    return Pool(np.stack(c), np.stack(a), np.stack(t), np.stack(f),
                np.arange(count, dtype=np.int64), s[0])
