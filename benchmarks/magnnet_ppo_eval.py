"""MAGNNET variant ``ppo`` (attention + PPO alone, issue 33) beside the other MAGNNET variants,
against Hungarian, on held-out seeds, with intervals.

Instances: the first decision of ``scenarios/paper_static.toml`` for the evaluation seeds
2 000 000 .. 2 000 000 + count - 1 (:mod:`allocators.magnnet.problems`; training and
validation draw from seeds 1 000 000 on, so they never overlap). Every allocator answers
through the plugin interface (decision rounds, conflict rule and message model of
:func:`dispatch.api.decentralized.run_rounds`), at unlimited radio range and at ``--ranges``.

Per N, range and method: gap to Hungarian's total (mean over the instances fully assigned,
%, with a 95 % t-interval over instances), conflict-free share (tasks assigned without ever
being in conflict, over all tasks; mean and t-interval over instances), instances fully
assigned, rounds, and decision time per agent (``Allocation.agent_seconds``, mean over the
agents that decided; ms).

    .venv/bin/python benchmarks/magnnet_ppo_eval.py [--count 12] [--sizes 4 8 12 20]
        [--ranges inf 20] [--checkpoint PATH] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from benchmarks.paper_tables import PAPER, problem_of

METHODS = ("greedy", "magnnet:paper", "magnnet:match", "magnnet:ppo")
#: two-sided 95 % quantiles of Student's t by degrees of freedom (n - 1)
_T95 = {1: 12.71, 2: 4.30, 3: 3.18, 4: 2.78, 5: 2.57, 6: 2.45, 7: 2.36, 8: 2.31, 9: 2.26,
        10: 2.23, 11: 2.20, 12: 2.18, 13: 2.16, 14: 2.14, 15: 2.13, 19: 2.09, 24: 2.06,
        29: 2.05, 49: 2.01}


def interval(values) -> tuple[float, float]:
    """Mean and half-width of its 95 % t-interval (nan without values)."""
    v = np.asarray(values, float)
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size == 1:
        return float(v[0]), float("nan")
    df = v.size - 1
    t = _T95.get(df, _T95[max(k for k in _T95 if k <= df)])
    return float(v.mean()), float(t * v.std(ddof=1) / math.sqrt(v.size))


def build(name: str, checkpoint: str | None):
    from dispatch.api.registry import load

    plugin, _, variant = name.partition(":")
    cls = load("allocator", plugin)
    if plugin != "magnnet":
        return cls()
    if variant == "ppo" and checkpoint:
        return cls(variant="ppo", checkpoint=checkpoint)
    return cls(variant=variant)


def evaluate(pool, allocators: dict, comm_range: float | None) -> dict:
    from dispatch.api.registry import load

    hung = load("allocator", "hungarian")()
    res = {k: {"gap": [], "cf": [], "complete": [], "rounds": [], "ms": []} for k in allocators}
    for k in range(len(pool)):
        p = problem_of(pool, k, int(pool.seeds[k]), comm_range)
        ref = float(sum(p.cost[i, j] for i, j in hung.allocate(p).pairs))
        for name, alloc in allocators.items():
            p = problem_of(pool, k, int(pool.seeds[k]), comm_range)
            a = alloc.allocate(p)
            r = res[name]
            total = float(sum(p.cost[i, j] for i, j in a.pairs))
            full = len(a.pairs) == min(p.n_agents, p.n_tasks)
            if full:
                r["gap"].append(100 * (total - ref) / ref)
            conflicted = a.conflicted_tasks()
            r["cf"].append(100 * sum(1 for _, j in a.pairs if j not in conflicted) / p.n_tasks)
            r["complete"].append(100 * full)
            r["rounds"].append(a.rounds)
            sec = np.asarray(a.agent_seconds)
            r["ms"].append(1000 * float(sec[sec > 0].mean()) if (sec > 0).any() else 0.0)
    return res


def main(argv=None) -> int:
    from allocators.magnnet.allocator import clear_model_cache
    from allocators.magnnet.problems import load_pool

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=12)
    p.add_argument("--sizes", type=int, nargs="*", default=[4, 8, 12, 20])
    p.add_argument("--ranges", type=float, nargs="*", default=[math.inf, 20.0])
    p.add_argument("--methods", nargs="*", default=list(METHODS))
    p.add_argument("--checkpoint", default=None, help="a ppo checkpoint instead of ppo.pt")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    out = []
    hdr = (f"{'N':>3} {'range':>5} {'method':<15} {'gap %':>13} {'conflict-free %':>16} "
           f"{'all %':>6} {'rounds':>6} {'ms/agent':>8}")
    print(hdr)
    print("-" * len(hdr))
    for rng in args.ranges:
        for n in args.sizes:
            pool = load_pool(n, args.count, "eval")
            clear_model_cache()
            allocs = {m: build(m, args.checkpoint) for m in args.methods}
            t0 = time.perf_counter()
            res = evaluate(pool, allocs, None if math.isinf(rng) else rng)
            for name, r in res.items():
                g, gh = interval(r["gap"])
                c, ch = interval(r["cf"])
                row = {"n": n, "range": rng, "method": name, "gap": g, "gap_ci": gh,
                       "cf": c, "cf_ci": ch, "complete": float(np.mean(r["complete"])),
                       "rounds": float(np.mean(r["rounds"])), "ms_per_agent":
                       float(np.mean(r["ms"])), "instances": len(pool),
                       "seeds": [int(pool.seeds[0]), int(pool.seeds[-1])]}
                out.append(row)
                print(f"{n:>3} {rng:>5g} {name:<15} {g:>6.2f} ± {gh:<4.2f} {c:>8.1f} ± {ch:<5.1f}"
                      f" {row['complete']:>6.0f} {row['rounds']:>6.1f} "
                      f"{row['ms_per_agent']:>8.2f}", flush=True)
            if n in PAPER and math.isinf(rng):
                _, g, s = PAPER[n]
                print(f"{n:>3} {'':>5} {'paper reports':<15} {g:>6.1f} {'':>6} {s:>8.1f}")
            print(f"    ({len(pool)} instances, seeds {pool.seeds[0]}..{pool.seeds[-1]}, "
                  f"{time.perf_counter() - t0:.0f} s)", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
