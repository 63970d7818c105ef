"""MAGNNET-ppo: an attention policy over agent-task pairs, and the decision rule it is
trained and deployed with (issue 33).

The paper names attention as its next step ("introducing an attention mechanism to improve
conflict resolution"). This module holds the three pieces that the PPO training environment
(:mod:`allocators.magnnet.ppo_env`) and the ``magnnet`` plugin's variant ``"ppo"`` share, so
that the policy trained is the policy deployed:

* :func:`observe` — the observation of one or many decisions (a batch), from the costs, the
  agents still deciding, the tasks believed open, the radio graph and the agents' kinds;
* :class:`AttentionPolicy` — the network: every agent-task pair has a hidden state; each layer
  lets a pair attend over the *tasks* of its agent (row attention) and over the *agents within
  radio range* of its agent for the same task (column attention, masked by the adjacency),
  then a feed-forward block. Nothing depends on ``N`` or ``M``: one model for every size.
  The actor scores ``{wait, task 1 .. task M}`` per agent; the critic (training only,
  centralized) pools every pair and agent and gives one value per agent;
* :func:`requests` — the decision rule: action ``0`` is :data:`~dispatch.api.decentralized.WAIT`
  (request nothing this round, decide again) until round :func:`patience`, then ``-1`` (done
  waiting: a round where nobody requests or waits ends the decision, as
  :func:`dispatch.api.decentralized.run_rounds` does); action ``j + 1`` requests task ``j``.

Decentralized execution. A pair's state after ``L`` layers depends on the agent's own costs,
the open tasks, and the costs of the agents within ``L`` radio hops (column attention is
masked by the adjacency): what the agent receives from its neighbours' broadcasts, relayed
``L - 1`` times. On a complete graph (the paper's setting) every agent sees the same
observation, and one forward pass gives every agent's own scores.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from dispatch.api.decentralized import WAIT

#: Seconds per model cost unit, and the cap (also the value of unavailable pairs).
COST_SCALE = 10.0
COST_CAP = 3.0
#: Input features per pair (see :func:`observe`).
PAIR_F = 6
#: Input features per agent: ``[deciding, flies]``.
AGENT_F = 2


def patience(m: int) -> int:
    """The round from which an agent that would wait rejects instead (``2 M + 2``, the
    paper variant's round limit): a decision cannot wait forever."""
    return 2 * m + 2


def observe(cost, deciding, open_tasks, comm, flies) -> dict[str, torch.Tensor]:
    """The observation of ``B`` decisions (torch tensors, batch first).

    ``cost (B, N, M)`` seconds (``inf``: infeasible), ``deciding (B, N)`` bool (agents that
    decide this round), ``open_tasks (B, M)`` bool (believed open), ``comm (B, N, N)`` bool
    (radio links), ``flies (B, N)`` bool. Per pair ``(i, j)`` (scaled units, capped):

    0. ``c_ij`` (the cap where the pair is not available);
    1. available (``i`` decides, ``j`` open, feasible);
    2. ``c_ij - min_j' c_ij'`` over ``i``'s available tasks (its regret for ``j``);
    3. ``c_ij - min_k c_kj`` over the deciding agents ``k`` that ``i`` hears (itself included:
       negative never, 0 when ``i`` is the cheapest it hears of);
    4. how many deciding agents ``i`` hears are cheaper for ``j`` (divided by 10);
    5. the task's open flag.
    """
    cost = torch.as_tensor(cost, dtype=torch.float64)
    deciding = torch.as_tensor(deciding, dtype=torch.bool)
    open_tasks = torch.as_tensor(open_tasks, dtype=torch.bool)
    comm = torch.as_tensor(comm, dtype=torch.bool)
    flies = torch.as_tensor(flies, dtype=torch.bool)
    n = cost.shape[1]
    avail = torch.isfinite(cost) & deciding[:, :, None] & open_tasks[:, None, :]
    c = torch.where(avail, (cost / COST_SCALE).clamp(max=COST_CAP),
                    torch.full_like(cost, COST_CAP)).float()
    rowmin = c.amin(-1, keepdim=True)
    adj = comm | torch.eye(n, dtype=torch.bool)[None]
    # ck[b, i, k, j]: the cost of agent k for task j as agent i hears it
    hear = adj & deciding[:, None, :]
    ck = torch.where(hear[..., None], c[:, None].expand(-1, n, -1, -1),
                     torch.full_like(c[:, None].expand(-1, n, -1, -1), COST_CAP))
    colmin = torch.minimum(ck.amin(2), c)
    cheaper = ((ck < c[:, :, None]) & hear[..., None]).sum(2).float() / 10.0
    pair = torch.stack([c, avail.float(), c - rowmin, c - colmin, cheaper,
                        open_tasks[:, None, :].expand_as(c).float()], -1)
    pair = torch.where(avail[..., None], pair, torch.zeros_like(pair))
    pair[..., 0] = torch.where(avail, c, torch.full_like(c, COST_CAP))
    agents = torch.stack([deciding.float(), flies.float()], -1)
    return {"pair": pair, "agents": agents, "available": avail, "adjacency": adj,
            "deciding": deciding}


class _Attention(nn.Module):
    """Multi-head attention along one axis with a boolean mask of allowed keys."""

    def __init__(self, d: int, heads: int) -> None:
        super().__init__()
        self.h, self.dk = heads, d // heads
        self.qkv = nn.Linear(d, 3 * d)
        self.out = nn.Linear(d, d)

    def forward(self, x, allowed):
        """``x (..., L, d)``, ``allowed (..., L, L)`` (query, key) -> ``(..., L, d)``. A query
        without any allowed key attends to nothing (zeros)."""
        *lead, L, d = x.shape
        q, k, v = self.qkv(x).reshape(*lead, L, 3, self.h, self.dk).unbind(-3)
        s = torch.einsum("...qhd,...khd->...hqk", q, k) / math.sqrt(self.dk)
        mask = allowed.unsqueeze(-3)
        s = s.masked_fill(~mask, -1e9)
        w = torch.softmax(s, -1) * mask.any(-1, keepdim=True)
        o = torch.einsum("...hqk,...khd->...qhd", w, v).reshape(*lead, L, d)
        return self.out(o)


class _Layer(nn.Module):
    """Row attention (a pair over its agent's tasks), column attention (a pair over the same
    task's pairs of the agents in radio range), feed-forward; pre-norm residuals."""

    def __init__(self, d: int, heads: int) -> None:
        super().__init__()
        self.n1, self.n2, self.n3 = nn.LayerNorm(d), nn.LayerNorm(d), nn.LayerNorm(d)
        self.row = _Attention(d, heads)
        self.col = _Attention(d, heads)
        self.ff = nn.Sequential(nn.Linear(d, 2 * d), nn.ReLU(), nn.Linear(2 * d, d))

    def forward(self, x, row_ok, col_ok):
        # x (B, N, M, d); row_ok (B, N, M, M); col_ok (B, M, N, N)
        x = x + self.row(self.n1(x), row_ok)
        xc = self.n2(x).transpose(1, 2)  # (B, M, N, d)
        x = x + self.col(xc, col_ok).transpose(1, 2)
        return x + self.ff(self.n3(x))


class AttentionPolicy(nn.Module):
    """The ``ppo`` variant's network (see the module doc); ``d`` hidden units per pair,
    ``layers`` attention layers of ``heads`` heads."""

    variant = "ppo"

    def __init__(self, d: int = 32, layers: int = 2, heads: int = 4) -> None:
        super().__init__()
        self.d, self.layers_n, self.heads = d, layers, heads
        self.pair_in = nn.Linear(PAIR_F, d)
        self.agent_in = nn.Linear(AGENT_F, d)
        self.layers = nn.ModuleList([_Layer(d, heads) for _ in range(layers)])
        self.norm = nn.LayerNorm(d)
        self.pair_out = nn.Linear(d, 1)
        self.wait_out = nn.Sequential(nn.Linear(2 * d, d), nn.ReLU(), nn.Linear(d, 1))
        self.critic = nn.Sequential(nn.Linear(3 * d, 2 * d), nn.ReLU(), nn.Linear(2 * d, 1))

    def config(self) -> dict:
        return {"variant": "ppo", "d": self.d, "layers": self.layers_n, "heads": self.heads}

    def trunk(self, obs):
        """Pair states ``(B, N, M, d)``."""
        avail, adj = obs["available"], obs["adjacency"]
        b, n, m = avail.shape
        x = self.pair_in(obs["pair"]) + self.agent_in(obs["agents"])[:, :, None]
        # a pair attends over its agent's available tasks; over its task's pairs of the
        # deciding agents its agent hears (the adjacency: radio range)
        row_ok = avail[:, :, None, :].expand(b, n, m, m)
        col_ok = (adj[:, None] & obs["deciding"][:, None, None, :]).expand(b, m, n, n)
        for layer in self.layers:
            x = layer(x, row_ok, col_ok)
        return self.norm(x)

    def forward(self, obs):
        """Masked logits ``(B, N, M + 1)`` (index 0: wait) and the pair states."""
        x = self.trunk(obs)
        avail = obs["available"]
        w = avail[..., None].float()
        cnt = w.sum(2).clamp(min=1.0)
        mean = (x * w).sum(2) / cnt
        big = torch.where(avail[..., None], x, torch.full_like(x, -1e4)).amax(2)
        big = torch.where(avail.any(-1, keepdim=True), big, torch.zeros_like(big))
        wait = self.wait_out(torch.cat([mean, big], -1))
        logits = torch.cat([wait, self.pair_out(x)[..., 0]], -1)
        ok = torch.cat([torch.ones_like(avail[..., :1]), avail], -1)
        return logits.masked_fill(~ok, -1e9), x

    def value(self, obs, x):
        """Centralized critic (training only): one value per agent ``(B, N)`` from its row's
        pooled pairs and the whole instance's pooled pairs."""
        avail = obs["available"]
        w = avail[..., None].float()
        row = (x * w).sum(2) / w.sum(2).clamp(min=1.0)
        allw = w.sum((1, 2)).clamp(min=1.0)
        glob = (x * w).sum((1, 2)) / allw
        gmax = torch.where(avail[..., None], x, torch.full_like(x, -1e4)).amax((1, 2))
        gmax = torch.where(avail.any(-1).any(-1, keepdim=True), gmax, torch.zeros_like(gmax))
        n = x.shape[1]
        h = torch.cat([row, glob[:, None].expand(-1, n, -1), gmax[:, None].expand(-1, n, -1)],
                      -1)
        return self.critic(h)[..., 0]


def requests(actions: np.ndarray, round_: int, m: int) -> np.ndarray:
    """Actions (``0``: wait, ``j + 1``: task ``j``) as the requests of
    :meth:`dispatch.api.decentralized.DecentralizedAllocator.choose`: a task index, ``WAIT``, or
    ``-1`` for a wait from round :func:`patience` on."""
    a = np.asarray(actions, np.int64)
    idle = WAIT if round_ < patience(m) else -1
    return np.where(a > 0, a - 1, idle)


def decide(model, cost, deciding, open_tasks, comm, flies, round_: int) -> np.ndarray:
    """The requests ``(N,)`` of one decision's round, as deployed: :func:`observe` (batch of
    one), the argmax of :func:`act`, :func:`requests`. Entries of agents not deciding are
    meaningless (the caller keeps the deciding ones)."""
    obs = observe(np.array(cost, np.float64)[None], np.asarray(deciding)[None],
                  np.asarray(open_tasks)[None], np.array(comm, dtype=bool)[None],
                  np.asarray(flies)[None])
    with torch.no_grad():
        a, _, _, _ = act(model, obs)
    return requests(a[0].numpy(), round_, np.asarray(cost).shape[1])


def act(model, obs, greedy: bool = True, generator: torch.Generator | None = None):
    """The actions ``(B, N)`` of every agent (argmax, as deployed; or sampled, in training),
    with their log-probabilities, the logits and the pair states."""
    logits, x = model(obs)
    if greedy:
        a = logits.argmax(-1)
    else:
        p = torch.softmax(logits, -1)
        a = torch.multinomial(p.reshape(-1, p.shape[-1]), 1, generator=generator).reshape(
            p.shape[:-1])
    lp = torch.log_softmax(logits, -1).gather(-1, a[..., None])[..., 0]
    return a, lp, logits, x
