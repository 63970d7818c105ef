"""MAGNNET trained for the day: PPO (CTDE) on taxi decisions of a simulated city day (issue 22).

``dispatch train magnnet --variant day`` starts from the shipped imitation weights
(``match.pt``) and fine-tunes them with the shared PPO update (:func:`allocators.magnnet.ppo.
ppo_update`, :func:`~allocators.magnnet.ppo.gae`: the trainer of the paper's variant, not a
copy) on the decisions of :class:`learning.rl.Decisions` runs of a road scenario (the Chicago
day, batched 30 s, by default).

One environment step is one dispatcher decision. The actor is the match network applied per
agent (decentralized execution: each agent's action is a softmax over "no request" and the
scores of its edges, the scores coming from the network over the decision's candidate graph);
each task's :data:`~allocators.magnnet.allocator.CANDIDATES` cheapest agents act (at most
:data:`N_MAX` agents and the first :data:`M_MAX` open requests, as the plugin cuts taxi-scale
views), the others request nothing; two requests for one task go to the cheaper (the paper's
conflict rule, :func:`learning.rl.pairs_from_choices`). With ``--value FILE`` (default the
shipped Chicago value) the actor reads the value-adjusted costs of :class:`learning.value.
ValueOption` (as ``magnnet`` with ``value`` runs it) and the centralized critic reads the value of
every idle vehicle's zone and time, with the time of day, the fleet's and the requests' counts
(the critic sees the whole decision: centralized training).

Reward of a step (as :mod:`learning.rl`): ``+1`` per request picked up until the next decision,
``-0.01`` per minute those requests waited. The team advantage (one critic value per decision)
reaches every agent that acted. Written to ``--out``: ``model.pt`` (a ``match`` checkpoint: run
it with ``magnnet``'s ``checkpoint`` parameter), ``curve.csv`` and ``curve.png`` (mean reward per
decision per update with the day and simulated hour it ended at: the reward follows the hour's
demand, so compare updates at the same hour of different days, and each finished day's served
share).
"""

from __future__ import annotations

import argparse
import csv
import logging
import math
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch
from torch import nn

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
#: the padded size of one decision's candidate graph (agents, requests)
N_MAX, M_MAX = 128, 32
#: features of the critic's state (see :meth:`DayTrainer.state`)
STATE_FEATURES = 8
WAIT_COST = 0.01  # reward per minute waited (learning.rl's default)
#: the reward the critic learns is the step's reward times this (a decision's pickups are
#: tens at N = 500; returns of hundreds slow the critic's fit; advantages are normalized)
REWARD_SCALE = 0.01


class DayPolicy(nn.Module):
    """The match network as a per-agent actor (logits ``(B, N_MAX, 1 + M_MAX)``: no request,
    then each task) and a centralized critic over the decision's state (``value(obs, z)``):
    the interface :func:`allocators.magnnet.ppo.ppo_update` trains."""

    def __init__(self, match: nn.Module) -> None:
        super().__init__()
        self.match = match
        self.reject = nn.Parameter(torch.zeros(()))  # the "no request" logit
        self.critic = nn.Sequential(nn.Linear(STATE_FEATURES, 64), nn.Tanh(),
                                    nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, 1))

    def forward(self, obs: dict):
        # each decision is scored at its own size, as the plugin scores it (the network's rank
        # features are normalized by the size, so padding would change the scores)
        mask = obs["mask"]
        s = torch.full(mask.shape, -1e4, dtype=obs["cost"].dtype, device=mask.device)
        for b, (n, m) in enumerate(obs["size"].tolist()):
            if n and m:
                s[b, :n, :m] = self.match(obs["cost"][b:b + 1, :n, :m], mask[b:b + 1, :n, :m],
                                          obs["flies"][b:b + 1, :n])[0]
        rej = self.reject.expand(s.shape[0], s.shape[1], 1)
        return torch.cat([rej, s], dim=-1), s  # z: the scores (the critic reads the state)

    def value(self, obs: dict, z=None) -> torch.Tensor:
        return self.critic(obs["state"])[..., 0]


class DayTrainer:
    """Turns the decisions of a run into the actor's observations and the critic's state."""

    def __init__(self, value=None, candidates: int = 4) -> None:
        self.value, self.candidates = value, candidates

    def sub_problem(self, problem):
        """The agents (rows) and requests (columns) that act in this decision and their costs
        as the model reads them: the first :data:`M_MAX` requests, each one's ``candidates``
        cheapest agents (at most :data:`N_MAX`), costs value-adjusted (``value``) and
        rescaled as the plugin does (median to the training instances')."""
        from allocators.magnnet.allocator import TRAIN_MAX_S, TRAIN_MEDIAN_S

        cost = self.value.costs(problem) + self.value.offset if self.value is not None \
            else np.asarray(problem.cost, float)
        cols = np.arange(min(cost.shape[1], M_MAX))
        c = cost[:, cols]
        finite = np.isfinite(c)
        if not finite.any():
            return None
        k = min(self.candidates, c.shape[0])
        top = np.argsort(np.where(finite, c, np.inf), axis=0, kind="stable")[:k]
        kept = np.zeros(c.shape, bool)
        kept[top, np.arange(c.shape[1])[None, :]] = True
        kept &= finite
        rows = np.flatnonzero(kept.any(axis=1))
        if rows.size > N_MAX:  # the agents with the cheapest kept edges
            best = np.where(kept, c, np.inf).min(axis=1)[rows]
            rows = np.sort(rows[np.argsort(best, kind="stable")[:N_MAX]])
        sub = np.where(kept[rows], c[rows], np.inf)
        med = float(np.median(sub[np.isfinite(sub)]))
        if med > TRAIN_MAX_S:
            sub = sub * (TRAIN_MEDIAN_S / med)
        return rows, cols, sub

    def state(self, problem, now: float) -> np.ndarray:
        """The critic's view of the whole decision: time of day (sin, cos), idle vehicles and
        open requests (hundreds), the mean and spread of the idle vehicles' values now, the
        mean value at the requests' drop-offs, and the decision's feasible share."""
        n, m = problem.cost.shape
        h = 2 * math.pi * (now % 86400.0) / 86400.0
        v_now = v_drop = np.zeros(1)
        if self.value is not None and n and m:
            zv = self.value.value
            nodes = problem.agents.nodes
            if nodes is None:
                nodes = [a.loc for a in problem.agents]
            v_now = zv.value(np.asarray(nodes, np.int64), now)
            drops = [t.loc if t.dropoff is None else t.dropoff for t in problem.tasks]
            v_drop = zv.value(np.asarray(drops, np.int64), now)
        feas = float(np.isfinite(problem.cost).mean()) if n and m else 0.0
        return np.array([math.sin(h), math.cos(h), n / 100.0, m / 10.0, v_now.mean(),
                         v_now.std(), v_drop.mean(), feas], np.float32)

    def observe(self, problem, now: float):
        """``(obs, rows, cols)``: one decision's padded tensors (no batch axis) and which agents
        and requests of the problem they hold (None: nobody can act)."""
        from allocators.magnnet.match import _scale

        got = self.sub_problem(problem)
        state = torch.from_numpy(self.state(problem, now))
        cost = torch.zeros(N_MAX, M_MAX)
        mask = torch.zeros(N_MAX, M_MAX, dtype=torch.bool)
        rows = cols = None
        if got is not None:
            rows, cols, sub = got
            c, mk = _scale(sub)
            cost[: len(rows), : len(cols)] = torch.from_numpy(c)
            mask[: len(rows), : len(cols)] = torch.from_numpy(mk)
        size = torch.zeros(2, dtype=torch.long)
        if rows is not None:
            size[0], size[1] = len(rows), len(cols)
        obs = {"cost": cost, "mask": mask, "flies": torch.zeros(N_MAX, dtype=torch.bool),
               "state": state, "size": size}
        return obs, rows, cols


def collect(model, trainer: DayTrainer, runs, steps: int, stats: dict):
    """Roll the policy over ``steps`` decisions of the run in ``runs['run']`` (a new day, the
    next seed, when one ends): the batch of :func:`allocators.magnnet.ppo.collect`'s format,
    one environment (``B = 1``)."""
    from torch.distributions import Categorical

    from learning.rl import pairs_from_choices

    obs_l, act_l, logp_l, acted_l, val_l, rew_l, done_l = [], [], [], [], [], [], []
    run = runs["run"]
    for _ in range(steps):
        problem = run.problem
        now = float(run.env.now)
        obs, rows, cols = trainer.observe(problem, now)
        ob = {k: v[None] for k, v in obs.items()}
        with torch.no_grad():
            logits, _ = model(ob)
            v = model.value(ob)
            a = Categorical(logits=logits).sample()
            lp = Categorical(logits=logits).log_prob(a)
        acted = torch.zeros(1, N_MAX, dtype=torch.bool)
        choice = np.zeros(problem.cost.shape[0], np.int64)
        if rows is not None:
            acted[0, : len(rows)] = obs["mask"][: len(rows)].any(dim=1)
            pick = a[0, : len(rows)].numpy()
            ok = (pick > 0) & (pick <= len(cols))
            choice[rows[ok]] = cols[pick[ok] - 1] + 1
        happened = run.answer(pairs_from_choices(problem, choice))
        pickups = happened["pickups"]
        r = len(pickups) - WAIT_COST * sum(w for _, w in pickups) / 60.0
        stats["reward"].append(r)
        obs_l.append(ob)
        act_l.append(a)
        logp_l.append(lp)
        acted_l.append(acted)
        val_l.append(v)
        rew_l.append(torch.tensor([REWARD_SCALE * r], dtype=torch.float32))
        done = run.problem is None
        done_l.append(torch.tensor([float(done)]))
        if done:
            s = run.summary
            stats["days"].append({"seed": runs["seed"],
                                  "served": s["tasks_completed"] / max(1, s["n_tasks"]),
                                  "wait": s["wait_time_mean"]})
            log.info("day seed %d: served %.2f %%", runs["seed"], 100 * stats["days"][-1]["served"])
            runs["seed"] += 1
            runs["run"] = run = runs["make"](runs["seed"])
            run.start()
    with torch.no_grad():
        ob, _, _ = trainer.observe(run.problem, float(run.env.now))
        last_v = model.value({k: v[None] for k, v in ob.items()})
    cat = lambda xs: torch.stack(xs)  # noqa: E731 - (T, B, ...)
    return {"obs": {k: cat([o[k] for o in obs_l]) for k in obs_l[0]}, "actions": cat(act_l),
            "logp": cat(logp_l), "acted": cat(acted_l), "values": cat(val_l),
            "rewards": cat(rew_l), "dones": cat(done_l), "last_value": last_v}


def train(args) -> dict:
    """PPO for the day (see the module doc); returns what was written."""
    from allocators.magnnet.allocator import shipped
    from allocators.magnnet.ppo import PPOConfig, load_checkpoint, ppo_update, save_checkpoint
    from learning.rl import Decisions
    from learning.value import ValueOption
    from learning.value_train import scenario_for

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    device = torch.device(args.device if args.device != "auto" else
                          ("cuda" if torch.cuda.is_available() else "cpu"))
    sc = scenario_for(args.scenario, args.batch_window, args.hours)
    sc = replace(sc, fleet=replace(sc.fleet, agents=args.agents))
    value = ValueOption.of(args.value) if args.value else None
    match, _ = load_checkpoint(args.init or shipped("match"))
    model = DayPolicy(match)
    cfg = PPOConfig(lr=args.lr, batch_size=args.batch, minibatch_size=args.minibatch,
                    epochs=args.epochs, ent_coef=args.ent, gamma=args.gamma, n_envs=1,
                    total_steps=args.steps, seed=args.seed)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-5)
    trainer = DayTrainer(value)
    runs = {"seed": args.seeds[0], "make": lambda s: Decisions(sc, s)}
    runs["run"] = runs["make"](runs["seed"])
    runs["run"].start()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stats: dict = {"reward": [], "days": []}
    curve = []
    t0 = time.perf_counter()
    updates = max(1, args.steps // cfg.batch_size)
    print(f"PPO for the day: {updates} updates of {cfg.batch_size} decisions, updates on {device}",
          file=sys.stderr, flush=True)
    for u in range(updates):
        model.eval()
        batch = collect(model, trainer, runs, cfg.batch_size, stats)
        model.train()
        model.to(device)
        losses = ppo_update(model, opt, _to(batch, device), cfg,
                            actor=u >= args.critic_warmup)
        model.to("cpu")
        model.eval()
        row = {"update": u + 1, "steps": (u + 1) * cfg.batch_size,
               "reward": float(np.mean(stats["reward"][-cfg.batch_size:])),
               "day": runs["seed"], "hour": round(float(runs["run"].env.now) / 3600.0, 2),
               "seconds": round(time.perf_counter() - t0, 1), **losses}
        curve.append(row)
        print(f"update {u + 1}/{updates}: reward/decision {row['reward']:.3f}, "
              f"kl {losses['losses/approx_kl']:.4f}, value loss {losses['losses/value']:.3f} "
              f"({row['seconds']:.0f} s)", file=sys.stderr, flush=True)
    save_checkpoint(model.match, out / "model.pt", cfg,
                    extra={"trained": "PPO for the day (allocators/magnnet/day.py)",
                           "init": str(args.init or "match.pt"), "scenario": str(args.scenario),
                           "agents": args.agents, "seeds_from": args.seeds[0],
                           "value": str(args.value), "days": stats["days"],
                           "updates": updates, "seconds": round(time.perf_counter() - t0, 1),
                           "ppo": asdict(cfg)})
    _write_curve(out, curve, stats["days"])
    return {"model": out / "model.pt", "curve": out / "curve.png", "days": stats["days"]}


def _to(batch: dict, device) -> dict:
    return {k: ({kk: vv.to(device) for kk, vv in v.items()} if isinstance(v, dict)
                else v.to(device)) for k, v in batch.items()}


def _write_curve(out: Path, curve: list[dict], days: list[dict]) -> None:
    with (out / "curve.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, list(curve[0]))
        w.writeheader()
        w.writerows(curve)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    ax[0].plot([r["steps"] for r in curve], [r["reward"] for r in curve])
    ax[0].set(xlabel="decisions", ylabel="mean reward per decision",
              title="PPO for the day: reward (follows the hour's demand)")
    if days:
        ax[1].plot(range(1, len(days) + 1), [100 * d["served"] for d in days], "o-")
    else:
        ax[1].text(0.5, 0.5, "no training day finished", ha="center", va="center")
    ax[1].set(xlabel="training day", ylabel="served %", title="days played while training")
    fig.tight_layout()
    fig.savefig(out / "curve.png", dpi=100)
    plt.close(fig)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default=str(ROOT / "scenarios" / "chicago_taxi.toml"))
    p.add_argument("--agents", type=int, default=500)
    p.add_argument("--batch-window", type=float, default=30.0)
    p.add_argument("--hours", type=float, default=None, help="shorter days (a quick look)")
    p.add_argument("--seeds", type=int, nargs=1, default=[100],
                   help="the first training day's seed (the next days: +1 each; keep the "
                        "evaluation's seeds 0-4 out)")
    p.add_argument("--value", default=str(ROOT / "learning" / "data" / "values" /
                                          "chicago_n500.npz"),
                   help="the learned value the actor's costs and the critic use ('' : none)")
    p.add_argument("--init", default=None, help="start from this match checkpoint "
                                                "(default: the shipped imitation match.pt)")
    p.add_argument("--steps", type=int, default=6144, help="decisions of PPO training")
    p.add_argument("--batch", type=int, default=256, help="decisions per PPO update")
    p.add_argument("--minibatch", type=int, default=64)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--lr", type=float, default=3e-5)
    p.add_argument("--ent", type=float, default=0.001)
    p.add_argument("--gamma", type=float, default=0.99, help="per decision (30 s)")
    p.add_argument("--critic-warmup", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--device", default="auto", help="auto (cuda when there is a GPU), cpu, cuda")
    p.add_argument("--out", default=str(Path("runs") / "train" / "magnnet_day"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="dispatch train magnnet --variant day",
                                description=__doc__.split("\n\n")[0])
    add_arguments(p)
    got = train(p.parse_args(argv))
    print(f"wrote {got['model']} and {got['curve']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
