"""``dispatch train magnnet --variant ppo``: the attention policy trained by PPO alone.

Output folder (default ``runs/train/magnnet_ppo``): ``model.pt`` (``weights_only=True``),
``log.parquet`` (one row per update and per validation), ``reward.png``, ``entropy.png`` and
``validation.png`` (gap to the optimal assignment and conflict-free share of the argmax
policy on the validation decisions, per N).

Instances: the cached ``N = 20`` training pool (seeds from 1 000 000); its last ``--val``
instances are held out for validation (cut to N = 4, 8, 12, 20); the evaluation seeds
(2 000 000 on) are never read. Budget: ``--minutes`` of wall time (the updates stop there;
default 120, the issue's two hours of CPU), or ``--updates``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

VAL_SIZES = (4, 8, 12, 20)

#: the ``ppo`` variant's training, in :class:`~allocators.magnnet.ppo.PPOConfig` terms: the
#: rounds environment, per-agent credit, 12 rounds of 48 decisions per update, every size from
#: 4 to 12 in turn, a radio graph of 15-40 m for 30 % of the decisions
RECIPE = {"env": "rounds", "credit": "agent", "n_envs": 48, "batch_size": 48 * 12, "epochs": 3,
          "minibatch_size": 256, "sizes": ((4, 4), (6, 6), (8, 8), (10, 10), (12, 12)),
          "comm_ranges": (15.0, 40.0), "p_range": 0.3, "val_every": 10}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--updates", type=int, default=100_000)
    p.add_argument("--minutes", type=float, default=120.0,
                   help="wall-time budget of the PPO updates")
    p.add_argument("--pool", type=int, default=600)
    p.add_argument("--val", type=int, default=60)
    p.add_argument("--val-count", type=int, default=24, help="validation decisions per N")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--ent", type=float, default=0.01)
    p.add_argument("--team-weight", type=float, default=0.5)
    p.add_argument("--cost-weight", type=float, default=1.0,
                   help="weight w of the win and stall rewards against the conflict "
                        "penalty: w (R_WIN - c / c_mean), w R_STALL")
    p.add_argument("--gap-weight", type=float, default=1.0,
                   help="weight of the gap in the validation score that keeps the weights")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("runs/train/magnnet_ppo"))


def validation(pool, count: int, seed: int = 4321):
    """Fixed validation decisions per N (cut from held-out training instances) with their
    optimal totals (for the reported gap only; the trainer never sees them)."""
    from allocators.hungarian import optimal_pairs
    from allocators.magnnet.ppo import Sampler

    out = {}
    s = Sampler(pool, np.random.default_rng(seed))
    for n in VAL_SIZES:
        d = s.draw(count, n, n)
        cost, flies = d.cost, d.flies
        opt = np.array([sum(c[a, t] for a, t in optimal_pairs(c)) for c in cost])
        out[n] = (cost, flies, opt)
    return out


def measure(model, val, gap_weight: float = 1.0) -> dict:
    """Gap (fully assigned decisions), conflict-free share of tasks, share fully assigned,
    per N; ``score`` (lower is better: ``gap_weight`` times the gap, plus the share of tasks
    not conflict-free, plus three times the share left incomplete, averaged over N) picks the
    kept weights."""
    from allocators.magnnet.ppo_env import play

    res, score = {}, 0.0
    for n, (cost, flies, opt) in val.items():
        env, _ = play(model, cost, flies)
        full = (env.agent_task >= 0).sum(1) == n
        gap = (env.totals() - opt) / opt
        g = float(gap[full].mean()) if full.any() else 1.0
        cf = float((env.taken & ~env.conflicted).mean())
        comp = float(full.mean())
        res.update({f"gap{n}": g, f"cf{n}": cf, f"complete{n}": comp})
        score += gap_weight * g + (1 - cf) + 3 * (1 - comp)
    res["score"] = score / len(val)
    return res


def run(args, console=None) -> int:
    import torch

    from allocators.magnnet.attention import AttentionPolicy
    from allocators.magnnet.ppo import PPOConfig, save_checkpoint, train
    from allocators.magnnet.problems import load_pool
    from allocators.magnnet.train_files import write_log

    torch.set_num_threads(args.threads)
    say = console.print if console else print
    device = "cuda" if torch.cuda.is_available() else "cpu"
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    full = load_pool(20, args.pool, "train", workers=2)
    n_val = min(args.val, len(full) // 2)
    pool = full.take(slice(0, len(full) - n_val))
    val = validation(full.take(slice(len(full) - n_val, len(full))), args.val_count)
    cfg = PPOConfig(**RECIPE, lr=args.lr, ent_coef=args.ent, team_weight=args.team_weight,
                    cost_weight=args.cost_weight, total_steps=args.updates * RECIPE["batch_size"],
                    seed=args.seed, wall_s=60 * args.minutes)
    with torch.random.fork_rng():
        torch.manual_seed(cfg.seed)
        model = AttentionPolicy()
    started = time.perf_counter()

    def on_update(row):
        if row["phase"] == "val":
            gaps = " / ".join(f"{100 * row[f'val/gap{n}']:.1f}" for n in VAL_SIZES)
            cfs = " / ".join(f"{100 * row[f'val/cf{n}']:.0f}" for n in VAL_SIZES)
            say(f"update {row['update']}: val gap {gaps} %, cf {cfs} % ({row['wall_s']:.0f} s)")

    rows = train(model, pool, cfg, on_update, validate=lambda m: measure(m, val, args.gap_weight))
    wall = time.perf_counter() - started
    vals = [r for r in rows if r["phase"] == "val"]
    kept = min(vals, key=lambda r: r["val/score"]) if vals else None
    steps = rows[-1]["env_steps"] if rows else 0
    from dataclasses import asdict

    save_checkpoint(model, out / "model.pt", None,
                    {"wall_s": wall, "env_steps": steps, "device": device,
                     "threads": args.threads, "ppo": asdict(cfg),
                     "val": {k: v for k, v in (kept or {}).items() if k.startswith("val/")},
                     "kept_update": kept["update"] if kept else None,
                     "world_size": full.world_size.tolist(),
                     "pool": f"train seeds from 1000000, N=20, {len(pool)} training + "
                             f"{n_val} validation instances"})
    write_log(rows, out)
    figures(rows, out)
    say(f"trained in {wall:.0f} s, {steps} environment steps, {len(rows) - len(vals)} "
        f"updates; checkpoint {out / 'model.pt'}; kept update {kept and kept['update']}")
    return 0


def figures(rows, out: Path) -> None:
    """reward.png, entropy.png (running means over the updates) and validation.png."""
    from allocators.magnnet.train_files import pyplot

    plt = pyplot()
    if plt is None:
        return
    ppo = [r for r in rows if r["phase"] == "ppo"]
    x = np.array([r["env_steps"] for r in ppo])
    for key, name, label in (("charts/episode_return", "reward.png",
                              "mean episode team reward per agent"),
                             ("losses/entropy", "entropy.png", "policy entropy (deciding)")):
        y = np.array([r[key] for r in ppo], float)
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.plot(x, y, alpha=0.3, lw=0.7)
        k = max(1, len(y) // 30)
        if len(y) >= k:
            ok = np.nan_to_num(y, nan=np.nanmean(y) if np.isfinite(y).any() else 0.0)
            ax.plot(x[k - 1:], np.convolve(ok, np.ones(k) / k, mode="valid"),
                    label=f"mean of {k}")
            ax.legend(fontsize=7)
        ax.set_xlabel("environment steps (rounds of one decision)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / name, dpi=120)
        plt.close(fig)
    val = [r for r in rows if r["phase"] == "val"]
    if val:
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
        xv = [r["env_steps"] for r in val]
        for n in VAL_SIZES:
            ax[0].plot(xv, [100 * r[f"val/gap{n}"] for r in val], label=f"N={n}")
            ax[1].plot(xv, [100 * r[f"val/cf{n}"] for r in val], label=f"N={n}")
        ax[0].set_ylabel("validation gap to optimal (%)")
        ax[1].set_ylabel("validation conflict-free tasks (%)")
        for a in ax:
            a.set_xlabel("environment steps")
            a.grid(alpha=0.3)
            a.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "validation.png", dpi=120)
        plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="magnnet-train --variant ppo", description=__doc__)
    add_arguments(p)
    return run(p.parse_args(argv))
