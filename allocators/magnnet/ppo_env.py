"""The training environments of the PPO trainer. :class:`RoundsEnv`, the ``ppo`` variant's:
many static decisions played at once under the plugin's own decision rounds and conflict rule.

A decision is a cost matrix (seconds, ``inf`` infeasible), the agents' kinds and a radio
graph. It is played in rounds exactly as :func:`dispatch.api.decentralized.run_rounds` plays it on
a complete graph without loss (every agent hears every request): the agents that decide are
those unassigned with an open feasible task; each is given its observation
(:func:`allocators.magnnet.attention.observe`), acts, and its action becomes a request by
:func:`allocators.magnnet.attention.requests` (the plugin's rule); a round in which nobody
requests or waits ends the decision; the requests are settled by the kernel's conflict rule
(:func:`dispatch.api.decentralized.resolve_conflicts`: the cheapest requester wins, ties to the
lowest index). No SimPy: a static decision needs only its cost matrix. Games of a radio graph
(training under limited range) still learn of every won task at once (the game's beliefs are
global); the plugin under limited range relays the news hop by hop.

Rewards come from the cost matrix only (no optimal assignment, no teacher), per agent:

* ``w (R_WIN - c_ij / c_mean)`` when it wins task ``j`` (``w``: ``cost_weight``, default 1;
  it weighs the win and stall rewards against the conflict penalty) (``c_mean``: the instance's mean
  finite
  cost): a win is worth more the cheaper it is, and requesting is worth more than waiting
  (without ``R_WIN`` a win is an immediate loss and waiting is paid only at the end: the
  first training run waited);
* :data:`R_CONFLICT` for each request of a task that two or more agents requested that round;
* ``w`` :data:`R_STALL` when the decision ends while it is still deciding (unassigned while an open
  task it can serve is left).

The *team* reward of a round is the sum over agents; each agent trains on
``(1 - team_weight) * own + team_weight * team / N`` (``team_weight`` of the trainer).

The trainer (:mod:`allocators.magnnet.ppo`) reaches an environment through its kind here
(:data:`ENVS`): :class:`GameKind` for the paper's game, :class:`RoundsKind` for this one. A kind
says how actions are drawn and scored, what an agent is rewarded with and what a finished
episode reports. :func:`play` plays decisions of this environment to their end.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.distributions import Categorical

from allocators.magnnet.attention import act, observe, requests
from allocators.magnnet.game import BatchedGame
from dispatch.api.decentralized import WAIT, resolve_conflicts

R_WIN = 2.0
R_CONFLICT = -1.0
R_STALL = -3.0


class RoundsEnv:
    """``B`` decisions of one size ``N x M`` played round by round (numpy state)."""

    def __init__(self, batch: int, n: int, m: int, cost_weight: float = 1.0) -> None:
        self.B, self.n, self.m = batch, n, m
        self.cost_weight = cost_weight
        self.cost = np.zeros((batch, n, m))
        self.flies = np.zeros((batch, n), bool)
        self.comm = np.ones((batch, n, n), bool)
        self.c_mean = np.ones(batch)
        self.agent_task = np.full((batch, n), -1, np.int64)
        self.taken = np.zeros((batch, m), bool)
        self.conflicted = np.zeros((batch, m), bool)
        self.round = np.zeros(batch, np.int64)

    def load(self, slots, cost, flies, comm=None) -> None:
        """New decisions in ``slots``: ``cost (k, N, M)``, ``flies (k, N)``, ``comm (k, N, N)``
        (None: complete graphs)."""
        slots = np.asarray(slots)
        self.cost[slots] = cost
        self.flies[slots] = flies
        self.comm[slots] = True if comm is None else comm
        for k, s in enumerate(slots.tolist()):
            fin = cost[k][np.isfinite(cost[k])]
            self.c_mean[s] = float(fin.mean()) if fin.size else 1.0
        self.agent_task[slots] = -1
        self.taken[slots] = False
        self.conflicted[slots] = False
        self.round[slots] = 0

    def deciding(self) -> np.ndarray:
        return (self.agent_task < 0) & (np.isfinite(self.cost) & ~self.taken[:, None, :]).any(-1)

    def obs(self) -> dict[str, torch.Tensor]:
        """Every game's observation, as the plugin builds it for the same state."""
        return observe(self.cost, self.deciding(), ~self.taken, self.comm, self.flies)

    def totals(self) -> np.ndarray:
        a = np.maximum(self.agent_task, 0)
        c = np.take_along_axis(self.cost, a[..., None], 2)[..., 0]
        return np.where(self.agent_task >= 0, c, 0.0).sum(1)

    def step(self, actions: np.ndarray):
        """One round of every game; ``actions (B, N)`` in ``0..M``. Returns ``(own (B, N),
        acted (B, N), done (B,))``: each agent's own reward, the agents that decided, the
        games whose decision ended (reload them before the next step)."""
        own = np.zeros((self.B, self.n))
        dec = self.deciding()
        done = np.zeros(self.B, bool)
        for b in range(self.B):
            agents = np.flatnonzero(dec[b])
            if agents.size == 0:
                done[b] = True
                continue
            choice = requests(actions[b, agents], int(self.round[b]), self.m)
            self.round[b] += 1
            asked = choice >= 0
            if not asked.any() and not (choice == WAIT).any():
                done[b] = True  # the shared loop stops: nobody requests or waits
                continue
            ra, rt = agents[asked], choice[asked]
            winners = resolve_conflicts(self.cost[b], ra, rt)
            count = np.bincount(rt, minlength=self.m)
            contested = count[rt] > 1
            own[b, ra[contested]] += R_CONFLICT
            self.conflicted[b, rt[contested]] = True
            for t, a in winners.items():
                self.agent_task[b, a] = t
                self.taken[b, t] = True
                own[b, a] += self.cost_weight * (R_WIN - self.cost[b, a, t] / self.c_mean[b])
        still = self.deciding()
        done |= ~still.any(1)
        own += np.where(done[:, None] & still, self.cost_weight * R_STALL, 0.0)
        return own, dec, done


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


class GameKind:
    """``env="game"``: the paper's game; ``Categorical`` actions from torch's global generator;
    per episode the team return, the gap to the optimum, completeness and conflicts."""

    credits = ("team", "agent")
    warm_start = True
    own_generator = False

    @staticmethod
    def make(n: int, m: int, cfg) -> BatchedGame:
        return BatchedGame(cfg.n_envs, n, m)

    @staticmethod
    def act(model, obs, gen):
        """Sampled actions, their log-probabilities and the critic's values."""
        logits, z = model(obs)
        v = model.value(obs, z)
        dist = Categorical(logits=logits)
        a = dist.sample()
        return a, dist.log_prob(a), v

    @staticmethod
    def value(model, obs):
        _, z = model(obs)
        return model.value(obs, z)

    @staticmethod
    def log_probs(logits, actions):
        """The log-probabilities of ``actions`` and the entropies under ``logits``."""
        dist = Categorical(logits=logits)
        return dist.log_prob(actions), dist.entropy()

    @staticmethod
    def running(env: BatchedGame):
        return torch.zeros(env.B)

    @staticmethod
    def step(env: BatchedGame, a, cfg, run):
        """One round: the rewards trained on (``credit``), the agents that acted, the finished
        games' slots (numpy); ``run`` (each game's team return so far) grows in place."""
        rew, team, acted, _, done, _ = env.step(a)
        if cfg.credit == "agent":  # the bonus reaches the agents that left early too
            r = rew + torch.where(done[:, None] & ~acted, env.last_bonus[:, None],
                                  torch.zeros_like(rew))
        else:
            r = team
        run += team
        return r, acted, done.float(), torch.nonzero(done).flatten()

    @staticmethod
    def ended(env: BatchedGame, d, run, stats: dict) -> None:
        gap = (env.totals()[d] - env.opt_total[d]) / env.opt_total[d].clamp(min=1e-9)
        full = (env.agent_task[d] >= 0).sum(1) >= env.opt_count[d]
        stats.setdefault("returns", []).extend(run[d].tolist())
        stats.setdefault("gaps", []).extend(gap[full].tolist())
        stats.setdefault("complete", []).extend(full.float().tolist())
        stats.setdefault("conflict_free", []).extend(
            (1.0 - env.conflicted[d].float().mean(1)).tolist())
        run[d] = 0.0

    @staticmethod
    def charts(stats: dict, batch: dict) -> dict:
        rets, gaps = stats.pop("returns", []), stats.pop("gaps", [])
        comp, cf = stats.pop("complete", []), stats.pop("conflict_free", [])
        mean = lambda xs: float(np.mean(xs)) if xs else float("nan")  # noqa: E731
        return {"charts/episode_return": mean(rets),
                "charts/mean_step_reward": float(batch["rewards"].mean()),
                "charts/gap": mean(gaps), "charts/complete": mean(comp),
                "charts/conflict_free": mean(cf), "charts/episodes": len(rets)}


class RoundsKind:
    """``env="rounds"``: the plugin's decision rounds (:class:`RoundsEnv`); actions and
    minibatch orders from the trainer's own generator; per episode the team return per agent
    and the share of tasks assigned conflict-free."""

    credits = ("agent",)
    warm_start = False
    own_generator = True

    @staticmethod
    def make(n: int, m: int, cfg) -> RoundsEnv:
        return RoundsEnv(cfg.n_envs, n, m, cfg.cost_weight)

    @staticmethod
    def act(model, obs, gen):
        a, lp, _, x = act(model, obs, greedy=False, generator=gen)
        return a, lp, model.value(obs, x)

    @staticmethod
    def value(model, obs):
        _, _, _, x = act(model, obs)
        return model.value(obs, x)

    @staticmethod
    def log_probs(logits, actions):
        logp_all = torch.log_softmax(logits, -1)
        lp = logp_all.gather(-1, actions[..., None])[..., 0]
        p = logp_all.exp()
        return lp, -(p * logp_all.clamp(min=-30)).sum(-1)  # (masked logits: 0 * -1e9)

    @staticmethod
    def running(env: RoundsEnv):
        return np.zeros(env.B)

    @staticmethod
    def step(env: RoundsEnv, a, cfg, run):
        own, acted, done = env.step(a.numpy())
        team = own.sum(1, keepdims=True)
        r = (1 - cfg.team_weight) * own + cfg.team_weight * team / env.n
        run += team[:, 0]
        return (torch.from_numpy(r).float(), torch.from_numpy(acted),
                torch.from_numpy(done).float(), np.flatnonzero(done))

    @staticmethod
    def ended(env: RoundsEnv, d, run, stats: dict) -> None:
        stats.setdefault("returns", []).extend((run[d] / env.n).tolist())
        stats.setdefault("conflict_free", []).extend(
            (env.taken[d] & ~env.conflicted[d]).mean(1).tolist())
        run[d] = 0.0

    @staticmethod
    def charts(stats: dict, batch: dict) -> dict:
        rets, cf = stats.pop("returns", []), stats.pop("conflict_free", [])
        return {"charts/episode_return": float(np.mean(rets)) if rets else float("nan"),
                "charts/conflict_free": float(np.mean(cf)) if cf else float("nan"),
                "charts/episodes": len(rets)}


#: the training environments by :attr:`allocators.magnnet.ppo.PPOConfig.env`
ENVS = {"game": GameKind, "rounds": RoundsKind}
