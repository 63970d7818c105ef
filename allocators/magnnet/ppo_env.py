"""The training environment of the ``ppo`` variant: many static decisions played at once
under the plugin's own decision rounds and conflict rule (issue 33).

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
"""

from __future__ import annotations

import numpy as np
import torch

from allocators.magnnet.attention import observe, requests
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
