"""PPO with a centralized critic (CTDE) for MAGNNET, readable top to bottom.

Hyperparameters live in :class:`PPOConfig`, whose defaults are the paper's (Adam 1e-5, batch
512, minibatch 64, 10 epochs, entropy 0.05, gamma 0.99, GAE lambda 0.95). GAE, rollout
collection and the update are functions the tests call.

CTDE: every agent acts from its own local view through the shared actor (parameter sharing);
the critic sees the whole state and estimates the *team* return (the sum of the agents'
rewards, team bonus included). Every acting agent of a round gets the round's team advantage.

Counting: one *environment step* is one round of one game (all its deciding agents act).
``batch_size`` and ``minibatch_size`` count environment steps.

Warm start (our addition, off with ``bc_updates=0``): before PPO, the actor can imitate the
optimal assignment on the states it visits (DAgger-style: roll out the current policy, label
each deciding agent with its task in the optimal assignment of the open tasks to the deciding
agents, minimize cross-entropy). With ``bc_defer`` an agent whose optimal task has a cheaper
deciding contender is labelled "reject" for that round (it waits; the rest of the optimum
stays optimal), which a policy can imitate without conflicts. This is centralized information
used in training only; at execution the policy is as decentralized as ever.

Also ours: ``critic_warmup`` PPO updates that fit only the critic first (so an untrained critic
does not undo the warm start), and, when ``train`` gets a ``validate`` function (held-out
training instances, never the evaluation ones), the weights that validate best are kept.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch.distributions import Categorical

from allocators.magnnet.game import BatchedGame


@dataclass
class PPOConfig:
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
    """environment steps of PPO training."""
    bc_updates: int = 0
    """imitation (warm start) updates before PPO; 0 = pure PPO as in the paper."""
    bc_lr: float = 3e-3
    """Adam learning rate of the warm start."""
    critic_warmup: int = 0
    """PPO updates at the start that fit only the critic (the actor is left as the warm start
    made it, instead of being pushed around by advantages of an untrained critic)."""
    bc_defer: bool = False
    """warm-start target: agents whose optimal task has a cheaper contender wait a round
    (:func:`optimal_targets` with ``defer``)."""
    seed: int = 0
    """seed of torch and of the instance draws."""
    val_every: int = 20
    """PPO updates between two validations (when ``train`` gets a ``validate`` function)."""
    credit: str = "team"
    """``"team"``: every acting agent of a round gets the round's team advantage (the team
    reward, one critic value). ``"agent"`` (ours): each agent's advantage comes from its own
    reward stream (its win, conflict, reject and stall rewards, plus the team bonus, which
    reaches every agent of the episode at its end) against its own value from the
    centralized critic (built with ``agent_values``): an agent is credited with what it did,
    not with what the other agents did in the same round."""


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


class Sampler:
    """Feeds a :class:`BatchedGame` with instances: random subsets of a pool's instances
    (a pool of ``N' >= N`` agents gives ``N``-agent instances: a random half of UAVs and of UGVs
    and random tasks; agents and tasks are shuffled, so the fixed-size model sees every order).
    """

    def __init__(self, pool, n: int, m: int, rng: np.random.Generator,
                 comm_ranges: tuple[float, float] | None = None, p_range: float = 0.5) -> None:
        self.pool, self.n, self.m, self.rng = pool, n, m, rng
        self.comm_ranges, self.p_range = comm_ranges, p_range

    def draw(self, count: int):
        p, n, m = self.pool, self.n, self.m
        ks = self.rng.integers(len(p), size=count)
        costs, aps, tps, fls = [], [], [], []
        for k in ks:
            fl = p.flies[k]
            uav, ugv = np.flatnonzero(fl), np.flatnonzero(~fl)
            n_uav = min(len(uav), (n + 1) // 2 if len(ugv) else n)
            a = np.concatenate([self.rng.choice(uav, n_uav, replace=False),
                                self.rng.choice(ugv, n - n_uav, replace=False)])
            a = self.rng.permutation(a)
            t = self.rng.choice(p.cost.shape[2], m, replace=False)
            costs.append(p.cost[k][np.ix_(a, t)])
            aps.append(p.agent_pos[k][a])
            tps.append(p.task_pos[k][t])
            fls.append(fl[a])
        return np.stack(costs), np.stack(aps), np.stack(tps), np.stack(fls), p.world_size

    def fill(self, game: BatchedGame, slots) -> None:
        slots = np.asarray(slots)
        if slots.size:
            c, a, t, f, s = self.draw(len(slots))
            comm = None
            if self.comm_ranges is not None:
                from dispatch.api.comms import comm_graph

                lo, hi = self.comm_ranges
                comm = np.stack([
                    comm_graph(a[k], self.rng.uniform(lo, hi))
                    if self.rng.random() < self.p_range else np.ones((self.n, self.n), bool)
                    for k in range(len(slots))])
            game.load(slots, c, a, t, f, s, comm)


def _cat_obs(obs_list):
    return {k: torch.stack([o[k] for o in obs_list]) for k in obs_list[0]}


def collect(model, game: BatchedGame, sampler: Sampler, steps: int, stats: dict):
    """Roll the current policy for ``steps`` rounds of every game (refilling finished games).

    Returns a dict of tensors with time first: ``obs`` (dict, ``(T, B, ...)``), ``actions``,
    ``logp``, ``acted`` ``(T, B, N)``, ``values``, ``rewards``, ``dones`` ``(T, B)`` and
    ``last_value (B,)``. Appends finished episodes' returns and gaps to ``stats``.
    """
    obs_l, act_l, logp_l, acted_l, val_l, rew_l, done_l = [], [], [], [], [], [], []
    ep_ret = stats.setdefault("_running", torch.zeros(game.B))
    for _ in range(steps):
        obs = game.obs()
        with torch.no_grad():
            logits, z = model(obs)
            v = model.value(obs, z)
            dist = Categorical(logits=logits)
            a = dist.sample()
            lp = dist.log_prob(a)
        rew, team, acted, ended, done, trunc = game.step(a)
        obs_l.append(obs)
        act_l.append(a)
        logp_l.append(lp)
        acted_l.append(acted)
        val_l.append(v)
        if v.dim() == 2:  # per-agent credit: the bonus reaches the agents that left early too
            rew_l.append(rew + torch.where(done[:, None] & ~acted, game.last_bonus[:, None],
                                           torch.zeros_like(rew)))
        else:
            rew_l.append(team)
        done_l.append(done.float())
        ep_ret += team
        if done.any():
            d = torch.nonzero(done).flatten()
            gap = (game.totals()[d] - game.opt_total[d]) / game.opt_total[d].clamp(min=1e-9)
            full = (game.agent_task[d] >= 0).sum(1) >= game.opt_count[d]
            stats.setdefault("returns", []).extend(ep_ret[d].tolist())
            stats.setdefault("gaps", []).extend(gap[full].tolist())
            stats.setdefault("complete", []).extend(full.float().tolist())
            stats.setdefault("conflict_free", []).extend(
                (1.0 - game.conflicted[d].float().mean(1)).tolist())
            ep_ret[d] = 0.0
            sampler.fill(game, d.numpy())
    with torch.no_grad():
        obs = game.obs()
        logits, z = model(obs)
        last_v = model.value(obs, z)
    return {"obs": _cat_obs(obs_l), "actions": torch.stack(act_l), "logp": torch.stack(logp_l),
            "acted": torch.stack(acted_l), "values": torch.stack(val_l),
            "rewards": torch.stack(rew_l), "dones": torch.stack(done_l), "last_value": last_v}


def ppo_update(model, optimizer, batch, cfg: PPOConfig, actor: bool = True) -> dict[str, float]:
    """The PPO update on one batch from :func:`collect`: ``cfg.epochs`` passes in minibatches of
    ``cfg.minibatch_size`` environment steps. Returns mean losses and entropy. With
    ``actor=False`` only the value loss is minimized (critic warm-up)."""
    dones = batch["dones"]
    per_agent = batch["values"].dim() == 3  # (T, B, N): one value per agent
    if per_agent:
        dones = dones[..., None].expand_as(batch["values"])
    adv, ret = gae(batch["rewards"], batch["values"], dones, batch["last_value"],
                   cfg.gamma, cfg.gae_lambda)
    T, B = adv.shape[:2]
    flat = lambda x: x.reshape(T * B, *x.shape[2:])  # noqa: E731
    obs = {k: flat(v) for k, v in batch["obs"].items()}
    actions, old_lp, acted = flat(batch["actions"]), flat(batch["logp"]), flat(batch["acted"])
    adv, ret = flat(adv), flat(ret)
    if per_agent:  # normalized over the decisions taken (the steps of agents that acted)
        sel = adv[acted]
        adv = (adv - sel.mean()) / (sel.std() + 1e-8)
    else:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    logs = {"losses/policy": [], "losses/value": [], "losses/entropy": [], "losses/approx_kl": []}
    for _ in range(cfg.epochs):
        perm = torch.randperm(T * B)
        for s in range(0, T * B, cfg.minibatch_size):
            idx = perm[s:s + cfg.minibatch_size]
            o = {k: v[idx] for k, v in obs.items()}
            logits, z = model(o)
            dist = Categorical(logits=logits)
            lp = dist.log_prob(actions[idx])
            ent = dist.entropy()
            mask = acted[idx].float()
            cnt = mask.sum().clamp(min=1.0)
            ratio = torch.exp(lp - old_lp[idx])
            a = adv[idx] if per_agent else adv[idx][:, None]
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


def optimal_targets(game: BatchedGame, defer: bool = False) -> torch.Tensor:
    """Per deciding agent, ``1 + its task`` in the optimal assignment of the open tasks to the
    deciding agents (0 for agents left out of it); ``-1`` for agents not deciding.

    ``defer``: an agent whose optimal task has a cheaper deciding contender rejects this round
    instead (it waits; the optimal assignment of what is left is unchanged by the commits of
    the others), unless that would leave the round without any request. Same optimum, more
    rounds, and a target a policy that sees its neighbours' costs per task can imitate better.
    """
    from allocators.hungarian import optimal_pairs

    dec = game.deciding()
    avail = game.available()
    cost = torch.where(avail, game.cost, torch.full_like(game.cost, float("inf"))).numpy()
    tgt = torch.full(dec.shape, -1, dtype=torch.long)
    for b in range(game.B):
        rows = np.flatnonzero(dec[b].numpy())
        if rows.size == 0:
            continue
        tgt[b, rows] = 0
        c = cost[b][rows]
        pairs = optimal_pairs(c)
        keep = [(a, t) for a, t in pairs if not defer or int(np.argmin(c[:, t])) == a]
        for a, t in (keep or pairs):
            tgt[b, rows[a]] = t + 1
    return tgt


def bc_update(model, optimizer, game: BatchedGame, sampler: Sampler, steps: int = 8,
              defer: bool = False) -> float:
    """One warm-start update: roll the current policy for ``steps`` rounds, label every state
    with :func:`optimal_targets`, and take one cross-entropy step on all of them."""
    obs_l, tgt_l = [], []
    for _ in range(steps):
        obs = game.obs()
        tgt_l.append(optimal_targets(game, defer))
        obs_l.append(obs)
        with torch.no_grad():
            logits, _ = model(obs)
            a = Categorical(logits=logits).sample()
        _, _, _, _, done, _ = game.step(a)
        if done.any():
            sampler.fill(game, torch.nonzero(done).flatten().numpy())
    obs = {k: torch.cat([o[k] for o in obs_l]) for k in obs_l[0]}
    tgt = torch.cat(tgt_l)
    logits, _ = model(obs)
    mask = tgt >= 0
    loss = torch.nn.functional.cross_entropy(logits[mask], tgt[mask])
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    return float(loss.item())


def train(model, pool, n: int, m: int, cfg: PPOConfig, on_update=None,
          sizes: list[tuple[int, int]] | None = None,
          comm_ranges: tuple[float, float] | None = None, validate=None) -> list[dict]:
    """Warm start (``cfg.bc_updates``) then PPO for ``cfg.total_steps`` environment steps.

    ``comm_ranges``: when given, half the games get a communication graph of a range drawn
    uniformly from it (metres), the rest a complete graph. ``sizes`` (size-agnostic model
    only) lists ``(N, M)`` sizes to cycle through, one per
    update; default ``[(n, m)]``. ``on_update(row)`` is called after every update with the
    logged scalars (``charts/...``, ``losses/...``); the rows are also returned.

    ``validate(model) -> dict`` (optional; held-out instances, never the evaluation ones): run
    after the warm start and every ``cfg.val_every`` PPO updates; its ``"score"`` (lower is
    better) picks the weights the model ends with (logged as ``phase="val"`` rows).
    """
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    sizes = sizes or [(n, m)]
    games = []
    for nn_, mm in sizes:
        sampler = Sampler(pool, nn_, mm, rng, comm_ranges)
        game = BatchedGame(cfg.n_envs, nn_, mm)
        sampler.fill(game, np.arange(cfg.n_envs))
        games.append((game, sampler, {}))
    rows: list[dict] = []
    started = time.perf_counter()
    env_steps = 0
    if cfg.bc_updates:
        bc_opt = torch.optim.Adam(model.parameters(), lr=cfg.bc_lr)
        for u in range(cfg.bc_updates):
            game, sampler, _ = games[u % len(games)]
            loss = bc_update(model, bc_opt, game, sampler, defer=cfg.bc_defer)
            env_steps += 8 * cfg.n_envs
            row = {"phase": "bc", "update": u, "env_steps": env_steps, "n_agents": game.n,
                   "wall_s": time.perf_counter() - started, "losses/imitation": loss}
            rows.append(row)
            if on_update:
                on_update(row)
        for game, sampler, _ in games:
            sampler.fill(game, np.arange(cfg.n_envs))
    best = {"score": float("inf"), "state": None}

    def check(u):
        if validate is None:
            return
        res = validate(model)
        row = {"phase": "val", "update": u, "env_steps": env_steps,
               "wall_s": time.perf_counter() - started,
               **{f"val/{k}": float(v) for k, v in res.items()}}
        rows.append(row)
        if res["score"] < best["score"]:
            best["score"] = res["score"]
            best["state"] = {k: v.clone() for k, v in model.state_dict().items()}

    check(-1)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-5)
    steps_per = max(1, cfg.batch_size // cfg.n_envs)
    n_updates = cfg.total_steps // (steps_per * cfg.n_envs)
    for u in range(n_updates):
        game, sampler, stats = games[u % len(games)]
        batch = collect(model, game, sampler, steps_per, stats)
        env_steps += steps_per * cfg.n_envs
        logs = ppo_update(model, opt, batch, cfg, actor=u >= cfg.critic_warmup)
        rets = stats.pop("returns", [])
        gaps = stats.pop("gaps", [])
        comp = stats.pop("complete", [])
        cf = stats.pop("conflict_free", [])
        row = {"phase": "ppo", "update": u, "env_steps": env_steps, "n_agents": game.n,
               "wall_s": time.perf_counter() - started,
               "charts/episode_return": float(np.mean(rets)) if rets else float("nan"),
               "charts/mean_step_reward": float(batch["rewards"].mean()),
               "charts/gap": float(np.mean(gaps)) if gaps else float("nan"),
               "charts/complete": float(np.mean(comp)) if comp else float("nan"),
               "charts/conflict_free": float(np.mean(cf)) if cf else float("nan"),
               "charts/episodes": len(rets), **logs}
        rows.append(row)
        if on_update:
            on_update(row)
        if (u + 1) % cfg.val_every == 0 or u == n_updates - 1:
            check(u)
    if best["state"] is not None:
        model.load_state_dict(best["state"])
    return rows


def validation_set(pool, n: int, m: int, count: int, seed: int = 12345):
    """A fixed :class:`~allocators.magnnet.problems.Pool` of ``count`` ``N x M`` instances cut
    from ``pool``'s instances as the trainer's :class:`Sampler` cuts them."""
    from allocators.magnnet.problems import Pool

    c, a, t, f, s = Sampler(pool, n, m, np.random.default_rng(seed)).draw(count)
    return Pool(c, a, t, f, np.arange(count, dtype=np.int64), s)


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
