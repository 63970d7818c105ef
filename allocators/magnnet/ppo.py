"""The one PPO trainer of MAGNNET (CTDE: decentralized actors, a centralized critic), readable
top to bottom: :class:`PPOConfig`, :func:`gae`, the :class:`Sampler` of instances, the two
training environments, :func:`collect`, :func:`ppo_update` and :func:`train`.

Every agent acts from its own view through the shared actor (parameter sharing); the critic
sees the whole state. Counting: one *environment step* is one round of one game (all its
deciding agents act); ``batch_size`` and ``minibatch_size`` count environment steps. One
update plays ``batch_size // n_envs`` rounds of ``n_envs`` games of one size (``sizes`` taken
in turn, finished games replaced by fresh instances), then runs ``epochs`` passes of clipped
PPO in minibatches; only the steps where an agent decided carry policy loss.

What differs between the variants is three explicit options of :class:`PPOConfig`:

* ``env`` — the training environment. ``"game"``: the paper's game (:class:`~allocators.
  magnnet.game.BatchedGame`, the rewards of :mod:`~allocators.magnnet.rules`, team bonus
  included), actions drawn by ``Categorical`` from torch's global generator (seeded with
  ``seed``), for the paper's networks (``dispatch train magnnet --variant paper``).
  ``"rounds"``: the plugin's own decision rounds and conflict rule (:class:`~allocators.
  magnnet.ppo_env.RoundsEnv`, rewards from the costs alone), each agent training on
  ``(1 - team_weight) * own + team_weight * team / N``, actions and minibatches drawn from a
  generator of its own (seeded with ``seed``), for the attention policy (``--variant ppo``).
* ``credit`` — the advantages. ``"team"``: every acting agent of a round gets the round's
  team advantage (the team reward against one critic value). ``"agent"``: each agent's
  advantage comes from its own reward stream against its own value of the centralized critic
  (advantages normalized over the decisions taken): an agent is credited with what it did,
  not with what the others did in the same round. In the game the team bonus reaches every
  agent of the episode at its end, those that left early too. The rounds environment pays
  per agent, so it trains with ``"agent"`` only.
* warm start (``bc_updates``, game only; off with 0, the paper's pure PPO): before PPO the
  actor imitates the optimal assignment on the states it visits (DAgger-style: roll out the
  current policy, label each deciding agent with its task in the optimal assignment of the
  open tasks to the deciding agents, minimize cross-entropy). With ``bc_defer`` an agent whose
  optimal task has a cheaper deciding contender is labelled "reject" for that round.
  Centralized information used in training only; ``critic_warmup`` PPO updates then fit only
  the critic (so an untrained critic does not undo the warm start).

When :func:`train` gets a ``validate`` function (held-out training instances, never the
evaluation ones), the weights that validate best are kept. Each environment draws its random
numbers in one fixed order (instances from ``numpy``'s generator seeded with ``seed``; actions
and minibatch orders from torch's global generator in the game, from the trainer's own in the
rounds environment), so one seed trains to the same weights every time.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numpy as np
import torch

from allocators.magnnet.game import BatchedGame
from allocators.magnnet.ppo_env import ENVS, RoundsEnv


@dataclass
class PPOConfig:
    env: str = "game"
    """training environment: ``"game"`` (the paper's game) or ``"rounds"`` (the plugin's
    decision rounds, cost-only rewards); see the module doc."""
    credit: str = "team"
    """advantages: ``"team"`` (one per round, the team reward) or ``"agent"`` (each agent's
    own reward stream and value; needs a critic with one value per agent)."""
    lr: float = 1e-5
    """Adam learning rate (paper: 1e-5)."""
    batch_size: int = 512
    """environment steps (rounds of one game) per update (paper: 512)."""
    minibatch_size: int = 64
    """environment steps per gradient step (paper: 64)."""
    epochs: int = 10
    """passes over each batch (paper: 10 SGD iterations)."""
    ent_coef: float = 0.05
    """entropy bonus coefficient (paper: 0.05)."""
    gamma: float = 0.99
    """discount factor (paper: 0.99)."""
    gae_lambda: float = 0.95
    """GAE lambda (paper: 0.95)."""
    clip: float = 0.2
    """PPO ratio clip."""
    vf_coef: float = 0.5
    """value loss coefficient."""
    max_grad_norm: float = 0.5
    """gradient norm clip."""
    n_envs: int = 32
    """games stepped together by the batched environment."""
    total_steps: int = 200_000
    """environment steps of PPO training (``total_steps // batch_size`` updates)."""
    sizes: tuple = ((8, 8),)
    """``(N, M)`` game sizes, one per update in turn (a size-agnostic model can take several)."""
    comm_ranges: tuple | None = None
    """radio ranges (metres): a share ``p_range`` of the games gets a communication graph of
    a range drawn uniformly from them, the rest a complete graph; None: complete graphs."""
    p_range: float = 0.5
    team_weight: float = 0.5
    """rounds: share of the team reward (mean over agents) in each agent's reward."""
    cost_weight: float = 1.0
    """rounds: weight of the win and stall rewards against the conflict penalty
    (:class:`~allocators.magnnet.ppo_env.RoundsEnv`)."""
    bc_updates: int = 0
    """game: imitation (warm start) updates before PPO; 0 = pure PPO as in the paper."""
    bc_lr: float = 3e-3
    """Adam learning rate of the warm start."""
    bc_defer: bool = False
    """warm-start target: agents whose optimal task has a cheaper contender wait a round
    (:func:`optimal_targets` with ``defer``)."""
    critic_warmup: int = 0
    """PPO updates at the start that fit only the critic."""
    seed: int = 0
    """seed of torch (and of the rounds environment's generator) and of the instance draws."""
    val_every: int = 20
    """PPO updates between two validations (when ``train`` gets a ``validate`` function)."""
    wall_s: float = float("inf")
    """wall-time budget: no update starts after it (a validation closes the run)."""

    def __post_init__(self) -> None:
        if self.env not in ENVS:
            raise ValueError(f"PPOConfig env {self.env!r}: expected one of {sorted(ENVS)}")
        kind = ENVS[self.env]
        if self.credit not in kind.credits:
            raise ValueError(f"PPOConfig credit {self.credit!r}: the {self.env!r} environment "
                             f"trains with {' or '.join(map(repr, kind.credits))}")
        if self.bc_updates and not kind.warm_start:
            raise ValueError(f"PPOConfig bc_updates: the {self.env!r} environment has no "
                             "teacher (the warm start needs the game's optimal assignment)")


def gae(rewards, values, dones, last_value, gamma: float, lam: float):
    """Generalized advantage estimation along the first (time) axis.

    ``rewards``, ``values``, ``dones`` have shape ``(T, ...)``; ``dones[t]`` is 1 when the
    episode ended at step ``t`` (no bootstrapping past it); ``last_value`` is the value of the
    state after step ``T - 1``. Returns ``(advantages, returns)``.
    """
    T = rewards.shape[0]
    adv = torch.zeros_like(rewards)
    last = torch.zeros_like(rewards[0])
    for t in reversed(range(T)):
        nxt = last_value if t == T - 1 else values[t + 1]
        nonterm = 1.0 - dones[t]
        delta = rewards[t] + gamma * nxt * nonterm - values[t]
        last = delta + gamma * lam * nonterm * last
        adv[t] = last
    return adv, adv + values


class Draw(NamedTuple):
    """``count`` instances cut by :meth:`Sampler.draw`: ``cost (k, N, M)``, positions, kinds,
    radio graphs (``None`` when the sampler draws none) and the world's size."""

    cost: np.ndarray
    agent_pos: np.ndarray
    task_pos: np.ndarray
    flies: np.ndarray
    comm: np.ndarray | None
    world_size: np.ndarray


class Sampler:
    """Instances ``N x M`` cut from a pool's instances (a pool of ``N' >= N`` agents: random
    agents, half of them UAVs where the pool has enough of both kinds, random tasks; agents
    and tasks shuffled, so a fixed-size model sees every order), with a radio graph for a share
    ``p_range`` of them when ``comm_ranges`` is given."""

    def __init__(self, pool, rng: np.random.Generator,
                 comm_ranges: tuple[float, float] | None = None, p_range: float = 0.5) -> None:
        self.pool, self.rng = pool, rng
        self.comm_ranges, self.p_range = comm_ranges, p_range

    def draw(self, count: int, n: int, m: int) -> Draw:
        """``count`` instances; per instance the draws come in one order (pool index, agents,
        their order, tasks, then the radio graph), so a seed gives the same instances."""
        p, rng = self.pool, self.rng
        costs, aps, tps, fls, comms = [], [], [], [], []
        for k in rng.integers(len(p), size=count):
            fl = p.flies[k]
            uav, ugv = np.flatnonzero(fl), np.flatnonzero(~fl)
            n_uav = min(len(uav), max((n + 1) // 2, n - len(ugv)))
            a = rng.permutation(np.concatenate([rng.choice(uav, n_uav, replace=False),
                                                rng.choice(ugv, n - n_uav, replace=False)]))
            t = rng.choice(p.cost.shape[2], m, replace=False)
            costs.append(p.cost[k][np.ix_(a, t)])
            aps.append(p.agent_pos[k][a])
            tps.append(p.task_pos[k][t])
            fls.append(fl[a])
            comm = np.ones((n, n), bool)
            if self.comm_ranges is not None and rng.random() < self.p_range:
                from dispatch.api.comms import comm_graph

                comm = comm_graph(p.agent_pos[k][a], rng.uniform(*self.comm_ranges))
            comms.append(comm)
        return Draw(np.stack(costs), np.stack(aps), np.stack(tps), np.stack(fls),
                    None if self.comm_ranges is None else np.stack(comms), p.world_size)

    def fill(self, env, slots) -> None:
        """Fresh instances into ``slots`` of ``env`` (a game or a rounds environment)."""
        slots = np.asarray(slots)
        if slots.size:
            d = self.draw(len(slots), env.n, env.m)
            if isinstance(env, RoundsEnv):
                env.load(slots, d.cost, d.flies, d.comm)
            else:
                env.load(slots, d.cost, d.agent_pos, d.task_pos, d.flies, d.world_size, d.comm)


def collect(model, env, sampler: Sampler, steps: int, stats: dict, *, cfg: PPOConfig,
            gen: torch.Generator | None = None):
    """Roll the current policy for ``steps`` rounds of every game of ``env`` (the environment
    ``cfg.env`` names), refilling finished games from ``sampler``.

    Returns a dict of tensors with time first: ``obs`` (dict, ``(T, B, ...)``), ``actions``,
    ``logp``, ``acted`` ``(T, B, N)``, ``values`` and ``rewards`` (``(T, B)`` under team
    credit, ``(T, B, N)`` under agent credit), ``dones`` ``(T, B)`` and ``last_value``.
    Finished episodes' figures go to ``stats`` (the environment's :meth:`charts` reads them).
    """
    kind = ENVS[cfg.env]
    obs_l, act_l, logp_l, acted_l, val_l, rew_l, done_l = [], [], [], [], [], [], []
    run = stats.setdefault(("run", env.n, env.m), kind.running(env))
    for _ in range(steps):
        obs = env.obs()
        with torch.no_grad():
            a, lp, v = kind.act(model, obs, gen)
        if (v.dim() == 2) != (cfg.credit == "agent"):
            raise ValueError(f"credit {cfg.credit!r} needs a critic with "
                             f"{'one value per agent' if cfg.credit == 'agent' else 'one value'}"
                             f" (the model's values have shape {tuple(v.shape)})")
        r, acted, done, finished = kind.step(env, a, cfg, run)
        obs_l.append(obs)
        act_l.append(a)
        logp_l.append(lp)
        acted_l.append(acted)
        val_l.append(v)
        rew_l.append(r)
        done_l.append(done)
        if len(finished):
            kind.ended(env, finished, run, stats)
            sampler.fill(env, np.asarray(finished))
    with torch.no_grad():
        last_v = kind.value(model, env.obs())
    return {"obs": {k: torch.stack([o[k] for o in obs_l]) for k in obs_l[0]},
            "actions": torch.stack(act_l), "logp": torch.stack(logp_l),
            "acted": torch.stack(acted_l), "values": torch.stack(val_l),
            "rewards": torch.stack(rew_l), "dones": torch.stack(done_l), "last_value": last_v}


def advantages(batch, cfg: PPOConfig):
    """Normalized advantages and the returns of a :func:`collect` batch, flattened to
    ``(T * B, ...)``: GAE over the team reward against one value per round (``credit``
    ``"team"``: normalized over all steps), or over each agent's reward stream against its
    own value (``"agent"``: normalized over the decisions taken, the steps of agents that
    acted)."""
    dones = batch["dones"]
    if cfg.credit == "agent":
        dones = dones[..., None].expand_as(batch["values"])
    adv, ret = gae(batch["rewards"], batch["values"], dones, batch["last_value"],
                   cfg.gamma, cfg.gae_lambda)
    T, B = adv.shape[:2]
    adv, ret = adv.reshape(T * B, *adv.shape[2:]), ret.reshape(T * B, *ret.shape[2:])
    if cfg.credit == "agent":
        sel = adv[batch["acted"].reshape(T * B, -1)]
        if sel.numel() > 1:
            adv = (adv - sel.mean()) / (sel.std() + 1e-8)
    else:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    return adv, ret


def ppo_update(model, optimizer, batch, cfg: PPOConfig, actor: bool = True,
               gen: torch.Generator | None = None) -> dict[str, float]:
    """The PPO update on one batch from :func:`collect`: ``cfg.epochs`` passes in minibatches of
    ``cfg.minibatch_size`` environment steps (orders from ``gen``; None: torch's global
    generator). Returns mean losses and entropy. With ``actor=False`` only the value loss is
    minimized (critic warm-up)."""
    kind = ENVS[cfg.env]
    adv, ret = advantages(batch, cfg)
    T, B = batch["actions"].shape[:2]
    flat = lambda x: x.reshape(T * B, *x.shape[2:])  # noqa: E731
    obs = {k: flat(v) for k, v in batch["obs"].items()}
    actions, old_lp, acted = flat(batch["actions"]), flat(batch["logp"]), flat(batch["acted"])
    logs = {"losses/policy": [], "losses/value": [], "losses/entropy": [], "losses/approx_kl": []}
    for _ in range(cfg.epochs):
        perm = torch.randperm(T * B, generator=gen)
        for s in range(0, T * B, cfg.minibatch_size):
            idx = perm[s:s + cfg.minibatch_size]
            o = {k: v[idx] for k, v in obs.items()}
            logits, z = model(o)
            lp, ent = kind.log_probs(logits, actions[idx])
            mask = acted[idx].float()
            cnt = mask.sum().clamp(min=1.0)
            ratio = torch.exp(lp - old_lp[idx])
            a = adv[idx] if cfg.credit == "agent" else adv[idx][:, None]
            pg = -torch.min(ratio * a, ratio.clamp(1 - cfg.clip, 1 + cfg.clip) * a)
            pg = (pg * mask).sum() / cnt
            entropy = (ent * mask).sum() / cnt
            v = model.value(o, z if actor else z.detach())
            vloss = ((v - ret[idx]) ** 2).mean()
            loss = cfg.vf_coef * vloss
            if actor:
                loss = loss + pg - cfg.ent_coef * entropy
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm)
            optimizer.step()
            with torch.no_grad():
                kl = (((ratio - 1) - (lp - old_lp[idx])) * mask).sum() / cnt
            logs["losses/policy"].append(pg.item())
            logs["losses/value"].append(vloss.item())
            logs["losses/entropy"].append(entropy.item())
            logs["losses/approx_kl"].append(kl.item())
    return {k: float(np.mean(v)) for k, v in logs.items()}


def train(model, pool, cfg: PPOConfig, on_update=None, validate=None) -> list[dict]:
    """Warm start (``cfg.bc_updates``) then PPO for ``cfg.total_steps`` environment steps (or
    until ``cfg.wall_s``), the sizes of ``cfg.sizes`` one per update in turn.

    ``on_update(row)`` is called after every row with the logged scalars (``phase`` ``"bc"``,
    ``"ppo"`` with ``charts/...`` and ``losses/...``, or ``"val"``); the rows are also
    returned. ``validate(model) -> dict`` (optional; held-out instances, never the evaluation
    ones): run after the warm start and every ``cfg.val_every`` PPO updates; its ``"score"``
    (lower is better) picks the weights the model ends with.
    """
    from allocators.magnnet.ppo_warm import bc_update

    kind = ENVS[cfg.env]
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed) if kind.own_generator else None
    sampler = Sampler(pool, np.random.default_rng(cfg.seed), cfg.comm_ranges, cfg.p_range)
    envs = []
    for n, m in cfg.sizes:
        env = kind.make(n, m, cfg)
        sampler.fill(env, np.arange(cfg.n_envs))
        envs.append((env, {}))
    rows: list[dict] = []
    started = time.perf_counter()
    env_steps = 0

    def log(row):
        rows.append(row)
        if on_update:
            on_update(row)

    if cfg.bc_updates:
        bc_opt = torch.optim.Adam(model.parameters(), lr=cfg.bc_lr)
        for u in range(cfg.bc_updates):
            env, _ = envs[u % len(envs)]
            loss = bc_update(model, bc_opt, env, sampler, defer=cfg.bc_defer)
            env_steps += 8 * cfg.n_envs
            log({"phase": "bc", "update": u, "env_steps": env_steps, "n_agents": env.n,
                 "wall_s": time.perf_counter() - started, "losses/imitation": loss})
        for env, _ in envs:
            sampler.fill(env, np.arange(cfg.n_envs))
    best = {"score": float("inf"), "state": None}

    def check(u):
        if validate is None:
            return
        res = validate(model)
        log({"phase": "val", "update": u, "env_steps": env_steps,
             "wall_s": time.perf_counter() - started,
             **{f"val/{k}": float(v) for k, v in res.items()}})
        if res["score"] < best["score"]:
            best["score"] = res["score"]
            best["state"] = {k: v.clone() for k, v in model.state_dict().items()}

    check(-1)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-5)
    steps_per = max(1, cfg.batch_size // cfg.n_envs)
    n_updates = cfg.total_steps // (steps_per * cfg.n_envs)
    for u in range(n_updates):
        env, stats = envs[u % len(envs)]
        batch = collect(model, env, sampler, steps_per, stats, cfg=cfg, gen=gen)
        env_steps += steps_per * cfg.n_envs
        logs = ppo_update(model, opt, batch, cfg, actor=u >= cfg.critic_warmup, gen=gen)
        log({"phase": "ppo", "update": u, "env_steps": env_steps, "n_agents": env.n,
             "wall_s": time.perf_counter() - started, **kind.charts(stats, batch), **logs})
        last = u == n_updates - 1 or time.perf_counter() - started > cfg.wall_s
        if (u + 1) % cfg.val_every == 0 or last:
            check(u)
        if last:
            break
    if best["state"] is not None:
        model.load_state_dict(best["state"])
    return rows


def validation_set(pool, n: int, m: int, count: int, seed: int = 12345):
    """A fixed :class:`~allocators.magnnet.problems.Pool` of ``count`` ``N x M`` instances cut
    from ``pool``'s instances as the trainer's :class:`Sampler` cuts them."""
    from allocators.magnnet.problems import Pool

    d = Sampler(pool, np.random.default_rng(seed)).draw(count, n, m)
    return Pool(d.cost, d.agent_pos, d.task_pos, d.flies, np.arange(count, dtype=np.int64),
                d.world_size)


def score(res: dict) -> float:
    """Validation score (lower is better): the gap plus the share of tasks not assigned
    conflict-free plus three times the share of instances left incomplete (a point of
    conflicts weighs as much as a point of gap; an instance the deterministic policy leaves
    with a task unassigned, because every deciding agent rejected in one round, three times
    as much). An all-reject policy assigns nothing and scores 1 + 1 + 3 (its tasks are never
    in conflict, but never assigned either)."""
    gap = res["gap"] if res["gap"] == res["gap"] else 1.0
    return gap + (1.0 - res["success"]) + 3.0 * (1.0 - res["complete"])


def save_checkpoint(model, path, cfg: PPOConfig | None = None, extra: dict | None = None):
    """Weights, the model's config and the training config, loadable with
    ``torch.load(path, weights_only=True)``."""
    torch.save({"config": model.config(), "state_dict": model.state_dict(),
                "train": asdict(cfg) if cfg else {}, "extra": extra or {}}, path)


def load_checkpoint(path):
    from allocators.magnnet.model import build

    ck = torch.load(path, weights_only=True, map_location="cpu")
    model = build(ck["config"])
    model.load_state_dict(ck["state_dict"])
    model.eval()
    return model, ck


def evaluate(model, pool, comm=None) -> dict[str, float]:
    """Play every instance of ``pool`` once with the model's most likely actions (as the plugin
    does) on a complete communication graph (or ``comm (B, N, N)``); mean gap to the optimal
    total over fully assigned instances, share fully assigned, conflict-free rate (tasks
    never requested by two agents in one round, over all tasks: a task nobody requested
    counts as conflict-free) and ``success`` (the benchmark's conflict-free success: tasks
    assigned without ever being in conflict, over all tasks)."""
    b, n, m = pool.cost.shape
    game = BatchedGame(b, n, m)
    game.load(np.arange(b), pool.cost, pool.agent_pos, pool.task_pos, pool.flies,
              pool.world_size, comm)
    over = torch.zeros(b, dtype=torch.bool)
    with torch.no_grad():
        for _ in range(game.max_rounds):
            logits, _ = model(game.obs())
            a = torch.where(over[:, None], torch.zeros_like(logits[..., 0], dtype=torch.long),
                            logits.argmax(-1))
            # finished games only see rejects: nothing changes in them
            _, _, _, _, done, _ = game.step(a)
            over |= done
            if over.all():
                break
    total = game.totals()
    gap = (total - game.opt_total) / game.opt_total.clamp(min=1e-9)
    full = (game.agent_task >= 0).sum(1) >= game.opt_count
    return {"gap": float(gap[full].mean()) if full.any() else float("nan"),
            "complete": float(full.float().mean()),
            "conflict_free": float(1.0 - game.conflicted.float().mean()),
            "success": float((game.taken & ~game.conflicted).float().mean())}
