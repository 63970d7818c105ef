"""MAGNNET's networks, as Section III of the paper describes them.

Inputs are the observation tensors of :mod:`allocators.magnnet.game`, batched:
``agents (B, N, 5)`` = ``[status, flies, x, y, z]``, ``cost (B, N, M)`` (scaled, capped),
``available (B, N, M)``, ``tasks (B, M, 4)`` = ``[open, x, y, z]`` and ``adjacency (B, N, N)``
(communication links, diagonal included).

The graph is heterogeneous: agent nodes, task nodes, agent-task edges (every pair; the edge
carries the pair's scaled cost and availability) and agent-agent edges (the communication
graph). :class:`HeteroGraphConv` is one graph-convolution layer over it in dense batched form
(many tiny graphs of equal size at once: one batched matrix product per edge type instead of
scatter operations). It computes the same function as the layer built from PyTorch Geometric's
parts in :mod:`allocators.magnnet.pyg_layer` (a test checks it) and trains faster: 1.5x PyG's
layer alone, 7-26x with the PyG batch built per minibatch (``benchmarks/gnn_layers.py``). Messages flow task -> agent and agent -> agent only; task nodes are
updated from their own state. So after two layers an agent's embedding depends on its own
features, every task, and the agents within two communication hops, and nothing else: that is
what makes execution decentralized (each agent can compute its own embedding from what its
neighbourhood sends it; a test checks it).
"""

from __future__ import annotations

import torch
from torch import nn

from allocators.magnnet import rules

AGENT_F = 5
TASK_F = 4


class HeteroGraphConv(nn.Module):
    r"""One graph convolution over agent and task nodes.

    .. math::
        h_i' = \mathrm{ReLU}\Big(W_s h_i + \frac{1}{|\mathcal N(i)|}\sum_{k \in \mathcal N(i)}
               W_a h_k + \frac1M \sum_j W_t [g_j \,\|\, e_{ij}] + b\Big), \qquad
        g_j' = \mathrm{ReLU}(W_g g_j + b_g)

    with :math:`\mathcal N(i)` the communication neighbours of agent ``i`` (itself included).

    Args:
        agent_in, task_in, edge_in: feature sizes of agent nodes, task nodes, agent-task edges.
        out: output size of both node types (default in MAGNNET: 6).

    Shapes:
        agents ``(B, N, agent_in)``, tasks ``(B, M, task_in)``, edges ``(B, N, M, edge_in)``,
        adjacency ``(B, N, N)`` -> ``(B, N, out)``, ``(B, M, out)``.
    """

    def __init__(self, agent_in: int, task_in: int, edge_in: int, out: int) -> None:
        super().__init__()
        self.self_lin = nn.Linear(agent_in, out)
        self.nb_lin = nn.Linear(agent_in, out, bias=False)
        self.task_lin = nn.Linear(task_in + edge_in, out, bias=False)
        self.task_self = nn.Linear(task_in, out)

    def reset_parameters(self) -> None:
        for m in (self.self_lin, self.nb_lin, self.task_lin, self.task_self):
            m.reset_parameters()

    def forward(self, h, g, e, adj):
        deg = adj.sum(-1, keepdim=True).clamp(min=1.0)
        nb = torch.bmm(adj, self.nb_lin(h)) / deg
        m = g.shape[1]
        ge = torch.cat([g[:, None].expand(-1, h.shape[1], -1, -1), e], -1)
        tk = self.task_lin(ge).sum(2) / max(m, 1)
        return torch.relu(self.self_lin(h) + nb + tk), torch.relu(self.task_self(g))


def _edges(obs):
    return torch.stack([obs["cost"], obs["available"].float()], -1)


def _mask(logits_tasks, reject, available):
    logits = torch.cat([reject, logits_tasks], -1)
    ok = torch.cat([torch.ones_like(available[..., :1], dtype=torch.bool),
                    available.bool()], -1)
    return logits.masked_fill(~ok, -1e9)


class MagnnetPolicy(nn.Module):
    """The paper's model for ``N`` agents and ``M`` tasks.

    Agent nodes hold ``[status, flies, x, y, z]`` and the agent's ``M`` scaled cost estimates
    (the paper: "position, status and cost estimates {c_ij}"); task nodes ``[open, x, y, z]``.
    Two :class:`HeteroGraphConv` layers of ``hidden`` units (6) give each agent an embedding
    ``z_i``; the actor is an MLP over ``[status, M costs, z_i]`` (input ``M + 7``) with one
    hidden layer of 128 and a softmax over ``{reject, task 1 .. task M}``; the centralized
    critic is an MLP (128 hidden) over all embeddings and task states, used in training only.
    With ``agent_values`` (ours, training only: the actor is unchanged) the critic's output
    layer gives one value per agent instead of the team's one (per-agent credit, see
    :class:`~allocators.magnnet.ppo.PPOConfig` ``credit``).

    ``task_features=0`` is that model exactly (variant ``"paper"``). With
    ``task_features=K > 0`` (variant ``"paper_nb"``, **our addition**, not in the paper) the
    actor's input also holds, per task, the ``K`` features of :func:`neighbour_task_features`
    that agent ``i`` computes from the cost vectors its one-hop neighbours broadcast (the
    agent-agent messages carry per-task information): input ``M (1 + K) + 7``. Both are
    decentralized in the same way (only one- and two-hop information reaches ``z_i``).
    """

    def __init__(self, n_agents: int, n_tasks: int, hidden: int = 6, mlp: int = 128,
                 task_features: int = 0, agent_values: bool = False) -> None:
        super().__init__()
        self.n_agents, self.n_tasks, self.hidden, self.mlp = n_agents, n_tasks, hidden, mlp
        self.task_features = task_features
        self.agent_values = agent_values
        self.gnn = nn.ModuleList([
            HeteroGraphConv(AGENT_F + n_tasks, TASK_F, 2, hidden),
            HeteroGraphConv(hidden, hidden, 2, hidden),
        ])
        self.actor = nn.Sequential(
            nn.Linear(n_tasks * (1 + task_features) + 1 + hidden, mlp), nn.ReLU(),
            nn.Linear(mlp, n_tasks + 1))
        self.critic = nn.Sequential(nn.Linear(n_agents * hidden + n_tasks * TASK_F, mlp),
                                    nn.ReLU(), nn.Linear(mlp, n_agents if agent_values else 1))

    @property
    def variant(self) -> str:
        return "paper_nb" if self.task_features else "paper"

    def config(self) -> dict:
        cfg = {"variant": "paper", "n_agents": self.n_agents, "n_tasks": self.n_tasks,
               "hidden": self.hidden, "mlp": self.mlp}
        if self.task_features:
            cfg["task_features"] = self.task_features
        if self.agent_values:
            cfg["agent_values"] = True
        return cfg

    def embed(self, obs):
        h = torch.cat([obs["agents"], obs["cost"]], -1)
        g, e, adj = obs["tasks"], _edges(obs), obs["adjacency"]
        for layer in self.gnn:
            h, g = layer(h, g, e, adj)
        return h, g

    def forward(self, obs):
        """Masked action logits ``(B, N, M + 1)`` and the embeddings ``(B, N, hidden)``."""
        z, _ = self.embed(obs)
        parts = [obs["agents"][..., :1], obs["cost"]]
        if self.task_features:
            f = neighbour_task_features(obs)[..., :self.task_features]
            parts.append(f.reshape(*f.shape[:2], -1))
        x = torch.cat(parts + [z], -1)
        out = self.actor(x)
        return _mask(out[..., 1:], out[..., :1], obs["available"]), z

    def value(self, obs, z):
        """The centralized critic: ``(B,)`` (the team's value), or ``(B, N)`` (each agent's
        value, from the same global input) when built with ``agent_values``."""
        b = z.shape[0]
        v = self.critic(torch.cat([z.reshape(b, -1), obs["tasks"].reshape(b, -1)], -1))
        return v if self.agent_values else v[:, 0]


#: Number of per-task features :func:`neighbour_task_features` returns.
NB_FEATURES = 6


def neighbour_task_features(obs) -> torch.Tensor:
    """Per agent ``i`` and task ``j`` (our addition to the paper's actor input), from ``i``'s
    own costs and the cost vectors its deciding one-hop neighbours ``k`` broadcast:

    0. ``c_ij - min_k c_kj`` (negative: ``i`` is the cheapest contender for ``j`` it can hear);
    1. ``min (c_kj - min_j' c_kj')`` over the neighbours ``k`` cheaper than ``i`` for ``j``
       (0: ``j`` is the best task of a cheaper neighbour; the cap when none is cheaper);
    2. how many deciding neighbours are cheaper than ``i`` for ``j``, divided by 10;
    3. ``second-smallest c_kj - c_ij`` over the neighbours (how deep the competition is);
    4. the regret of the cheapest neighbour ``k*`` for ``j``: ``c_k*j' - c_k*j`` with ``j'``
       the best other task of ``k*`` (what ``k*`` loses without ``j``);
    5. ``i``'s own regret for ``j``: ``c_ij - min_{j' != j} c_ij'`` (negative: ``j`` is its
       best task, by that much).

    Scaled cost units, clamped to ``[-cap, cap]``
    (:data:`~allocators.magnnet.rules.COST_CAP`); shape ``(B, N, M, NB_FEATURES)``.
    """
    cap = rules.COST_CAP
    cost, avail = obs["cost"], obs["available"].bool()
    adj = obs["adjacency"].bool()
    n, m = cost.shape[1], cost.shape[2]
    status = obs["agents"][..., 0] > 0.5
    eye = torch.eye(n, dtype=torch.bool)
    nb = adj & ~eye & status[:, None, :]
    c = torch.where(avail, cost, torch.full_like(cost, cap))
    rowmin = c.amin(-1, keepdim=True)
    # best other task of every agent, per task: min over j' != j
    if m > 1:
        two = torch.topk(c, 2, dim=-1, largest=False)
        best_other = torch.where(torch.arange(m) == two.indices[..., :1],
                                 two.values[..., 1:2], two.values[..., :1])
    else:
        best_other = torch.full_like(c, cap)
    regret = best_other - c  # (B, k, j): what k loses without j (>0: j is k's best)
    big = torch.full_like(c[:, None], 2 * cap)
    ck = torch.where(nb[..., None], c[:, None].expand(-1, n, -1, -1), big)  # (B, i, k, j)
    if n > 2:
        low = torch.topk(ck, 2, dim=2, largest=False)
        colmin, second = low.values[:, :, 0], low.values[:, :, 1]
        kstar = low.indices[:, :, 0]
    else:
        colmin = ck.amin(2)
        second = torch.full_like(colmin, 2 * cap)
        kstar = ck.argmin(2)
    has = nb.any(-1)[..., None]
    k_regret = torch.gather(regret, 1, kstar)  # regret[b, kstar[b, i, j], j]
    k_regret = torch.where(has, k_regret, torch.zeros_like(k_regret))
    cheaper = (ck < c[:, :, None]) & nb[..., None]
    slack = (c - rowmin)[:, None]
    slack_cheaper = torch.where(cheaper, slack.expand_as(ck), torch.full_like(ck, cap)).amin(2)
    f = torch.stack([c - colmin, slack_cheaper, cheaper.sum(2).float() / 10.0, second - c,
                     k_regret, c - best_other], -1)
    return f.clamp(-cap, cap)


def build(config: dict) -> nn.Module:
    """A model from its :meth:`config` (what a checkpoint stores beside the weights)."""
    cfg = dict(config)
    variant = cfg.pop("variant")
    if variant == "paper":
        return MagnnetPolicy(**cfg)
    if variant == "match":
        from allocators.magnnet.match import MatchPolicy

        return MatchPolicy(**cfg)
    if variant == "view":
        from allocators.magnnet.views import ViewPolicy

        return ViewPolicy(**cfg)
    if variant == "ppo":
        from allocators.magnnet.attention import AttentionPolicy

        return AttentionPolicy(**cfg)
    raise ValueError(f"unknown MAGNNET variant {variant!r}")
