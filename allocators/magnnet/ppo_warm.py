"""The imitation warm start of :func:`allocators.magnnet.ppo.train` (``bc_updates``, the game
environment only): the optimal assignment as the teacher, DAgger-style on the states the
current policy visits. Centralized information used in training only."""

from __future__ import annotations

import numpy as np
import torch
from torch.distributions import Categorical

from allocators.magnnet.game import BatchedGame


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


def bc_update(model, optimizer, game: BatchedGame, sampler, steps: int = 8,
              defer: bool = False) -> float:
    """One warm-start update: roll the current policy for ``steps`` rounds (actions from
    torch's global generator; finished games refilled from ``sampler``), label every state with
    :func:`optimal_targets`, and take one cross-entropy step on all of them. Returns the loss."""
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
