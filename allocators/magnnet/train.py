"""``dispatch train magnnet``: train a MAGNNET model, log to Parquet, draw Figures 3 and 4.

Output folder: ``model.pt`` (checkpoint, loadable with ``weights_only=True``), ``log.parquet``
(one row per update: ``charts/...`` and ``losses/...`` scalars), ``reward.png`` (the paper's
Figure 3: mean reward against training steps) and ``entropy.png`` (Figure 4) for the PPO
variants; ``loss.png`` (imitation loss and validation curve) for ``match`` and ``view``.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from allocators.magnnet.train_files import pyplot, write_log

log = logging.getLogger(__name__)

#: The view model's second DAgger stage (``dispatch train magnnet --variant view`` runs both):
#: the played policy waits longer before it must request, and the steps are half as large.
STAGE2 = {"iterations": 3, "patience": 8, "lr": 5e-4}

#: PPO recipe of the shipped ``paper_n{N}.pt`` (``dispatch train magnnet --variant paper``):
#: pure PPO from random weights (no imitation), the paper's hyperparameters except the
#: learning rate (the paper's 1e-5 does not move the policy in 500k steps here: the README's
#: ablation), with the reward of :mod:`allocators.magnnet.rules`.
RECIPE = {"lr": 3e-4, "steps": 500_000, "bc_updates": 0, "critic_warmup": 0}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from allocators.magnnet.ppo import PPOConfig

    d = PPOConfig()
    p.add_argument("--agents", type=int, default=8, help="N (= M tasks) of the paper model")
    p.add_argument("--variant", choices=["paper", "paper_nb", "match", "view", "day", "ppo"],
                   default="paper",
                   help="paper: the paper's model exactly, PPO; paper_nb: plus per-task "
                        "neighbour features in the actor (ours); match: size-agnostic "
                        "agent-task graph network trained by imitation of the optimal "
                        "assignment (ours; --agents and the PPO options do not apply); view: "
                        "the match network for partial views (2-hop, limited range), DAgger "
                        "from match.pt (ours; --iterations, --episodes, --updates); day: "
                        "PPO on taxi decisions of a city day from match.pt (issue 22; its own "
                        "options: --variant day --help); ppo: the attention policy trained by "
                        "PPO alone, one model for every N (issue 33; its own options: "
                        "--variant ppo --help)")
    p.add_argument("--updates", type=int, default=None,
                   help="match: imitation updates (default 6000); view: per DAgger iteration "
                        "(default 300)")
    p.add_argument("--iterations", type=int, default=None,
                   help="view: DAgger iterations of the first stage (default 4)")
    p.add_argument("--stage2", type=int, default=STAGE2["iterations"],
                   help="view: DAgger iterations of the second stage, from the first stage's "
                        "kept weights with --stage2-patience and --stage2-lr and a fresh "
                        "dataset (0: one stage)")
    p.add_argument("--stage2-patience", type=int, default=STAGE2["patience"],
                   help="view: the played policy's patience in the second stage")
    p.add_argument("--stage2-lr", type=float, default=STAGE2["lr"],
                   help="view: learning rate of the second stage")
    p.add_argument("--episodes", type=int, default=None,
                   help="view: decisions played per DAgger iteration")
    p.add_argument("--patience", type=int, default=None,
                   help="view: round from which the played policy must request (default 5)")
    p.add_argument("--confidence", type=float, default=None,
                   help="view: softmax a pair needs before the played policy requests it")
    p.add_argument("--view-hops", type=int, default=2,
                   help="view: view_hops of the played plugin (2, the default: two-hop views "
                        "only, as the shipped view.pt was trained; 6: the plugin's default "
                        "rule, so DAgger visits the states after the component plans)")
    p.add_argument("--threads", type=int, default=2, help="view: torch threads")
    p.add_argument("--taxi", action="store_true",
                   help="view: DAgger on taxi decisions of a city day under a radio range "
                        "instead of the voxel stages, from the shipped view.pt (or --init): "
                        "the view_taxi.pt the plugin runs on taxi-scale views "
                        "(allocators/magnnet/view_taxi.py; --iterations, --episodes, --updates, "
                        "--lr apply)")
    p.add_argument("--taxi-scenario", type=Path,
                   default=Path(__file__).resolve().parents[2] / "scenarios" / "chicago_taxi.toml",
                   help="view --taxi: the road scenario whose decisions are trained on")
    p.add_argument("--taxi-agents", type=int, nargs="+", default=[500, 1000],
                   help="view --taxi: fleet sizes of the training days")
    p.add_argument("--taxi-seeds", type=int, nargs="+", default=[100, 101],
                   help="view --taxi: training days (keep the evaluation's seeds 0-4 out)")
    p.add_argument("--taxi-val-seed", type=int, default=110,
                   help="view --taxi: the day whose decisions pick the kept weights")
    p.add_argument("--taxi-every", type=int, default=6,
                   help="view --taxi: keep every k-th decision of the night and day windows")
    p.add_argument("--taxi-range", type=float, default=2000.0,
                   help="view --taxi: radio range in metres")
    p.add_argument("--taxi-windows", nargs="+", default=["0.5-4", "7-10"],
                   help="view --taxi: hours of the day the decisions are drawn from, as A-B "
                        "(default: the night and the morning)")
    p.add_argument("--init", type=Path, default=None,
                   help="view: continue from this view checkpoint instead of match.pt")
    p.add_argument("--steps", type=int, default=RECIPE["steps"],
                   help="PPO environment steps (rounds of one game)")
    p.add_argument("--bc-updates", type=int, default=RECIPE["bc_updates"],
                   help="imitation warm-start updates before PPO (0, the default: pure PPO "
                        "from random weights, as in the paper; the checkpoints shipped before "
                        "issue 19 had 300)")
    p.add_argument("--bc-defer", action=argparse.BooleanOptionalAction, default=True,
                   help="warm-start target: agents with a cheaper contender for their optimal "
                        "task wait a round (see ppo_warm.optimal_targets)")
    p.add_argument("--lr", type=float, default=None,
                   help=f"PPO learning rate (default {RECIPE['lr']:g}; the paper's {d.lr:g} "
                        "learns nothing in our step budget)")
    p.add_argument("--credit", choices=["team", "agent"], default=d.credit,
                   help="PPO advantages: team (one per round, the team reward; default) or "
                        "agent (each agent's own reward stream and value; see PPOConfig)")
    p.add_argument("--envs", type=int, default=d.n_envs)
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--pool", type=int, default=600, help="training instances (cached A* costs)")
    p.add_argument("--val", type=int, default=100,
                   help="of those, held out for validation (picks the final weights; 0: none)")
    p.add_argument("--reject-penalty", type=float, default=None,
                   help="paper/paper_nb: R_REJECT, the reward of rejecting while the cheapest "
                        "deciding contender for an open task (default: rules.R_REJECT)")
    p.add_argument("--losers-only", action=argparse.BooleanOptionalAction, default=None,
                   help="paper/paper_nb: only the losers of a contested task pay R_CONFLICT "
                        "(default: rules.CONFLICT_LOSERS_ONLY)")
    p.add_argument("--critic-warmup", type=int, default=RECIPE["critic_warmup"],
                   help="PPO updates at the start that fit only the critic")
    p.add_argument("--ent", type=float, default=d.ent_coef, help="entropy coefficient")
    p.add_argument("--out", type=Path, default=None, help="output folder")


def run(args, console=None) -> int:
    import torch
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from allocators.magnnet.model import NB_FEATURES, MagnnetPolicy
    from allocators.magnnet.ppo import (PPOConfig, evaluate, save_checkpoint, score, train,
                                        validation_set)
    from allocators.magnnet.problems import load_pool

    if args.variant == "match":
        return _run_match(args, console)
    if args.variant == "view":
        return _run_view(args, console)
    torch.set_num_threads(1)
    from allocators.magnnet import rules

    if args.reject_penalty is not None:  # this process only: the game reads rules at each step
        rules.R_REJECT = args.reject_penalty
    if args.losers_only is not None:
        rules.CONFLICT_LOSERS_ONLY = args.losers_only
    reward = {k: getattr(rules, k) for k in ("R_WIN", "R_COST", "R_CONFLICT", "R_REJECT",
                                               "R_TEAM", "TEAM_SHARPNESS", "R_STALL",
                                               "CONFLICT_LOSERS_ONLY")}
    n = args.agents
    out = args.out or Path("runs") / "train" / f"magnnet_{args.variant}_n{n}"
    out.mkdir(parents=True, exist_ok=True)
    cfg = PPOConfig(lr=RECIPE["lr"] if args.lr is None else args.lr, total_steps=args.steps,
                    bc_updates=args.bc_updates, n_envs=args.envs, seed=args.seed,
                    bc_defer=args.bc_defer, critic_warmup=args.critic_warmup,
                    ent_coef=args.ent, credit=args.credit, sizes=((n, n),))
    pool_n = max(20, n)
    full = load_pool(pool_n, args.pool, "train", workers=2)
    n_val = min(args.val, len(full) // 2)
    pool = full.take(slice(0, len(full) - n_val))
    validate = None
    if n_val and args.variant.startswith("paper"):
        val = validation_set(full.take(slice(len(full) - n_val, len(full))), n, n, 100)

        def validate(model):
            res = evaluate(model, val)
            return {**res, "score": score(res)}
    tf = NB_FEATURES if args.variant == "paper_nb" else 0
    with torch.random.fork_rng():  # seeded initial weights, without touching global state
        torch.manual_seed(cfg.seed)
        model = MagnnetPolicy(n, n, task_features=tf, agent_values=cfg.credit == "agent")
    started = time.perf_counter()
    total = cfg.bc_updates + cfg.total_steps // (max(1, cfg.batch_size // cfg.n_envs)
                                                 * cfg.n_envs)
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}"
                  "/{task.total}"), TimeElapsedColumn(), console=console) as progress:
        bar = progress.add_task(f"magnnet {args.variant} N={n}", total=total)

        def on_update(row):
            if row["phase"] == "val":
                return
            desc = (f"{row['phase']} loss {row['losses/imitation']:.3f}" if row["phase"] == "bc"
                    else f"ppo return {row['charts/episode_return']:.2f} "
                         f"gap {row['charts/gap']:.3f}")
            if row["phase"] != "val":
                progress.update(bar, advance=1, description=desc)

        rows = train(model, pool, cfg, on_update, validate=validate)
    wall = time.perf_counter() - started
    steps = rows[-1]["env_steps"] if rows else 0
    ppo_rows = [r for r in rows if r["phase"] == "ppo"]
    bc_rows = [r for r in rows if r["phase"] == "bc"]
    bc_wall = bc_rows[-1]["wall_s"] if bc_rows else 0.0
    ppo_wall = (ppo_rows[-1]["wall_s"] - bc_wall) if ppo_rows else 0.0
    ppo_steps = len(ppo_rows) and ppo_rows[-1]["env_steps"] - (bc_rows[-1]["env_steps"]
                                                               if bc_rows else 0)
    vals = [r for r in rows if r["phase"] == "val"]
    best_val = min(vals, key=lambda r: r["val/score"]) if vals else None
    save_checkpoint(model, out / "model.pt", cfg,
                    {"wall_s": wall, "env_steps": steps, "ppo_wall_s": ppo_wall,
                     "reward": reward,
                     "ppo_env_steps": ppo_steps,
                     "val": {k: v for k, v in (best_val or {}).items() if k.startswith("val/")},
                     "world_size": pool.world_size.tolist(),
                     "pool": f"train seeds from 1000000, N={pool_n}, {len(pool)} training + "
                             f"{n_val} validation instances"})
    write_log(rows, out)
    _figures(rows, out)
    msg = (f"trained in {wall:.1f} s, {steps} env steps ({steps / wall:.0f} steps/s); PPO "
           f"{ppo_steps} env steps in {ppo_wall:.1f} s "
           f"({ppo_steps / max(ppo_wall, 1e-9):.0f} steps/s); checkpoint {out / 'model.pt'}")
    if best_val:
        msg += (f"\nkept weights of update {best_val['update']} (validation gap "
                f"{100 * best_val['val/gap']:.2f} %, conflict-free "
                f"{100 * best_val['val/conflict_free']:.1f} %)")
    (console.print if console else print)(msg)
    return 0


def _run_match(args, console=None) -> int:
    """Imitation training of :class:`~allocators.magnnet.match.MatchPolicy`: ``model.pt``,
    ``log.parquet`` (one row per update and per validation) and ``loss.png``."""
    import torch
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from allocators.magnnet.match import MatchConfig, MatchPolicy, config_dict, train
    from allocators.magnnet.ppo import save_checkpoint
    from allocators.magnnet.problems import load_pool

    torch.set_num_threads(2)
    cfg = MatchConfig(updates=args.updates or MatchConfig.updates, seed=args.seed)
    out = args.out or Path("runs") / "train" / "magnnet_match"
    out.mkdir(parents=True, exist_ok=True)
    full = load_pool(20, args.pool, "train", workers=2)
    n_val = min(args.val, len(full) // 2)
    pools = [full.take(slice(0, len(full) - n_val))]
    val = full.take(slice(len(full) - n_val, len(full))) if n_val else None
    with torch.random.fork_rng():  # seeded initial weights, without touching global state
        torch.manual_seed(cfg.seed)
        model = MatchPolicy(cfg.hidden, cfg.layers)
    started = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}"
                  "/{task.total}"), TimeElapsedColumn(), console=console) as progress:
        bar = progress.add_task("magnnet match", total=cfg.updates)

        def on_update(row):
            if row["phase"] == "val":
                progress.update(bar, description=f"validation gap {100 * row['val/gap']:.2f} %")
            else:
                progress.advance(bar)

        rows = train(model, pools, cfg, on_update, val_pool=val)
    wall = time.perf_counter() - started
    vals = [r for r in rows if r["phase"] == "val"]
    best = min(vals, key=lambda r: (-r["val/complete"], r["val/gap"])) if vals else None
    save_checkpoint(model, out / "model.pt", None,
                    {"wall_s": wall, "updates": cfg.updates, "match": config_dict(cfg),
                     "val": {k: v for k, v in (best or {}).items() if k.startswith("val/")},
                     "world_size": full.world_size.tolist(),
                     "pool": f"train seeds from 1000000: N=20 ({len(full) - n_val} training + "
                             f"{n_val} validation instances), random sub-problems up to "
                             f"{cfg.max_size} x {cfg.max_size}"})
    write_log(rows, out)
    _loss_figure(rows, out)
    msg = f"trained in {wall:.1f} s, {cfg.updates} updates; checkpoint {out / 'model.pt'}"
    if best:
        msg += (f"\nkept weights of update {best['update']} (validation gap "
                f"{100 * best['val/gap']:.2f} % on {n_val} held-out N=20 instances)")
    (console.print if console else print)(msg)
    return 0


def _run_view(args, console=None) -> int:
    """DAgger training of :class:`~allocators.magnnet.views.ViewPolicy` from ``match.pt``
    (CTDE: the teacher solves the whole remaining problem, the student sees one agent's
    two-hop view), in two stages (the second from the first's kept weights, with
    :data:`STAGE2`'s patience and learning rate and a fresh dataset): ``model.pt``,
    ``log.parquet`` (one row per update and per validation, with its ``stage``) and
    ``loss.png``. Validation: 40 held-out N = 20 and 20 held-out N = 50 training instances at
    a 20 m range; the weights of the iteration closest to the targets, over both stages, are
    kept."""
    import dataclasses

    import torch
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from allocators.magnnet.allocator import MagnnetAllocator, shipped
    from allocators.magnnet.ppo import load_checkpoint
    from allocators.magnnet.problems import load_pool
    from allocators.magnnet.views import (ViewConfig, ViewPolicy, config_dict, evaluate_views,
                                          train_views)

    if args.taxi:
        return _run_view_taxi(args, console)
    if args.view_hops < 2 or args.threads < 1:
        raise SystemExit("--view-hops must be >= 2 and --threads >= 1")
    if args.stage2 < 0 or args.stage2_patience < 0 or not args.stage2_lr > 0:
        raise SystemExit("--stage2 and --stage2-patience must be >= 0, --stage2-lr > 0")
    torch.set_num_threads(args.threads)
    d = ViewConfig()
    cfg = dataclasses.replace(d, iterations=args.iterations or d.iterations,
                              episodes=args.episodes or d.episodes,
                              updates=args.updates or d.updates, seed=args.seed,
                              patience=d.patience if args.patience is None else args.patience,
                              confidence=args.confidence or d.confidence,
                              lr=d.lr if args.lr is None else args.lr)
    stages = [cfg] + ([dataclasses.replace(cfg, iterations=args.stage2,
                                           patience=args.stage2_patience, lr=args.stage2_lr)]
                      if args.stage2 else [])
    out = args.out or Path("runs") / "train" / "magnnet_view"
    out.mkdir(parents=True, exist_ok=True)
    p20, p50 = load_pool(20, 600, "train", workers=2), load_pool(50, 200, "train", workers=2)
    pools = [p20.take(slice(0, 500)), p50.take(slice(0, 170))]
    v20, v50 = p20.take(slice(500, 540)), p50.take(slice(170, 190))
    match, _ = load_checkpoint(shipped("match"))
    with torch.random.fork_rng():  # seeded initial weights, without touching global state
        torch.manual_seed(cfg.seed)
        model = ViewPolicy().init_from(match)
    if args.init is not None:
        model.load_state_dict(load_checkpoint(args.init)[0].state_dict())

    def validate(m):
        r20 = evaluate_views(lambda: make(m), v20, 20.0)
        r50 = evaluate_views(lambda: make(m), v50, 20.0)
        # distance to the targets (gap <= 5 / 6 %, conflict-free >= 95 %), worst of each size
        score = (max(r20["gap"] / 0.05, (1 - r20["conflict_free"]) / 0.05)
                 + max(r50["gap"] / 0.06, (1 - r50["conflict_free"]) / 0.05))
        return {"gap20": r20["gap"], "cf20": r20["conflict_free"], "gap50": r50["gap"],
                "cf50": r50["conflict_free"], "score": score}

    started, cpu0 = time.perf_counter(), _cpu_s()
    rows: list = []
    best, best_state = None, None
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}"
                  "/{task.total}"), TimeElapsedColumn(), console=console) as progress:
        bar = progress.add_task("magnnet view",
                                total=sum(c.iterations * c.updates for c in stages))
        for stage, scfg in enumerate(stages, 1):
            it0 = 1 + max((r["iteration"] for r in rows), default=-1)
            up0 = 1 + max((r["update"] for r in rows), default=-1)
            t0 = time.perf_counter() - started

            def make(m, scfg=scfg):
                return MagnnetAllocator.with_models(match, m, view_hops=args.view_hops,
                                                    view_confidence=scfg.confidence,
                                                    view_patience=scfg.patience)

            def on_row(row, stage=stage, it0=it0, up0=up0, t0=t0):
                # one log across the stages: iterations, updates and wall time run on
                row.update(stage=stage, iteration=row["iteration"] + it0,
                           update=row["update"] + up0, wall_s=row["wall_s"] + t0)
                rows.append(row)
                if row["phase"] == "val":
                    progress.update(bar, description=f"val gap {100 * row['val/gap20']:.1f} % "
                                                     f"/ {100 * row['val/cf20']:.0f} % cf "
                                                     "(N=20)")
                else:
                    progress.advance(bar)

            stage_rows = train_views(model, pools, scfg, make, on_row, validate=validate)
            vals = [r for r in stage_rows if r["phase"] == "val"]
            if vals and (best is None or min(r["val/score"] for r in vals) < best):
                best = min(r["val/score"] for r in vals)
                best_state = {k: v.clone() for k, v in model.state_dict().items()}
    if best_state is not None:  # the best over both stages (the last need not improve)
        model.load_state_dict(best_state)
    wall, cpu, kept = _save_dagger(
        model, rows, out, args.threads, started, cpu0,
        {"view": config_dict(cfg),
         "stages": [{"iterations": c.iterations, "patience": c.patience, "lr": c.lr}
                    for c in stages],
         "from": str(args.init) if args.init else "match.pt",
         "view_hops": args.view_hops},
        {"world_size": p20.world_size.tolist(),
         "pool": "train seeds from 1000000: N=20 (500) and N=50 (170) instances "
                 "for DAgger, 40 + 20 held out for validation at 20 m"},
        ("stage", "iteration", "wall_s"), _view_figure)
    msg = (f"{_trained(wall, cpu, args.threads)}"
           f"{' + '.join(str(c.iterations) for c in stages)} DAgger iterations; checkpoint "
           f"{out / 'model.pt'}")
    if kept:
        msg += (f"\nkept weights of stage {kept['stage']} iteration {kept['iteration']} "
                f"(20 m range: N=20 gap {100 * kept['val/gap20']:.2f} %, conflict-free "
                f"{100 * kept['val/cf20']:.1f} %; N=50 gap {100 * kept['val/gap50']:.2f} %, "
                f"conflict-free {100 * kept['val/cf50']:.1f} %)")
    (console.print if console else print)(msg)
    return 0


def _run_view_taxi(args, console=None) -> int:
    """DAgger of the view model on taxi decisions (:mod:`allocators.magnnet.view_taxi`), from
    the shipped ``view.pt`` (or ``--init``): ``model.pt``, ``log.parquet`` and ``loss.png``
    (the imitation loss and the validation gap to the optimal assignment on the decisions of
    day ``--taxi-val-seed``)."""
    import dataclasses

    import torch

    from allocators.magnnet.allocator import MagnnetAllocator, shipped
    from allocators.magnnet.ppo import load_checkpoint
    from allocators.magnnet.view_taxi import (TaxiConfig, decision_gaps, taxi_decisions,
                                              train_taxi)

    if set(args.taxi_seeds + [args.taxi_val_seed]) & set(range(5)):
        raise SystemExit("--taxi-seeds and --taxi-val-seed must leave the evaluation's "
                         "seeds 0-4 out")
    if args.threads < 1 or args.view_hops < 2:
        raise SystemExit("--view-hops must be >= 2 and --threads >= 1")
    try:
        windows = tuple(tuple(float(h) for h in w.split("-")) for w in args.taxi_windows)
        assert all(len(w) == 2 and 0 <= w[0] < w[1] for w in windows)
    except (ValueError, AssertionError):
        raise SystemExit(f"--taxi-windows: hours as A-B with 0 <= A < B, got "
                         f"{args.taxi_windows}") from None
    torch.set_num_threads(args.threads)
    d = TaxiConfig()
    cfg = dataclasses.replace(d, iterations=args.iterations or d.iterations,
                              episodes=args.episodes or d.episodes,
                              updates=args.updates or d.updates, seed=args.seed,
                              lr=d.lr if args.lr is None else args.lr)
    out = args.out or Path("runs") / "train" / "magnnet_view_taxi"
    out.mkdir(parents=True, exist_ok=True)
    say = console.print if console else print
    started, cpu0 = time.perf_counter(), _cpu_s()
    problems, val = [], []
    for n in args.taxi_agents:
        for seed in args.taxi_seeds:
            problems += taxi_decisions(args.taxi_scenario, n, seed, windows,
                                       args.taxi_every, args.taxi_range)
        # validation: a tenth as many decisions of a day of its own
        val += taxi_decisions(args.taxi_scenario, n, args.taxi_val_seed, windows,
                              10 * args.taxi_every, args.taxi_range)
    say(f"{len(problems)} training and {len(val)} validation decisions "
        f"({time.perf_counter() - started:.0f} s)")
    match, _ = load_checkpoint(shipped("match"))
    model, _ = load_checkpoint(args.init or shipped("view"))

    def validate(m):
        r = decision_gaps(MagnnetAllocator.with_models(match, m, view_hops=args.view_hops), val)
        # incomplete decisions (fewer pairs than the optimum: requests left waiting) weigh most
        return {"gap": r["gap"], "complete": r["complete"], "pairs": r["pairs"],
                "rounds": r["rounds"], "score": r["gap"] + 5.0 * (1.0 - r["pairs"])}

    def on_row(row):
        if row["phase"] == "val":
            say(f"iteration {row['iteration']}: validation gap {100 * row['val/gap']:.1f} %, "
                f"pairs {100 * row['val/pairs']:.1f} % of the optimum, "
                f"{row['val/rounds']:.1f} rounds ({row['wall_s']:.0f} s)")

    if not problems:
        raise SystemExit("no taxi decisions under the range in those windows: widen "
                         "--taxi-windows or lower --taxi-every / --taxi-range")
    rows = train_taxi(model, match, problems, cfg, on_row,
                      validate=validate if val else None, view_hops=args.view_hops)
    wall, cpu, kept = _save_dagger(
        model, rows, out, args.threads, started, cpu0,
        {"taxi": dataclasses.asdict(cfg), "from": str(args.init or "view.pt"),
         "scenario": str(args.taxi_scenario), "agents": args.taxi_agents,
         "seeds": args.taxi_seeds, "val_seed": args.taxi_val_seed,
         "every": args.taxi_every, "radio_range": args.taxi_range,
         "windows_h": [list(w) for w in windows], "view_hops": args.view_hops},
        {"decisions": len(problems)}, ("iteration", "wall_s"), _taxi_figure)
    msg = (f"{_trained(wall, cpu, args.threads)}"
           f"{cfg.iterations} DAgger iterations on {len(problems)} taxi decisions; checkpoint "
           f"{out / 'model.pt'} (run it with magnnet's taxi_view_checkpoint)")
    if kept:
        msg += (f"\nkept weights of iteration {kept['iteration']} (-1: the starting ones; "
                f"validation gap {100 * kept['val/gap']:.1f} %, pairs "
                f"{100 * kept['val/pairs']:.1f} % of the optimum)")
    say(msg)
    return 0


def _cpu_s() -> float:
    """CPU seconds of this process so far (user + system, all threads)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _trained(wall: float, cpu: float, threads: int) -> str:
    return f"trained in {wall:.1f} s ({cpu:.1f} CPU s on {threads} torch threads), "


def _save_dagger(model, rows, out: Path, threads: int, started: float, cpu0: float,
                 head: dict, tail: dict, curve_keys: tuple, figure):
    """The end of a DAgger trainer of the view model: ``model.pt`` (its ``extra``: wall and
    CPU seconds, ``threads``, ``head``, the kept validation row's ``val/`` values, the
    ``curve`` of validation rows (their ``val/`` values and ``curve_keys``), then ``tail``),
    ``log.parquet`` and ``figure(rows, out)``. The kept row is the validation row of least
    ``val/score`` (None without validation). Returns ``(wall, cpu, kept)``."""
    from allocators.magnnet.ppo import save_checkpoint

    wall, cpu = time.perf_counter() - started, _cpu_s() - cpu0
    vals = [r for r in rows if r["phase"] == "val"]
    kept = min(vals, key=lambda r: r["val/score"]) if vals else None
    save_checkpoint(model, out / "model.pt", None,
                    {"wall_s": wall, "cpu_s": cpu, "threads": threads, **head,
                     "val": {k: v for k, v in (kept or {}).items() if k.startswith("val/")},
                     "curve": [{k: v for k, v in r.items() if k.startswith("val/")
                                or k in curve_keys} for r in vals],
                     **tail})
    write_log(rows, out)
    figure(rows, out)
    return wall, cpu, kept


def _loss_png(rows, out: Path, fit_phase: str, right) -> None:
    """``loss.png``: on the left the imitation loss of the ``fit_phase`` rows (running mean
    of a fiftieth of them), on the right what ``right(ax, fit, val)`` draws (``ax`` both
    axes, ``fit`` those rows, ``val`` the validation rows); nothing without matplotlib."""
    import numpy as np

    plt = pyplot()
    if plt is None:
        return
    fit = [r for r in rows if r["phase"] == fit_phase]
    val = [r for r in rows if r["phase"] == "val"]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    loss = np.array([r["losses/imitation"] for r in fit])
    k = max(1, len(loss) // 50)
    if len(loss):
        smooth = np.convolve(loss, np.ones(k) / k, mode="valid")
        ax[0].plot(np.arange(len(smooth)) + k - 1, smooth)
    ax[0].set_xlabel("update")
    ax[0].set_ylabel(f"imitation loss (mean of {k})")
    right(ax, fit, val)
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "loss.png", dpi=120)
    plt.close(fig)


def _taxi_figure(rows, out: Path) -> None:
    _loss_png(rows, out, "dagger", _taxi_curve)


def _taxi_curve(ax, fit, val) -> None:
    it = [r["iteration"] + 1 for r in val]
    ax[1].plot(it, [100 * r["val/gap"] for r in val], marker="o", label="gap to optimal")
    ax[1].plot(it, [100 * (1 - r["val/pairs"]) for r in val], marker="x", ls="--",
               label="pairs short of the optimum")
    ax[1].set_xlabel("DAgger iteration (0: the starting view.pt)")
    ax[1].set_ylabel("% on validation taxi decisions")
    ax[1].legend(fontsize=7)


def _view_figure(rows, out: Path) -> None:
    _loss_png(rows, out, "dagger", _view_curve)


def _view_curve(ax, fit, val) -> None:
    it = [r["iteration"] for r in val]
    for key, lab in (("val/gap20", "gap N=20"), ("val/gap50", "gap N=50")):
        ax[1].plot(it, [100 * r[key] for r in val], marker="o", label=lab)
    for key, lab in (("val/cf20", "conflicted N=20"), ("val/cf50", "conflicted N=50")):
        ax[1].plot(it, [100 * (1 - r[key]) for r in val], marker="x", ls="--", label=lab)
    for k in range(1, len(fit)):  # where a later stage starts (fresh data, its own rate)
        if fit[k].get("stage", 1) != fit[k - 1].get("stage", 1):
            ax[0].axvline(k, color="grey", ls=":")
            ax[1].axvline(fit[k]["iteration"] - 0.5, color="grey", ls=":")
    ax[1].set_xlabel("DAgger iteration")
    ax[1].set_ylabel("% at 20 m range (validation)")
    ax[1].legend(fontsize=7)


def _loss_figure(rows, out: Path) -> None:
    _loss_png(rows, out, "imitation", _match_curve)


def _match_curve(ax, fit, val) -> None:
    ax[1].plot([r["update"] for r in val], [100 * r["val/gap"] for r in val], marker="o")
    ax[1].set_xlabel("update")
    ax[1].set_ylabel("validation gap to optimal (%)")


def _figures(rows, out: Path) -> None:
    plt = pyplot()
    if plt is None:
        return
    ppo = [r for r in rows if r["phase"] == "ppo"]
    if not ppo:
        return
    x = [r["env_steps"] for r in ppo]
    for key, name, label in (("charts/episode_return", "reward.png", "mean episode reward"),
                             ("losses/entropy", "entropy.png", "policy entropy")):
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.plot(x, [r[key] for r in ppo])
        ax.set_xlabel("environment steps")
        ax.ticklabel_format(axis="x", style="sci", scilimits=(3, 3))
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / name, dpi=120)
        plt.close(fig)
    val = [r for r in rows if r["phase"] == "val" and "val/success" in r]
    if val:  # the deterministic policy on held-out training instances (what picks the weights)
        fig, ax = plt.subplots(figsize=(5, 3.2))
        xv = [r["env_steps"] for r in val]
        ax.plot(xv, [100 * r["val/gap"] for r in val], label="gap to optimal %")
        ax.plot(xv, [100 * r["val/success"] for r in val], label="conflict-free %")
        ax.plot(xv, [100 * r["val/complete"] for r in val], label="fully assigned %")
        ax.set_xlabel("environment steps")
        ax.ticklabel_format(axis="x", style="sci", scilimits=(3, 3))
        ax.set_ylabel("validation (argmax policy)")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "validation.png", dpi=120)
        plt.close(fig)


def main(argv=None) -> int:
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    for k, a in enumerate(argv):  # --variant day: PPO for the day, options of its own
        if (a == "--variant" and argv[k + 1:k + 2] == ["day"]) or a == "--variant=day":
            from allocators.magnnet import day

            return day.main(argv[:k] + argv[k + (1 if "=" in a else 2):])
        # --variant ppo: attention + PPO alone (issue 33), options of its own
        if (a == "--variant" and argv[k + 1:k + 2] == ["ppo"]) or a == "--variant=ppo":
            from allocators.magnnet import ppo_run

            return ppo_run.main(argv[:k] + argv[k + (1 if "=" in a else 2):])
    p = argparse.ArgumentParser(prog="magnnet-train", description=__doc__)
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
