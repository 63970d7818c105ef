"""Padded batches of labelled views: the view model's imitation loss in one forward pass.

DAgger (:func:`allocators.magnnet.views.train_views`) fits the view model on views of every
size (2 to 50 agents, 1 to 50 tasks). One forward and backward pass per view costs a few
milliseconds of Python and dispatch overhead whatever its size, so a gradient step of 16 views
took 16 of them. Here a batch is one padded tensor instead, and the loss is the same number:

* the input features of a view depend on its shape (ranks over its rows and columns, its
  second-best costs), so they are computed per view, unpadded, exactly as
  :meth:`~allocators.magnnet.views.ViewPolicy.forward` computes them (they hold no weight:
  computed once per view, when it is collected);
* a padded edge is an unavailable edge: the network masks those out of every aggregate, so the
  real edges' scores and null logits do not see the padding; padded columns score ``-1e4``
  (they add ``exp(-1e4) = 0`` to a softmax) and padded rows and columns are left out of the
  cross-entropies.

:func:`batch_loss` equals the mean of :func:`~allocators.magnnet.views.view_loss` over the
batch up to the order of float sums (``tests/magnnet/test_views.py`` checks it).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from allocators.magnnet.match import aggregates, edge_features, scaled


@torch.no_grad()
def prepare(sample) -> tuple:
    """A labelled view ``(cost, flies, hop, active, row_target, col_target)`` as the batch
    needs it: ``(features (n, m, F), mask (n, m), row_target, col_target)`` tensors."""
    cost, flies, hop, active, rt, ct = sample
    c, mask = scaled(cost)
    _, n, m = c.shape
    act = torch.from_numpy(np.asarray(active, bool))[None].float()
    frac = act.sum(1) / mask.any(1).sum(1).clamp(min=1)
    extra = torch.stack([(torch.from_numpy(np.asarray(hop)).float()[None] / 2)[:, :, None]
                         .expand(-1, -1, m),
                         act[:, :, None].expand(-1, -1, m),
                         frac[:, None, None].expand(-1, n, m)], -1)
    f = torch.cat([edge_features(c, mask, torch.from_numpy(np.asarray(flies, bool))[None]),
                   extra], -1)
    f = torch.where(mask[..., None], f, torch.zeros_like(f))
    return f[0], mask[0], torch.from_numpy(np.asarray(rt, np.int64)), \
        torch.from_numpy(np.asarray(ct, np.int64))


def _layer(layer, h: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """One :class:`~allocators.magnnet.match.EdgeLayer`, computed with its first linear map
    split by input block: the row and column aggregates go through their blocks of the weight
    once per row and per column, not once per edge (the same sum in another order; a third of
    the multiply-adds)."""
    row_mean, row_max, col_mean, col_max = aggregates(h, mask, keepdim=True)
    first, second = layer.mlp[0], layer.mlp[2]
    w = first.weight.split(h.shape[-1], dim=1)  # blocks of [h, row mean, row max, col ...]
    row = torch.cat([row_mean, row_max], -1) @ torch.cat(w[1:3], 1).T
    col = torch.cat([col_mean, col_max], -1) @ torch.cat(w[3:5], 1).T
    x = torch.relu(h @ w[0].T + row + col + first.bias)
    return layer.norm(h + second(x))


def forward_features(model, f: torch.Tensor, mask: torch.Tensor):
    """The view model's ``(scores, row_null, col_null)`` from input features ``f (B, n, m,
    F)`` (zero on masked edges) and ``mask (B, n, m)``: the part of
    :meth:`~allocators.magnnet.views.ViewPolicy.forward` after its features."""
    h = model.inp(f)
    for layer in model.gnn:
        h = _layer(layer, h, mask)
    return model.heads(h, mask)


def _chunks(prepared: list, waste: float) -> list[list]:
    """The views grouped by size (largest first) so that padding each group to its largest
    view adds at most ``waste`` times its real edges (a 50 x 50 view padded with fifteen
    5 x 5 ones would cost as much as sixteen 50 x 50 ones)."""
    order = sorted(prepared, key=lambda p: p[1].shape[0] * p[1].shape[1], reverse=True)
    groups, cur, real = [], [], 0
    for p in order:
        n, m = p[1].shape
        if cur:
            big_n, big_m = cur[0][1].shape[0], max(q[1].shape[1] for q in cur + [p])
            big_n = max(big_n, n)
            if (len(cur) + 1) * big_n * big_m > waste * (real + n * m):
                groups.append(cur)
                cur, real = [], 0
        cur.append(p)
        real += n * m
    return groups + [cur]


def _group_loss(model, prepared: list) -> torch.Tensor:
    """Sum over ``prepared`` views of the per-view loss, in one padded pass."""
    b = len(prepared)
    big_n = max(p[1].shape[0] for p in prepared)
    big_m = max(p[1].shape[1] for p in prepared)
    feat = prepared[0][0].shape[-1]
    f = torch.zeros(b, big_n, big_m, feat)
    mask = torch.zeros(b, big_n, big_m, dtype=torch.bool)
    rt = torch.full((b, big_n), -100, dtype=torch.int64)  # -100: cross_entropy's ignore
    ct = torch.full((b, big_m), -100, dtype=torch.int64)
    rows = torch.empty(b)
    cols = torch.empty(b)
    for k, (fk, mk, rk, ck) in enumerate(prepared):
        n, m = mk.shape
        f[k, :n, :m], mask[k, :n, :m] = fk, mk
        rt[k, :n] = torch.where(rk == m, big_m, rk)  # the null head sits after the padding
        ct[k, :m] = torch.where(ck == n, big_n, ck)
        rows[k], cols[k] = n, m
    s, rn, cn = forward_features(model, f, mask)
    ce = nn.functional.cross_entropy
    row = ce(torch.cat([s, rn[..., None]], 2).transpose(1, 2), rt, reduction="none")
    col = ce(torch.cat([s.transpose(1, 2), cn[..., None]], 2).transpose(1, 2), ct,
             reduction="none")
    return (row.sum(1) / rows).sum() + (col.sum(1) / cols).sum()


def batch_loss(model, prepared: list, waste: float = 1.5) -> torch.Tensor:
    """Mean over ``prepared`` views (from :func:`prepare`) of the per-view imitation loss
    (row cross-entropy plus column cross-entropy, null heads included), in a few padded
    passes (views of similar size together, see :func:`_chunks`)."""
    return sum(_group_loss(model, g) for g in _chunks(prepared, waste)) / len(prepared)
