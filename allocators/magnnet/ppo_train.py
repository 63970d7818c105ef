"""PPO alone for the ``ppo`` variant (issue 33): CTDE with a centralized critic, no teacher.

The trainer sees cost matrices, the agents' kinds and radio graphs (:class:`Sampler` cuts
them from the cached training pool, seeds from :data:`~allocators.magnnet.problems.
TRAIN_SEED0`), and the rewards :class:`~allocators.magnnet.ppo_env.RoundsEnv` computes from
those costs. It never calls an assignment solver and never sees a label: no imitation, no
warm start (a test runs it with the solvers made to raise).

One update: every size of ``cfg.sizes`` in turn (one model for every ``N``), ``cfg.n_envs``
decisions played for ``cfg.rounds`` rounds with sampled actions (finished decisions replaced
by fresh ones), per-agent GAE over each agent's reward stream against the critic's value for
that agent (the critic reads the whole instance: centralized), then ``cfg.epochs`` passes of
clipped PPO in minibatches. Only the steps where an agent decided carry policy loss.

Validation (held-out *training* seeds, never the evaluation seeds) plays the argmax policy
through the same environment; the weights that validate best are kept. The optimal
assignment is computed there (and only there) to report the gap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from allocators.magnnet.attention import act
from allocators.magnnet.ppo import gae
from allocators.magnnet.ppo_env import RoundsEnv


@dataclass
class Config:
    lr: float = 3e-4
    n_envs: int = 48
    rounds: int = 12
    """rounds played per environment and update (the batch is ``n_envs * rounds`` steps)."""
    epochs: int = 3
    minibatch: int = 256
    """environment steps (rounds of one game) per gradient step."""
    ent_coef: float = 0.01
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.2
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    team_weight: float = 0.5
    """share of the team reward (mean over agents) in each agent's reward."""
    cost_weight: float = 1.0
    """weight of the win and stall rewards against the conflict penalty
    (:class:`~allocators.magnnet.ppo_env.RoundsEnv`)."""
    sizes: tuple = (4, 6, 8, 10, 12)
    comm_ranges: tuple | None = (15.0, 40.0)
    """radio ranges (metres) drawn for ``p_range`` of the games; None: complete graphs only."""
    p_range: float = 0.3
    updates: int = 400
    val_every: int = 10
    seed: int = 0
    wall_s: float = float("inf")
    """wall-time budget: no update starts after it (a validation closes the run)."""


class Sampler:
    """Decisions ``N x M`` cut from a pool's instances (random agents, half UAVs where the
    pool has them, random tasks, shuffled), with a radio graph for a share of them."""

    def __init__(self, pool, rng: np.random.Generator, comm_ranges=None,
                 p_range: float = 0.0) -> None:
        self.pool, self.rng = pool, rng
        self.comm_ranges, self.p_range = comm_ranges, p_range

    def draw(self, count: int, n: int, m: int):
        p, rng = self.pool, self.rng
        costs, fls, comms = [], [], []
        for k in rng.integers(len(p), size=count):
            fl = p.flies[k]
            uav, ugv = np.flatnonzero(fl), np.flatnonzero(~fl)
            n_uav = min(len(uav), max((n + 1) // 2, n - len(ugv)))
            a = rng.permutation(np.concatenate([rng.choice(uav, n_uav, replace=False),
                                                rng.choice(ugv, n - n_uav, replace=False)]))
            t = rng.choice(p.cost.shape[2], m, replace=False)
            costs.append(p.cost[k][np.ix_(a, t)])
            fls.append(fl[a])
            comm = np.ones((n, n), bool)
            if self.comm_ranges is not None and rng.random() < self.p_range:
                from dispatch.api.comms import comm_graph

                comm = comm_graph(p.agent_pos[k][a], rng.uniform(*self.comm_ranges))
            comms.append(comm)
        return np.stack(costs), np.stack(fls), np.stack(comms)

    def fill(self, env: RoundsEnv, slots) -> None:
        slots = np.asarray(slots)
        if slots.size:
            env.load(slots, *self.draw(len(slots), env.n, env.m))


def _cat(obs_list):
    return {k: torch.cat([o[k] for o in obs_list]) for k in obs_list[0]}


def collect(model, env: RoundsEnv, sampler: Sampler, cfg: Config, gen, stats: dict):
    """``cfg.rounds`` sampled rounds of every game of ``env``: the batch (time first)."""
    obs_l, act_l, lp_l, acted_l, val_l, rew_l, done_l = [], [], [], [], [], [], []
    run = stats.setdefault(("run", env.n), np.zeros(env.B))
    for _ in range(cfg.rounds):
        obs = env.obs()
        with torch.no_grad():
            a, lp, _, x = act(model, obs, greedy=False, generator=gen)
            v = model.value(obs, x)
        own, acted, done = env.step(a.numpy())
        team = own.sum(1, keepdims=True)
        r = (1 - cfg.team_weight) * own + cfg.team_weight * team / env.n
        run += team[:, 0]
        obs_l.append(obs)
        act_l.append(a)
        lp_l.append(lp)
        acted_l.append(torch.from_numpy(acted))
        val_l.append(v)
        rew_l.append(torch.from_numpy(r).float())
        done_l.append(torch.from_numpy(done).float())
        if done.any():
            d = np.flatnonzero(done)
            stats.setdefault("returns", []).extend((run[d] / env.n).tolist())
            assigned = env.taken[d]
            stats.setdefault("conflict_free", []).extend(
                (assigned & ~env.conflicted[d]).mean(1).tolist())
            run[d] = 0.0
            sampler.fill(env, d)
    with torch.no_grad():
        obs = env.obs()
        _, _, _, x = act(model, obs)
        last = model.value(obs, x)
    return {"obs": obs_l, "actions": torch.stack(act_l), "logp": torch.stack(lp_l),
            "acted": torch.stack(acted_l), "values": torch.stack(val_l),
            "rewards": torch.stack(rew_l), "dones": torch.stack(done_l), "last": last}


def update(model, opt, batch, cfg: Config, gen) -> dict:
    """Clipped PPO on one batch of :func:`collect` (per-agent GAE)."""
    T = len(batch["obs"])
    dones = batch["dones"][..., None].expand_as(batch["values"])
    adv, ret = gae(batch["rewards"], batch["values"], dones, batch["last"], cfg.gamma,
                   cfg.gae_lambda)
    obs = _cat(batch["obs"])
    B = batch["actions"].shape[1]
    flat = lambda x: x.reshape(T * B, *x.shape[2:])  # noqa: E731
    actions, old, acted = flat(batch["actions"]), flat(batch["logp"]), flat(batch["acted"])
    adv, ret = flat(adv), flat(ret)
    sel = adv[acted]
    adv = (adv - sel.mean()) / (sel.std() + 1e-8) if sel.numel() > 1 else adv
    logs = {"losses/policy": [], "losses/value": [], "losses/entropy": [],
            "losses/approx_kl": []}
    for _ in range(cfg.epochs):
        perm = torch.randperm(T * B, generator=gen)
        for s in range(0, T * B, cfg.minibatch):
            idx = perm[s:s + cfg.minibatch]
            o = {k: v[idx] for k, v in obs.items()}
            logits, x = model(o)
            logp_all = torch.log_softmax(logits, -1)
            lp = logp_all.gather(-1, actions[idx][..., None])[..., 0]
            p = logp_all.exp()
            ent = -(p * logp_all.clamp(min=-30)).sum(-1)
            mask = acted[idx].float()
            cnt = mask.sum().clamp(min=1.0)
            ratio = torch.exp(lp - old[idx])
            a = adv[idx]
            pg = -torch.min(ratio * a, ratio.clamp(1 - cfg.clip, 1 + cfg.clip) * a)
            pg = (pg * mask).sum() / cnt
            entropy = (ent * mask).sum() / cnt
            v = model.value(o, x)
            vloss = ((v - ret[idx]) ** 2).mean()
            loss = pg - cfg.ent_coef * entropy + cfg.vf_coef * vloss
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm)
            opt.step()
            with torch.no_grad():
                kl = (((ratio - 1) - (lp - old[idx])) * mask).sum() / cnt
            logs["losses/policy"].append(pg.item())
            logs["losses/value"].append(vloss.item())
            logs["losses/entropy"].append(entropy.item())
            logs["losses/approx_kl"].append(kl.item())
    return {k: float(np.mean(v)) for k, v in logs.items()}


def play(model, cost, flies, comm=None, greedy: bool = True,
         generator: torch.Generator | None = None) -> tuple[RoundsEnv, np.ndarray]:
    """Play decisions ``cost (B, N, M)`` to their end (argmax actions, as deployed, or
    sampled); the finished environment (``agent_task``, ``taken``, ``conflicted``) and each
    decision's team return (the sum of its agents' rewards)."""
    b, n, m = cost.shape
    env = RoundsEnv(b, n, m)
    env.load(np.arange(b), cost, flies, comm)
    over = np.zeros(b, bool)
    ret = np.zeros(b)
    with torch.no_grad():
        while not over.all():
            a, _, _, _ = act(model, env.obs(), greedy=greedy, generator=generator)
            keep = env.agent_task.copy(), env.taken.copy(), env.conflicted.copy()
            own, _, done = env.step(a.numpy())
            # a finished decision is frozen (its stalled agents would act again)
            env.agent_task[over], env.taken[over], env.conflicted[over] = (
                keep[0][over], keep[1][over], keep[2][over])
            ret += np.where(over, 0.0, own.sum(1))
            over |= done
    return env, ret


def train(model, pool, cfg: Config, on_update=None, validate=None) -> list[dict]:
    """PPO for ``cfg.updates`` updates; returns the log rows (``phase`` ``"ppo"`` or
    ``"val"``) and leaves the model with the best validated weights (when ``validate``)."""
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    sampler = Sampler(pool, rng, cfg.comm_ranges, cfg.p_range)
    envs = []
    for n in cfg.sizes:
        env = RoundsEnv(cfg.n_envs, n, n, cfg.cost_weight)
        sampler.fill(env, np.arange(cfg.n_envs))
        envs.append(env)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-5)
    rows, stats = [], {}
    started = time.perf_counter()
    steps = 0
    best = {"score": float("inf"), "state": None}

    def check(u):
        if validate is None:
            return
        res = validate(model)
        rows.append({"phase": "val", "update": u, "env_steps": steps,
                     "wall_s": time.perf_counter() - started,
                     **{f"val/{k}": float(v) for k, v in res.items()}})
        if on_update:
            on_update(rows[-1])
        if res["score"] < best["score"]:
            best["score"] = res["score"]
            best["state"] = {k: v.clone() for k, v in model.state_dict().items()}

    check(-1)
    for u in range(cfg.updates):
        env = envs[u % len(envs)]
        batch = collect(model, env, sampler, cfg, gen, stats)
        steps += cfg.rounds * cfg.n_envs
        logs = update(model, opt, batch, cfg, gen)
        rets, cf = stats.pop("returns", []), stats.pop("conflict_free", [])
        rows.append({"phase": "ppo", "update": u, "env_steps": steps, "n_agents": env.n,
                     "wall_s": time.perf_counter() - started,
                     "charts/episode_return": float(np.mean(rets)) if rets else float("nan"),
                     "charts/conflict_free": float(np.mean(cf)) if cf else float("nan"),
                     "charts/episodes": len(rets), **logs})
        if on_update:
            on_update(rows[-1])
        last = u == cfg.updates - 1 or time.perf_counter() - started > cfg.wall_s
        if (u + 1) % cfg.val_every == 0 or last:
            check(u)
        if last:
            break
    if best["state"] is not None:
        model.load_state_dict(best["state"])
    return rows
