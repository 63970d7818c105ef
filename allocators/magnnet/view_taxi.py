"""The view model on taxi views: decisions of a city day under a radio range (issue 22).

The shipped ``view.pt`` was trained (DAgger, :func:`allocators.magnnet.views.train_views`) on
voxel instances of 8 to 50 agents at 10-30 m ranges. On the Chicago day under a 2 km range a
two-hop view holds hundreds of taxis (cut by the plugin to each request's 4 cheapest deciding
taxis, ``view_candidates = "auto"``) and taxis waiting at one pickup node have equal costs:
the teacher's answer between them is arbitrary, the model is confident of none and they wait.

Here DAgger runs on those decisions: :func:`taxi_decisions` records decisions of runs of a road
scenario under ``radio_range`` (driven by the optimal assignment, so the fleet is where a good
dispatcher leaves it) inside time windows (night and day), :func:`train_taxi` plays them with
the plugin's own decision rounds and the model being fitted, labels every view with the teacher
(the optimal assignment of the whole remaining problem; ``own_ties``: among equal-cost optima
the one that gives the view's own agent its task, so two taxis at one node each learn "take
it" rather than "maybe", and the conflict rule settles who gets it) and fits on everything
collected. :func:`decision_gaps` is the measure: the gap to the optimal assignment of an
allocator on recorded decisions.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np

log = logging.getLogger(__name__)

#: the radio range of the issue's target (metres)
RADIO_RANGE = 2000.0
#: simulated windows (hours of the day) the decisions are drawn from: the night (few requests,
#: hundreds of idle taxis: the README's failing case) and the morning
NIGHT = (0.5, 4.0)
DAY = (7.0, 10.0)


def snapshot(problem, seed: int):
    """A plain copy of a dispatcher's decision (views built, arrays copied, its own ``rng``):
    it stays valid after the run moves on."""
    from dispatch.api.problem import AllocationProblem

    return AllocationProblem(float(problem.time), tuple(problem.agents), tuple(problem.tasks),
                             np.array(problem.cost, float), np.array(problem.comm, bool),
                             np.random.default_rng(seed), max_rounds=problem.max_rounds,
                             loss=problem.loss, latency=problem.latency,
                             cell_size=problem.cell_size,
                             agent_pos=np.array(problem.agent_pos, float),
                             task_pos=np.array(problem.task_pos, float))


def taxi_decisions(scenario, agents: int, seed: int, windows=(NIGHT, DAY), every: int = 10,
                   radio_range: float = RADIO_RANGE, batch_window: float = 30.0,
                   limit: int | None = None) -> list:
    """Every ``every``-th decision inside ``windows`` (hours) of a run of ``scenario`` (a path)
    with ``agents`` vehicles, day ``seed``, under ``radio_range`` (decisions where some taxi
    does not hear the whole fleet and there is something to decide), as :func:`snapshot`\\ s;
    the run is driven by the optimal assignment (``hungarian``) and stops after the last
    window (or ``limit`` decisions)."""
    from allocators.hungarian import HungarianAllocator
    from learning.rl import Decisions
    from learning.value_train import scenario_for

    end = max(w[1] for w in windows)
    sc = scenario_for(scenario, batch_window, end)
    sc = replace(sc, fleet=replace(sc.fleet, agents=int(agents)),
                 comms=replace(sc.comms, range=float(radio_range)))
    run = Decisions(sc, int(seed))
    run.start()
    teacher = HungarianAllocator()
    out, k = [], 0
    while run.problem is not None and (limit is None or len(out) < limit):
        p = run.problem
        h = float(run.env.now) / 3600.0
        n, m = p.cost.shape
        if any(a <= h < b for a, b in windows) and n > 1 and m > 0 \
                and np.isfinite(p.cost).any() and not np.asarray(p.comm).all():
            if k % every == 0:
                out.append(snapshot(p, seed * 1_000_003 + k))
            k += 1
        run.answer(teacher.allocate(p))
    return out


def decision_gaps(allocator, problems) -> dict:
    """An allocator on recorded decisions against the optimal assignment: ``gap`` (mean of
    (total cost - optimal) / optimal over the decisions where it assigned as many pairs as the
    optimum and the optimum costs more than 0 s: a taxi may stand at the pickup),
    ``excess`` (their total cost over the optimum's, less 1, over every such decision),
    ``complete`` (share of such decisions), ``pairs`` (its pairs / the optimum's),
    ``rounds`` (mean decision rounds), and per decision ``gaps`` (nan where incomplete),
    ``per_pairs``, ``per_optimal`` (the optimum's pairs), ``per_cost``, ``per_optimal_cost``
    and ``per_rounds``."""
    from allocators.hungarian import optimal_pairs

    gaps, per_pairs, per_opt, rounds, costs, best_costs = [], [], [], [], [], []
    for p in problems:
        a = allocator.allocate(p)
        ids_a = {int(v): k for k, v in enumerate(p.agent_ids)}
        ids_t = {int(v): k for k, v in enumerate(p.task_ids)}
        got = [(ids_a[int(i)], ids_t[int(j)]) for i, j in a.pairs]
        opt = optimal_pairs(p.cost)
        total = float(sum(p.cost[i, j] for i, j in got))
        best = float(sum(p.cost[i, j] for i, j in opt))
        per_pairs.append(len(got))
        per_opt.append(len(opt))
        costs.append(total)
        best_costs.append(best)
        rounds.append(a.rounds)
        gaps.append((total - best) / best if len(got) == len(opt) and best > 0 else np.nan)
    g = np.asarray(gaps, float)
    ok = np.isfinite(g)
    full = np.asarray(per_pairs) == np.asarray(per_opt)
    c, b = np.asarray(costs)[full], np.asarray(best_costs)[full]
    return {"gap": float(g[ok].mean()) if ok.any() else float("nan"),
            "excess": float(c.sum() / b.sum() - 1) if b.sum() > 0 else float("nan"),
            "complete": float(full.mean()) if len(g) else float("nan"),
            "pairs": sum(per_pairs) / max(1, sum(per_opt)),
            "rounds": float(np.mean(rounds)) if rounds else float("nan"),
            "gaps": gaps, "per_pairs": per_pairs, "per_optimal": per_opt,
            "per_cost": costs, "per_optimal_cost": best_costs,
            "per_rounds": rounds}


@dataclass(frozen=True)
class TaxiConfig:
    """DAgger on taxi decisions (the defaults: the shipped ``view_taxi.pt``)."""

    iterations: int = 2
    episodes: int = 40         # decisions played per iteration
    updates: int = 120         # gradient steps per iteration (big views: about 1 s each)
    batch: int = 16
    lr: float = 3e-4
    max_views: int = 20_000
    #: views kept per decision played (drawn at random): a night decision at N = 1000 gives
    #: hundreds over its rounds, most of them alike; the views are kept as labelled costs and
    #: turned into features per batch (dense features of all of them filled 22 GB)
    views_per_decision: int = 60
    own_ties: bool = True
    seed: int = 0


def train_taxi(model, match, problems, cfg: TaxiConfig, on_row=None, validate=None,
               view_hops: int = 6):
    """DAgger of the view model ``model`` (a :class:`~allocators.magnnet.views.ViewPolicy`)
    on recorded taxi decisions ``problems``: ``cfg.iterations`` times, play ``cfg.episodes`` of
    them with the plugin (``match`` for whole components, ``model`` on partial views, the
    plugin's default rule otherwise), label the views (:func:`~allocators.magnnet.views.
    label`, ``own_ties``) and fit on all views so far. With ``validate(model) -> dict`` (a
    ``score``, lower is better) the best weights are kept. Returns the log rows."""
    import torch

    from allocators.magnnet.allocator import MagnnetAllocator
    from allocators.magnnet.view_batch import prepare
    from allocators.magnnet.views import DaggerLog, label, play_problem

    rng = np.random.default_rng(cfg.seed)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    data: list = []
    dagger = DaggerLog(model, on_row)
    model.eval()
    if validate is not None:
        # the starting weights compete too: DAgger must beat them to be kept
        dagger.validate(validate, -1)
    for it in range(cfg.iterations):
        model.eval()
        t0 = time.perf_counter()
        policy = MagnnetAllocator.with_models(match, model, view_hops=view_hops)
        for k in rng.choice(len(problems), size=min(cfg.episodes, len(problems)),
                            replace=False):
            p = problems[int(k)]
            alloc, views = play_problem(p, policy)
            got = label(p, alloc, views, own_ties=cfg.own_ties)
            if len(got) > cfg.views_per_decision:
                got = [got[i] for i in sorted(rng.choice(len(got), cfg.views_per_decision,
                                                         replace=False))]
            data.extend((np.asarray(c, np.float32), *rest) for c, *rest in got)
        data = data[-cfg.max_views:]
        play_s = time.perf_counter() - t0
        if not data:
            continue
        # the views are kept as labelled costs: features per batch (see views_per_decision)
        losses = dagger.fit(opt, data, rng, cfg.updates, cfg.batch, it, prep=prepare)
        log.info("taxi iteration %d: %d views, play %.1f s, loss %.3f", it, len(data), play_s,
                 float(np.mean(losses[-50:])))
        if validate is not None:
            dagger.validate(validate, it)
    return dagger.finish()
