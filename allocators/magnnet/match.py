"""MAGNNET-match: a size-agnostic agent-task graph network that learns the optimal assignment.

The paper's policy reads a cost vector of length ``M`` and is trained with PPO; on our instances
it stays far from the optimum (see ``benchmarks/paper_tables.py``). This variant keeps the idea
(a graph neural network over agents and tasks, executed per agent from what its communication
neighbourhood gives it) and changes two things, both measured:

* **The graph.** Every agent-task pair is an edge of the bipartite graph, with a hidden state.
  Each layer updates an edge from itself and four aggregates: mean and max over the edges of its
  agent (the agent's alternatives) and over the edges of its task (the competition for it), a
  residual MLP and layer normalization. The input features of edge ``(i, j)`` are the agent's
  cost and how it compares with the row and the column (:func:`edge_features`). Nothing depends
  on ``N`` or ``M``: one checkpoint serves every size.
* **The training signal.** Imitation of the optimal (Hungarian) assignment: a cross-entropy per
  agent over its tasks and per task over its agents, on random sub-problems (any ``n x m``, from
  2 up to 20) of the cached N = 20 training instances; evaluated up to N = 100. No reward shaping, no hand-written solver in the
  input; it trains in minutes on two CPU cores.

Execution (:func:`mutual_best`): in each decision round an agent scores the edges of its view
(the deciding agents within two communication hops, all open tasks), takes its best task, and
requests it only when no agent of its view scores that task higher and the model is confident
of the pair (row and column softmax both at least ``confidence``; if no pair of the view is
that sure, mutual best is enough); otherwise it waits a round, and the pairs settled meanwhile
make its choice clearer. On a complete graph every view is the same, so no two agents ever
request one task: the result is conflict-free by construction, and each round assigns at least
the best-scored pair. With limited range the views differ, conflicts can happen and the shared
conflict rule settles them; an agent that does not hear the whole fleet skips the confidence
test (waiting only delays it while others go ahead) and requests its best task regardless from
round ``patience`` on, so deciding never stalls.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from allocators.magnnet import rules

log = logging.getLogger(__name__)

#: Number of input features per edge (see :func:`edge_features`).
EDGE_FEATURES = 8
#: Cost of an infeasible or unavailable edge inside the feature computation (scaled units).
_FAR = 10.0


def edge_features(cost: torch.Tensor, mask: torch.Tensor, flies: torch.Tensor) -> torch.Tensor:
    """Input features of every edge, ``(B, n, m, EDGE_FEATURES)``; zeros on masked edges.

    ``cost (B, n, m)`` in scaled units (seconds / :data:`~allocators.magnnet.rules.COST_SCALE`),
    ``mask (B, n, m)`` the available edges, ``flies (B, n)``. Per edge ``(i, j)``:

    0. ``c_ij`` (capped at :data:`~allocators.magnnet.rules.COST_CAP`);
    1. ``c_ij - min_j' c_ij'`` (how much worse than the agent's best task);
    2. ``c_ij - min_k c_kj`` (how much dearer than the task's cheapest agent);
    3. ``c_ij - min_{j' != j} c_ij'`` (the agent's regret: negative when ``j`` is its best);
    4. ``c_ij - min_{k != i} c_kj`` (negative when ``i`` is the task's cheapest agent);
    5. rank of ``c_ij`` in the agent's row, over ``m - 1``;
    6. rank of ``c_ij`` in the task's column, over ``n - 1``;
    7. whether agent ``i`` flies.
    """
    _, n, m = cost.shape
    cap = rules.COST_CAP
    far = torch.full_like(cost, _FAR)
    c = torch.where(mask, cost, far)
    rowmin = c.amin(2, keepdim=True)
    colmin = c.amin(1, keepdim=True)
    if m > 1:
        two = torch.topk(c, 2, dim=2, largest=False)
        row_other = torch.where(torch.arange(m, device=c.device) == two.indices[..., :1], two.values[..., 1:2],
                                two.values[..., :1])
    else:
        row_other = far
    if n > 1:
        two = torch.topk(c, 2, dim=1, largest=False)
        col_other = torch.where(torch.arange(n, device=c.device)[None, :, None] == two.indices[:, :1],
                                two.values[:, 1:2], two.values[:, :1])
    else:
        col_other = far
    row_rank = c.argsort(2).argsort(2).float() / max(m - 1, 1)
    col_rank = c.argsort(1).argsort(1).float() / max(n - 1, 1)
    f = torch.stack([c.clamp(max=cap), (c - rowmin).clamp(max=cap), (c - colmin).clamp(max=cap),
                     (c - row_other).clamp(-cap, cap), (c - col_other).clamp(-cap, cap),
                     row_rank, col_rank, flies[:, :, None].float().expand(-1, -1, m)], -1)
    return torch.where(mask[..., None], f, torch.zeros_like(f))


def aggregates(h: torch.Tensor, mask: torch.Tensor, keepdim: bool):
    """The masked mean and max of the edge states ``h (B, n, m, H)`` over each agent's row and
    each task's column: ``(row_mean, row_max, col_mean, col_max)``; an agent (task) without
    any available edge aggregates to 0, not to the fill value."""
    mf = mask[..., None].to(h.dtype)
    hm = h * mf
    low = torch.where(mask[..., None], h, torch.full_like(h, -1e4))

    def along(dim: int):
        count = mf.sum(dim, keepdim=keepdim)
        return (hm.sum(dim, keepdim=keepdim) / count.clamp(min=1),
                low.amax(dim, keepdim=keepdim).clamp(min=-1e3) * (count > 0))

    return (*along(2), *along(1))


class EdgeLayer(nn.Module):
    """One round of message passing on the complete bipartite agent-task graph."""

    def __init__(self, hidden: int) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(5 * hidden, 2 * hidden), nn.ReLU(),
                                 nn.Linear(2 * hidden, hidden))
        self.norm = nn.LayerNorm(hidden)

    def forward(self, h: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        row_mean, row_max, col_mean, col_max = aggregates(h, mask, keepdim=True)
        x = torch.cat([h, row_mean.expand_as(h), row_max.expand_as(h),
                       col_mean.expand_as(h), col_max.expand_as(h)], -1)
        return self.norm(h + self.mlp(x))


class MatchPolicy(nn.Module):
    """Edge scores ``(B, n, m)`` (``-1e4`` on unavailable edges) for any ``n`` and ``m``."""

    variant = "match"

    def __init__(self, hidden: int = 32, layers: int = 5) -> None:
        super().__init__()
        self.hidden, self.layers = hidden, layers
        self.inp = nn.Sequential(nn.Linear(EDGE_FEATURES, hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden))
        self.gnn = nn.ModuleList([EdgeLayer(hidden) for _ in range(layers)])
        self.out = nn.Sequential(nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1))

    def config(self) -> dict:
        return {"variant": "match", "hidden": self.hidden, "layers": self.layers}

    def forward(self, cost: torch.Tensor, mask: torch.Tensor,
                flies: torch.Tensor) -> torch.Tensor:
        h = self.inp(edge_features(cost, mask, flies))
        for layer in self.gnn:
            h = layer(h, mask)
        s = self.out(h)[..., 0]
        return torch.where(mask, s, torch.full_like(s, -1e4))


def _scale(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cost / COST_SCALE as float32, finite mask)``, any shape; infeasible entries read 0."""
    mask = np.isfinite(cost)
    return np.where(mask, cost / rules.COST_SCALE, 0.0).astype(np.float32), mask


def scaled(cost: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """``(cost / COST_SCALE, finite mask)`` as a batch of one; infeasible entries read 0."""
    c, mask = _scale(cost)
    return torch.from_numpy(c)[None], torch.from_numpy(mask)[None]


@torch.no_grad()
def scores_of(model: MatchPolicy, cost: np.ndarray, flies: np.ndarray) -> np.ndarray:
    """The model's edge scores of one ``(n, m)`` problem (``-inf`` where infeasible)."""
    if cost.size == 0:
        return np.full(cost.shape, -np.inf)
    if cost.size >= SPARSE_MIN_PAIRS and np.isfinite(cost).mean() <= SPARSE_DENSITY:
        return sparse_scores(model, cost, flies)
    c, mask = scaled(cost)
    s = model(c, mask, torch.from_numpy(np.asarray(flies, bool))[None])[0].numpy()
    return np.where(mask[0].numpy(), s.astype(np.float64), -np.inf)


#: Default of :func:`mutual_best`'s ``confidence``: the best of 0, 0.5, ..., 0.9 on the 100
#: held-out training instances (mean gap over N = 4, 8, 12, 20: 0.96 % at 0, 0.17 % at 0.8).
CONFIDENCE = 0.8


def _softmax(s: np.ndarray, axis: int) -> np.ndarray:
    finite = np.isfinite(s)
    top = np.max(np.where(finite, s, -np.inf), axis=axis, keepdims=True)
    e = np.where(finite, np.exp(s - np.where(np.isfinite(top), top, 0.0)), 0.0)
    return e / np.maximum(e.sum(axis=axis, keepdims=True), 1e-300)


def mutual_best(scores: np.ndarray, rows: np.ndarray, force: bool = False,
                confidence: float = CONFIDENCE) -> np.ndarray:
    """Requests of the agents at ``rows`` of a view's ``scores (n, m)`` (``-1``: wait).

    A pair ``(i, j)`` is *mutual best* when ``j`` is ``i``'s best task and no agent of the view
    scores ``j`` higher (ties to the lower row). It is *confident* when, in addition, the
    softmax of ``i``'s row gives ``j`` at least ``confidence`` and the softmax of ``j``'s
    column gives ``i`` at least ``confidence`` (the model was trained with exactly these two
    cross-entropies, so they read as the chance that the pair is optimal). Agents of confident
    pairs request; if the view has no confident pair, agents of mutual-best pairs request
    (there always is one: the best finite score), so every round makes progress. Every agent
    of a view computes the same answer for the whole view. With ``force`` every agent
    requests its best task. ``-1`` where an agent has no feasible task.
    """
    out = np.full(len(rows), -1, np.int64)
    if scores.size == 0:
        return out
    n = scores.shape[0]
    best = scores.argmax(1)
    ok = np.isfinite(scores[np.arange(n), best])
    mutual = ok & (scores.argmax(0)[best] == np.arange(n))
    sure = (mutual & (_softmax(scores, 1)[np.arange(n), best] >= confidence)
            & (_softmax(scores, 0)[np.arange(n), best] >= confidence))
    go = ok if force else (sure if sure.any() else mutual)
    out[go[rows]] = best[rows][go[rows]]
    return out


# --------------------------------------------------------------------------- training


@dataclass(frozen=True)
class MatchConfig:
    """Imitation training (defaults: the shipped ``match.pt``, which was trained with
    ``seed=2``: the best of seeds 0-2 on the held-out training instances)."""

    updates: int = 6000
    batch: int = 32
    lr: float = 2e-3
    hidden: int = 32
    layers: int = 5
    max_size: int = 20
    square_share: float = 0.7
    val_every: int = 250
    seed: int = 0


def sample_batch(pools, rng: np.random.Generator, batch: int, max_size: int,
                 square_share: float):
    """Random sub-problems of one size from the cached pools, with their optimal assignment.

    Returns ``cost (B, n, m)`` scaled, ``mask``, ``flies (B, n)``, ``row_target (B, n)`` (the
    optimal task of each agent, ``-1`` if unassigned) and ``col_target (B, m)``.
    """
    from allocators.hungarian import optimal_pairs

    pools = [p for p in pools if min(p.cost.shape[1:]) >= 2]
    pool = pools[rng.integers(len(pools))]
    big_n, big_m = pool.cost.shape[1:]
    n = int(rng.integers(2, min(big_n, max_size) + 1))
    m = n if (rng.random() < square_share and n <= big_m) else \
        int(rng.integers(2, min(big_m, max_size) + 1))
    cost = np.empty((batch, n, m))
    flies = np.empty((batch, n), bool)
    rt = np.full((batch, n), -1, np.int64)
    ct = np.full((batch, m), -1, np.int64)
    for b in range(batch):
        k = rng.integers(len(pool))
        ai = rng.choice(big_n, n, replace=False)
        ti = rng.choice(big_m, m, replace=False)
        cost[b] = pool.cost[k][np.ix_(ai, ti)]
        flies[b] = pool.flies[k][ai]
        for i, j in optimal_pairs(cost[b]):
            rt[b, i], ct[b, j] = j, i
    c, mask = _scale(cost)
    return (torch.from_numpy(c), torch.from_numpy(mask), torch.from_numpy(flies),
            torch.from_numpy(rt), torch.from_numpy(ct))


def imitation_loss(scores: torch.Tensor, row_target: torch.Tensor,
                   col_target: torch.Tensor) -> torch.Tensor:
    """Mean cross-entropy of each assigned agent over its tasks plus each assigned task over
    its agents (entries with target ``-1`` do not count)."""
    f = nn.functional.cross_entropy
    lr = f(scores.transpose(1, 2), row_target.clamp(min=0), reduction="none")
    lc = f(scores, col_target.clamp(min=0), reduction="none")
    rw, cw = (row_target >= 0).float(), (col_target >= 0).float()
    return (lr * rw).sum() / rw.sum().clamp(min=1) + (lc * cw).sum() / cw.sum().clamp(min=1)


def plan(model: MatchPolicy, cost: np.ndarray, flies: np.ndarray,
         confidence: float = CONFIDENCE) -> np.ndarray:
    """The task of each agent (``-1``: none) when the decision rounds are played on a
    complete graph (see :func:`play`): what every agent that knows the whole ``cost``
    computes alike."""
    n, m = cost.shape
    out = np.full(n, -1, np.int64)
    free_a, free_t = np.ones(n, bool), np.ones(m, bool)
    while True:
        a_idx, t_idx = np.flatnonzero(free_a), np.flatnonzero(free_t)
        sub = cost[np.ix_(a_idx, t_idx)]
        if not np.isfinite(sub).any():
            return out
        req = mutual_best(scores_of(model, sub, flies[a_idx]), np.arange(len(a_idx)),
                          confidence=confidence)
        for r, j in enumerate(req):
            if j >= 0:
                out[a_idx[r]] = t_idx[j]
                free_a[a_idx[r]], free_t[t_idx[j]] = False, False


def play(model: MatchPolicy, cost: np.ndarray, flies: np.ndarray,
         confidence: float = CONFIDENCE) -> tuple[float, int, int]:
    """Decision rounds on a complete graph, as the plugin plays them: ``(total cost, agents
    assigned, rounds)``. Conflict-free by construction (every agent shares the one view)."""
    n, m = cost.shape
    free_a, free_t = np.ones(n, bool), np.ones(m, bool)
    total, assigned, rounds = 0.0, 0, 0
    while True:
        a_idx, t_idx = np.flatnonzero(free_a), np.flatnonzero(free_t)
        sub = cost[np.ix_(a_idx, t_idx)]
        if not np.isfinite(sub).any():
            return total, assigned, rounds
        req = mutual_best(scores_of(model, sub, flies[a_idx]), np.arange(len(a_idx)),
                          confidence=confidence)
        rounds += 1
        for r, j in enumerate(req):
            if j >= 0:
                i, t = a_idx[r], t_idx[j]
                total += cost[i, t]
                assigned += 1
                free_a[i], free_t[t] = False, False


def evaluate(model: MatchPolicy, pool) -> dict[str, float]:
    """Mean gap to the optimal total and share of instances fully assigned, on a complete
    graph (see :func:`play`)."""
    gaps, complete = [], []
    for k in range(len(pool)):
        cost = pool.cost[k]
        count, best = rules.optimal(cost)
        total, assigned, _ = play(model, cost, pool.flies[k])
        complete.append(assigned >= count)
        gaps.append((total - best) / best if best > 0 else 0.0)
    return {"val/gap": float(np.mean(gaps)), "val/complete": float(np.mean(complete))}


def train(model: MatchPolicy, pools, cfg: MatchConfig, on_update=None, val_pool=None):
    """Fit ``model`` by imitation; returns one log row per update (and per validation).

    With ``val_pool`` the model is validated every ``cfg.val_every`` updates and the weights
    with the smallest validation gap (among fully assigning ones) are kept at the end.
    """
    rng = np.random.default_rng(cfg.seed)  # the only randomness of training: the batches
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=cfg.updates)
    rows, best, best_state = [], None, None
    started = time.perf_counter()
    for u in range(cfg.updates):
        cost, mask, flies, rt, ct = sample_batch(pools, rng, cfg.batch, cfg.max_size,
                                                 cfg.square_share)
        model.train()
        loss = imitation_loss(model(cost, mask, flies), rt, ct)
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
        row = {"phase": "imitation", "update": u, "losses/imitation": loss.item(),
               "size_n": cost.shape[1], "size_m": cost.shape[2],
               "wall_s": time.perf_counter() - started}
        rows.append(row)
        if on_update:
            on_update(row)
        last = u == cfg.updates - 1
        if val_pool is not None and ((u + 1) % cfg.val_every == 0 or last):
            model.eval()
            res = evaluate(model, val_pool)
            vrow = {"phase": "val", "update": u, **res, "wall_s": time.perf_counter() - started}
            rows.append(vrow)
            if on_update:
                on_update(vrow)
            key = (-res["val/complete"], res["val/gap"])
            if best is None or key < best:
                best = key
                best_state = {k: v.clone() for k, v in model.state_dict().items()}
    if best_state is not None:
        model.load_state_dict(best_state)
    model.eval()
    return rows


def config_dict(cfg: MatchConfig) -> dict:
    return asdict(cfg)


# --------------------------------------------------------------------------- sparse evaluation
#: :func:`scores_of` evaluates the model edge by edge (:func:`sparse_scores`) when at most this
#: share of a problem's pairs is feasible and it has at least :data:`SPARSE_MIN_PAIRS` pairs
#: (a city's taxis: a request reaches a few percent of the idle fleet within its wait).
SPARSE_DENSITY = 0.25
SPARSE_MIN_PAIRS = 2048


def _segment_mean_max(h: torch.Tensor, seg: torch.Tensor, size: int):
    idx = seg[:, None].expand_as(h)
    count = torch.bincount(seg, minlength=size).clamp(min=1).to(h.dtype)[:, None]
    mean = torch.zeros(size, h.shape[1], dtype=h.dtype).index_add_(0, seg, h) / count
    top = torch.full((size, h.shape[1]), -1e4, dtype=h.dtype).scatter_reduce(0, idx, h, "amax")
    return mean, top.clamp(min=-1e3)


@torch.no_grad()
def sparse_scores(model: MatchPolicy, cost: np.ndarray, flies: np.ndarray) -> np.ndarray:
    """:func:`scores_of` computed on the feasible edges only (what the dense network computes
    for them, up to the order of float sums; its masked edges never reach a feasible one)."""
    n, m = cost.shape
    c, mask = scaled(cost)
    # the input features as the dense network computes them (cheap: n x m x 8 numbers; the
    # ranks keep torch's order of ties), then the layers on the feasible edges only
    feats = edge_features(c, mask, torch.from_numpy(np.asarray(flies, bool))[None])[0]
    rows_np, cols_np = np.nonzero(mask[0].numpy())
    rows, cols = torch.from_numpy(rows_np), torch.from_numpy(cols_np)
    h = model.inp(feats[rows, cols])
    for layer in model.gnn:
        rm, rx = _segment_mean_max(h, rows, n)
        cm, cx = _segment_mean_max(h, cols, m)
        x = torch.cat([h, rm[rows], rx[rows], cm[cols], cx[cols]], -1)
        h = layer.norm(h + layer.mlp(x))
    out = np.full((n, m), -np.inf)
    out[rows_np, cols_np] = model.out(h)[:, 0].numpy().astype(np.float64)
    return out
