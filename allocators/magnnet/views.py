"""MAGNNET under limited communication: a policy for partial views, trained CTDE-style.

With a communication range an agent knows only its *view*: the deciding agents within two hops
(their cost vectors come over the links) and the tasks it believes open. The match model of
:mod:`allocators.magnnet.match` was trained on whole problems; on a view it takes the view for
the world, so two agents of different views often both see themselves as the best agent for one
task (conflicts), and an agent takes a task that an agent it cannot hear should have had (gap).

The view model (:class:`ViewPolicy`) is the match network with what a view needs:

* two more edge features: the agent's hop distance from the deciding agent (0, 1, 2, over 2),
  and the size of the view against the open tasks (``n_view / m_open``: small views know they
  see a small part of the fleet);
* two *null* heads: per agent, "my task in the optimal assignment is none of these" and per
  task, "its agent in the optimal assignment is outside this view" (or it is already taken).

Training (:func:`train_views`) is centralized, execution decentralized (CTDE): the teacher sees
the whole remaining problem and solves it (Hungarian on the unassigned agents and the tasks not
yet taken); the student sees one agent's view and learns, per agent of the view, its task in
the teacher's answer (or null), and per task, its agent (or outside). The views come from the
states the student itself visits (DAgger): every iteration plays the decision rounds of the
plugin, with the shared conflict rule and message model, on training instances with random
ranges and loss, records every deciding agent's view, labels it with the teacher's answer for
that round and retrains on everything collected so far.

Execution (:func:`view_request`): the deciding agent requests its best task when the pair is
mutual best in its view (the task's best agent, the outside head included, is itself) and both
softmaxes (row and column, null heads included) give it at least ``confidence``; otherwise it
waits (:data:`dispatch.api.decentralized.WAIT`). From round ``patience`` on it must request: its
part of the view's best-score assignment (every agent of a view computes the same one), and
from twice that round its best task regardless, so a decision never stalls.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from allocators.magnnet.match import (EDGE_FEATURES, EdgeLayer, MatchPolicy, aggregates,
                                      edge_features, scaled)

log = logging.getLogger(__name__)

#: Extra input features per edge of the view model: hop of the agent / 2, whether the agent is
#: still deciding, deciding agents of the view / open tasks.
VIEW_FEATURES = 3


class ViewPolicy(nn.Module):
    """Edge scores ``(B, n, m)`` of one view, plus row-null ``(B, n)`` and column-null
    ``(B, m)`` logits; any ``n`` and ``m``."""

    variant = "view"

    def __init__(self, hidden: int = 32, layers: int = 5) -> None:
        super().__init__()
        self.hidden, self.layers = hidden, layers
        self.inp = nn.Sequential(nn.Linear(EDGE_FEATURES + VIEW_FEATURES, hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden))
        self.gnn = nn.ModuleList([EdgeLayer(hidden) for _ in range(layers)])
        self.out = nn.Sequential(nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1))
        self.row_null = nn.Sequential(nn.Linear(2 * hidden, hidden), nn.ReLU(),
                                      nn.Linear(hidden, 1))
        self.col_null = nn.Sequential(nn.Linear(2 * hidden, hidden), nn.ReLU(),
                                      nn.Linear(hidden, 1))

    def config(self) -> dict:
        return {"variant": "view", "hidden": self.hidden, "layers": self.layers}

    @torch.no_grad()
    def init_from(self, match: MatchPolicy) -> ViewPolicy:
        """Start from a trained match model: same weights, the new inputs weighted 0."""
        self.inp[0].weight.zero_()
        self.inp[0].weight[:, :EDGE_FEATURES] = match.inp[0].weight
        self.inp[0].bias.copy_(match.inp[0].bias)
        self.inp[2].load_state_dict(match.inp[2].state_dict())
        self.gnn.load_state_dict(match.gnn.state_dict())
        self.out.load_state_dict(match.out.state_dict())
        return self

    def forward(self, cost, mask, flies, hop, active):
        """``cost, mask (B, n, m)``, ``flies (B, n)``, ``hop (B, n)`` (0, 1 or 2), ``active
        (B, n)`` (the agent is still deciding)."""
        _, n, m = cost.shape
        act = active.float()
        frac = act.sum(1) / mask.any(1).sum(1).clamp(min=1)
        extra = torch.stack([(hop.float() / 2)[:, :, None].expand(-1, -1, m),
                             act[:, :, None].expand(-1, -1, m),
                             frac[:, None, None].expand(-1, n, m)], -1)
        f = torch.cat([edge_features(cost, mask, flies), extra], -1)
        h = self.inp(torch.where(mask[..., None], f, torch.zeros_like(f)))
        for layer in self.gnn:
            h = layer(h, mask)
        return self.heads(h, mask)

    def heads(self, h: torch.Tensor, mask: torch.Tensor):
        """``(scores, row_null, col_null)`` from the last layer's edge states ``h``."""
        s = self.out(h)[..., 0]
        row_mean, row_max, col_mean, col_max = aggregates(h, mask, keepdim=False)
        row = torch.cat([row_mean, row_max], -1)
        col = torch.cat([col_mean, col_max], -1)
        return (torch.where(mask, s, torch.full_like(s, -1e4)), self.row_null(row)[..., 0],
                self.col_null(col)[..., 0])


def hops_from(comm: np.ndarray, i: int, members: np.ndarray) -> np.ndarray:
    """Hop distance (0, 1 or 2) from agent ``i`` of each of ``members`` (all within two)."""
    one = comm[i].astype(bool)
    return np.where(members == i, 0, np.where(one[members], 1, 2))


@torch.no_grad()
def view_scores(model: ViewPolicy, cost: np.ndarray, flies: np.ndarray, hop: np.ndarray,
                active: np.ndarray):
    """``(scores (n, m) with -inf where infeasible, row_null (n,), col_null (m,))`` of one
    view."""
    c, mask = scaled(cost)
    s, rn, cn = model(c, mask, torch.from_numpy(np.asarray(flies, bool))[None],
                      torch.from_numpy(np.asarray(hop))[None],
                      torch.from_numpy(np.asarray(active, bool))[None])
    s = np.where(mask[0].numpy(), s[0].numpy().astype(np.float64), -np.inf)
    return s, rn[0].numpy().astype(np.float64), cn[0].numpy().astype(np.float64)


@torch.no_grad()
def view_scores_many(model: ViewPolicy, views) -> list[tuple]:
    """:func:`view_scores` of many views in one pass: ``views`` is a sequence of ``(cost,
    flies, hop, active)``; returns one ``(scores, row_null, col_null)`` per view, what
    :func:`view_scores` returns for it up to the order of float sums.

    Why it equals the per-view network: each view's input features are computed on that view
    alone, exactly as the dense network computes them (ranks and the view-size feature depend
    on the view's shape); after that every layer updates an edge from aggregates over the
    *available* edges of its agent and its task only (masked means and maxima), so the layers
    can run on the available edges of all views at once, as one graph whose agents and tasks
    are numbered per view (:func:`allocators.magnnet.match.sparse_scores` does the same for
    one problem). Unavailable edges, whose states the dense network computes and never reads,
    are not computed. A decision round of a taxi fleet scores hundreds of views of hundreds of
    agents: one pass instead of one per view, on a third of the edges."""
    from allocators.magnnet.match import _segment_mean_max

    views = list(views)
    if not views:
        return []
    feats, rows, cols, shapes, row_off, col_off = [], [], [], [], [0], [0]
    for cost, flies, hop, active in views:
        c, mask = scaled(cost)
        _, n, m = c.shape
        act = torch.from_numpy(np.asarray(active, bool))[None].float()
        frac = act.sum(1) / mask.any(1).sum(1).clamp(min=1)
        hop_t = torch.from_numpy(np.asarray(hop))[None]
        extra = torch.stack([(hop_t.float() / 2)[:, :, None].expand(-1, -1, m),
                             act[:, :, None].expand(-1, -1, m),
                             frac[:, None, None].expand(-1, n, m)], -1)
        f = torch.cat([edge_features(c, mask, torch.from_numpy(np.asarray(flies, bool))[None]),
                       extra], -1)[0]
        r, k = np.nonzero(mask[0].numpy())
        feats.append(f[torch.from_numpy(r), torch.from_numpy(k)])
        rows.append(r + row_off[-1])
        cols.append(k + col_off[-1])
        shapes.append((n, m, r, k))
        row_off.append(row_off[-1] + n)
        col_off.append(col_off[-1] + m)
    n_all, m_all = row_off[-1], col_off[-1]
    rows_t = torch.from_numpy(np.concatenate(rows).astype(np.int64))
    cols_t = torch.from_numpy(np.concatenate(cols).astype(np.int64))
    h = model.inp(torch.cat(feats, 0))
    for layer in model.gnn:
        rm, rx = _segment_mean_max(h, rows_t, n_all)
        cm, cx = _segment_mean_max(h, cols_t, m_all)
        x = torch.cat([h, rm[rows_t], rx[rows_t], cm[cols_t], cx[cols_t]], -1)
        h = layer.norm(h + layer.mlp(x))
    s = model.out(h)[:, 0].numpy().astype(np.float64)
    # the null heads read each agent's (task's) mean and max over its available edges; one
    # without any reads zeros, as in the dense network
    rm, rx = _segment_mean_max(h, rows_t, n_all)
    cm, cx = _segment_mean_max(h, cols_t, m_all)
    r_any = (torch.bincount(rows_t, minlength=n_all) > 0)[:, None]
    c_any = (torch.bincount(cols_t, minlength=m_all) > 0)[:, None]
    rn = model.row_null(torch.cat([rm, rx * r_any], -1))[:, 0].numpy().astype(np.float64)
    cn = model.col_null(torch.cat([cm, cx * c_any], -1))[:, 0].numpy().astype(np.float64)
    out, e0 = [], 0
    for v, (n, m, r, k) in enumerate(shapes):
        sc = np.full((n, m), -np.inf)
        sc[r, k] = s[e0:e0 + len(r)]
        e0 += len(r)
        out.append((sc, rn[row_off[v]:row_off[v + 1]], cn[col_off[v]:col_off[v + 1]]))
    return out


def _forced(scores: np.ndarray, r: int, active: np.ndarray | None, last: bool) -> int:
    from scipy.optimize import linear_sum_assignment

    n, m = scores.shape
    act = np.ones(n, bool) if active is None else np.asarray(active, bool)
    free = np.isfinite(scores).any(0) & act[scores.argmax(0)]
    if not (free & np.isfinite(scores[r])).any():
        free = np.isfinite(scores[r])
    rows, cols = np.flatnonzero(act), np.flatnonzero(free)
    sub = scores[np.ix_(rows, cols)]
    ok = np.isfinite(sub)
    low = sub[ok].min() if ok.any() else 0.0
    a, t = linear_sum_assignment(np.where(ok, sub - low + 1.0, 0.0), maximize=True)
    for i, k in zip(rows[a], cols[t]):
        if i == r and np.isfinite(scores[r, k]):
            return int(k)
    return int(np.where(free, scores[r], -np.inf).argmax()) if last else -2


def _softmax(x: np.ndarray) -> np.ndarray:
    e = np.exp(x - x.max())
    return e / e.sum()


def view_request(scores: np.ndarray, row_null: np.ndarray, col_null: np.ndarray, r: int,
                 confidence: float, force: bool, active: np.ndarray | None = None,
                 last: bool = True) -> int:
    """The request of the view's agent ``r``: its best task, when the pair is mutual best
    (null heads included) and both softmaxes give it at least ``confidence``; else ``-2``
    (wait), or ``-1`` when it has no feasible task.

    With ``force`` the agent must request: it leaves out the tasks whose best-scoring agent
    stopped deciding (``active`` False: that agent has most likely taken it), solves the
    assignment of the view's deciding agents to the other tasks that maximizes the total score
    (every agent of a view computes the same one, so neighbours do not all rush to one task)
    and requests its part; left out of it, it waits (unless ``last``) or requests its best
    such task."""
    row = scores[r]
    if not np.isfinite(row).any():
        return -1
    j = int(row.argmax())
    if force:
        return _forced(scores, r, active, last)
    pr = _softmax(np.append(np.where(np.isfinite(row), row, -1e9), row_null[r]))
    col = scores[:, j]
    pc = _softmax(np.append(np.where(np.isfinite(col), col, -1e9), col_null[j]))
    if pr.argmax() == j and pc.argmax() == r and pr[j] >= confidence and pc[r] >= confidence:
        return j
    return -2


# --------------------------------------------------------------------------- training


@dataclass(frozen=True)
class ViewConfig:
    """DAgger training of the view model (defaults: the first stage of the shipped
    ``view.pt``; its second stage continues with ``iterations=3, patience=8, lr=5e-4``)."""

    iterations: int = 4
    episodes: int = 40          # played per iteration
    updates: int = 200          # gradient steps per iteration
    batch: int = 16             # views per gradient step
    lr: float = 1e-3
    sizes: tuple[int, ...] = (8, 12, 20, 30, 50)
    ranges: tuple[float, ...] = (10.0, 15.0, 20.0, 20.0, 25.0, 30.0)
    loss_share: float = 0.25    # episodes played with 30 % message loss
    confidence: float = 0.5
    patience: int = 5
    max_views: int = 60_000     # the dataset keeps the most recent views
    seed: int = 0


def play_problem(problem, policy):
    """Run the plugin's decision rounds on ``problem`` with ``policy`` (a
    :class:`~allocators.magnnet.allocator.MagnnetAllocator`) recording every view; returns
    ``(allocation, views)``."""
    views: list = []
    policy._record = views
    try:
        alloc = policy.allocate(problem)
    finally:
        policy._record = None
    return alloc, views


def label(problem, alloc, views, own_ties: bool = False) -> list[tuple]:
    """Teacher labels of recorded views: per view ``(cost, flies, hop, active, row_target,
    col_target)``, targets the optimal assignment of the whole remaining problem of that
    round (``m`` / ``n``: the null heads); ``cost`` is the view's cost as the model read it
    when the record holds it (a taxi-scale view is rescaled and cut), else the problem's.

    ``own_ties``: per view, when the view's own agent (hop 0) has no task in the optimal
    assignment but costs exactly what the agent given some task costs for it (taxis at one
    node), the swap (it takes that task, the other none: an optimum too), so that taxis at
    one node do not learn that each of them is half likely to be the one.

    A teacher pair whose edge the view's cost lacks (not finite: a taxi-scale view cut to each
    task's cheapest candidates) is no target: its row's target is the null head, its column's
    the "outside" head."""
    from allocators.hungarian import optimal_pairs

    n, m = problem.cost.shape
    ia = {int(v): k for k, v in enumerate(problem.agent_ids)}  # ids -> indices
    it = {int(v): k for k, v in enumerate(problem.task_ids)}
    won = [(q.round, ia[int(q.agent_id)], it[int(q.task_id)]) for q in alloc.requests if q.won]
    free: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    teacher: dict = {}
    flies = problem_flies(problem)
    out = []
    for rec in views:
        r, members, tasks, hop, active = rec[:5]
        if r not in free:
            free_a, free_t = np.ones(n, bool), np.ones(m, bool)
            for rr, a, t in won:
                if rr < r:
                    free_a[a], free_t[t] = False, False
            free[r] = (np.flatnonzero(free_a), np.flatnonzero(free_t))
        ai, ti = free[r]
        if r not in teacher:
            at, ta = np.full(n, -1), np.full(m, -1)
            for i, j in optimal_pairs(problem.cost[np.ix_(ai, ti)]):
                at[ai[i]], ta[ti[j]] = ti[j], ai[i]
            teacher[r] = (at, ta)
        at, ta = teacher[r]
        if own_ties:
            own = int(members[np.flatnonzero(np.asarray(hop) == 0)[0]])
            if at[own] < 0:
                taken = np.flatnonzero(ta >= 0)
                tie = taken[problem.cost[own, taken] == problem.cost[ta[taken], taken]]
                if tie.size:  # swap: an assignment of the same cost, the owner in it
                    t = int(tie[0])
                    at, ta = at.copy(), ta.copy()
                    at[ta[t]], at[own], ta[t] = -1, t, own
        pos_t = {int(t): k for k, t in enumerate(tasks)}
        pos_a = {int(a): k for k, a in enumerate(members)}
        rt = np.array([pos_t.get(int(at[a]), len(tasks)) if act else len(tasks)
                       for a, act in zip(members, active)])
        ct = np.array([pos_a.get(int(ta[t]), len(members)) for t in tasks])
        cost = rec[5] if len(rec) > 5 else problem.cost[np.ix_(members, tasks)]
        # a taxi-scale view keeps each task's cheapest candidates only: a teacher pair whose
        # edge the cut removed is one the model cannot score (the plugin never requests it),
        # so the row learns "none of mine" and the column "its agent is not in this view"
        ok = np.isfinite(np.asarray(cost, float))
        rows = np.flatnonzero(rt < len(tasks))
        rt[rows[~ok[rows, rt[rows]]]] = len(tasks)
        cols = np.flatnonzero(ct < len(members))
        ct[cols[~ok[ct[cols], cols]]] = len(members)
        out.append((cost, flies[members], hop, active, rt, ct))
    return out


def problem_flies(problem) -> np.ndarray:
    return np.array([a.flies for a in problem.agents], bool)


def view_loss(model: ViewPolicy, sample) -> torch.Tensor:
    cost, flies, hop, active, rt, ct = sample
    c, mask = scaled(cost)
    s, rn, cn = model(c, mask, torch.from_numpy(flies)[None], torch.from_numpy(hop)[None],
                      torch.from_numpy(active)[None])
    row = torch.cat([s[0], rn[0][:, None]], 1)
    col = torch.cat([s[0].T, cn[0][:, None]], 1)
    f = nn.functional.cross_entropy
    return f(row, torch.from_numpy(rt)) + f(col, torch.from_numpy(ct))


def sub_problem(pool, k: int, n: int, comm_range: float | None, loss: float,
                rng: np.random.Generator):
    """A random ``n x n`` sub-problem (agents and tasks drawn without replacement) of
    instance ``k`` of ``pool``, as an AllocationProblem whose ids are indices."""
    from dispatch.api.comms import comm_graph
    from dispatch.api.problem import AgentView, AllocationProblem, TaskView

    big_n, big_m = pool.cost.shape[1:]
    ai = np.sort(rng.choice(big_n, min(n, big_n), replace=False))
    ti = np.sort(rng.choice(big_m, min(n, big_m), replace=False))
    flies = pool.flies[k][ai]
    agents = tuple(AgentView(i, "uav" if f else "ugv",
                             tuple(int(v) for v in np.floor(pool.agent_pos[k, a])),
                             5.0 if f else 3.0) for i, (a, f) in enumerate(zip(ai, flies)))
    tasks = tuple(TaskView(j, "ground", tuple(int(v) for v in np.floor(pool.task_pos[k, t])),
                           0.0) for j, t in enumerate(ti))
    return AllocationProblem(0.0, agents, tasks, pool.cost[k][np.ix_(ai, ti)].copy(),
                             comm_graph(pool.agent_pos[k][ai], comm_range),
                             np.random.default_rng(int(rng.integers(2**31))), loss=loss)


def evaluate_views(alloc_factory, pool, comm_range, loss: float = 0.0, limit: int | None = None):
    """Mean gap to Hungarian, conflict-free share and share of instances fully assigned of
    an allocator on ``pool``'s whole instances at ``comm_range``."""
    from allocators.hungarian import optimal_pairs

    gaps, free, complete = [], [], []
    rng = np.random.default_rng(0)
    alloc = alloc_factory()
    for k in range(len(pool) if limit is None else min(limit, len(pool))):
        n = pool.cost.shape[1]
        p = sub_problem(pool, k, n, comm_range, loss, rng)
        a = alloc.allocate(p)
        total = float(sum(p.cost[i, j] for i, j in a.pairs))
        best = float(sum(p.cost[i, j] for i, j in optimal_pairs(p.cost)))
        gaps.append((total - best) / best)
        bad = a.conflicted_tasks()
        free.append(sum(1 for _, j in a.pairs if j not in bad) / p.n_tasks)
        complete.append(len(a.pairs) == min(p.cost.shape))
    return {"gap": float(np.mean(gaps)), "conflict_free": float(np.mean(free)),
            "complete": float(np.mean(complete))}


class DaggerLog:
    """The log rows, the update count and the kept weights of one DAgger run of ``model``
    (what :func:`train_views` and :func:`allocators.magnnet.view_taxi.train_taxi` share): each
    row goes to :attr:`rows` and to ``on_row``; ``wall_s`` counts from the log's creation."""

    def __init__(self, model: ViewPolicy, on_row=None):
        self.model, self.on_row = model, on_row
        self.rows: list = []
        self.step = 0
        self.best, self.best_state = None, None
        self.started = time.perf_counter()

    def _add(self, row: dict) -> None:
        self.rows.append(row)
        if self.on_row:
            self.on_row(row)

    def fit(self, opt, data: list, rng: np.random.Generator, updates: int, batch: int,
            it: int, prep=None) -> list[float]:
        """``updates`` steps of ``opt`` on batches of ``batch`` views drawn from ``data`` with
        ``rng`` (each through ``prep`` first when given), gradients clipped to norm 1, one
        ``dagger`` row each (iteration ``it``); the model is left in eval mode. Returns the
        losses."""
        from allocators.magnnet.view_batch import batch_loss

        model = self.model
        model.train()
        losses = []
        for _ in range(updates):
            idx = rng.integers(len(data), size=batch)
            samples = [data[i] for i in idx] if prep is None else [prep(data[i]) for i in idx]
            loss = batch_loss(model, samples)  # = mean of view_loss
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            losses.append(loss.item())
            row = {"phase": "dagger", "iteration": it, "update": self.step,
                   "losses/imitation": losses[-1], "views": len(data),
                   "wall_s": time.perf_counter() - self.started}
            self.step += 1
            self._add(row)
        model.eval()
        return losses

    def validate(self, validate, it: int) -> None:
        """A ``val`` row of ``validate(model)`` (its keys as ``val/...``) for iteration ``it``;
        the weights are kept when its ``score`` is the lowest so far."""
        res = validate(self.model)
        self._add({"phase": "val", "iteration": it, "update": self.step - 1,
                   "wall_s": time.perf_counter() - self.started,
                   **{f"val/{k}": v for k, v in res.items()}})
        if self.best is None or res["score"] < self.best:
            self.best = res["score"]
            self.best_state = {k: v.clone() for k, v in self.model.state_dict().items()}

    def finish(self) -> list:
        """The kept weights back in the model (when any were kept), eval mode; the rows."""
        if self.best_state is not None:
            self.model.load_state_dict(self.best_state)
        self.model.eval()
        return self.rows


def train_views(model: ViewPolicy, pools, cfg: ViewConfig, make_allocator, on_row=None,
                validate=None):
    """DAgger: ``cfg.iterations`` times, play ``cfg.episodes`` training problems with the
    current model (``make_allocator(model)`` gives the plugin that plays them), label every
    view with the teacher, and fit the model on the views collected so far. Returns the log
    rows; with ``validate(model) -> dict`` the weights with the best ``score`` are kept."""
    from allocators.magnnet.view_batch import prepare

    rng = np.random.default_rng(cfg.seed)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    data: list = []
    dagger = DaggerLog(model, on_row)
    for it in range(cfg.iterations):
        model.eval()
        t0 = time.perf_counter()
        policy = make_allocator(model)
        for _ in range(cfg.episodes):
            pool = pools[rng.integers(len(pools))]
            n = int(rng.choice([s for s in cfg.sizes if s <= pool.cost.shape[1]]))
            rr = float(rng.choice(cfg.ranges))
            loss = 0.3 if rng.random() < cfg.loss_share else 0.0
            p = sub_problem(pool, int(rng.integers(len(pool))), n, rr, loss, rng)
            alloc, views = play_problem(p, policy)
            data.extend(prepare(s) for s in label(p, alloc, views))
        data = data[-cfg.max_views:]
        play_s = time.perf_counter() - t0
        losses = dagger.fit(opt, data, rng, cfg.updates, cfg.batch, it)
        log.info("iteration %d: %d views, play %.1f s, loss %.3f", it, len(data), play_s,
                 float(np.mean(losses[-50:])))
        if validate is not None:
            dagger.validate(validate, it)
    return dagger.finish()


def config_dict(cfg: ViewConfig) -> dict:
    return asdict(cfg)
