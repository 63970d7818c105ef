"""The paper's model trained by PPO (``magnnet`` variant ``paper``) on unseen instances, against
Hungarian and greedy, with both readings of conflict-free success.

Instances: the first decision of ``scenarios/paper_static.toml`` for the evaluation seeds
2 000 000 .. 2 000 000 + count - 1 (training draws its instances from seeds 1 000 000 on; see
:mod:`allocators.magnnet.problems`), complete communication graph (the paper's setting). Every
allocator answers through the plugin interface, as in ``benchmarks/paper_tables.py``.

Columns per N and method: gap to Hungarian (mean over the instances fully assigned, %; an
instance left with a task unassigned is counted in ``all`` instead), ``cf``: our conflict-free
success (tasks assigned without ever being in conflict, over all tasks), ``cf paper``: the
paper's reading (task claims granted: of all requests made, the share that ended with the task
assigned to its requester; a contested task whose cheapest requester won counts for that
requester), ``all``: instances fully assigned, ``rounds``.

    .venv/bin/python benchmarks/paper_ppo.py [--count 50] [--sizes 4 8 12 20]
        [--checkpoint 4=runs/train/magnnet_paper_n4/model.pt ...]
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.paper_tables import PAPER, problem_of


def paper_reading(allocation) -> float:
    """Share of the requests of ``allocation`` that won their task (1.0 without requests)."""
    reqs = allocation.requests
    return sum(r.won for r in reqs) / len(reqs) if reqs else 1.0


def ours(allocation, n_tasks: int) -> float:
    """Tasks assigned without ever being in conflict, over all tasks (the project's measure)."""
    conflicted = allocation.conflicted_tasks()
    return sum(1 for _, j in allocation.pairs if j not in conflicted) / n_tasks


def evaluate(pool, allocators: dict) -> dict:
    """``{name: {"gap", "cf", "cf_paper", "complete", "rounds"}}`` (means over ``pool``)."""
    res = {name: {k: [] for k in ("gap", "cf", "cf_paper", "complete", "rounds")}
           for name in allocators}
    from dispatch.api.registry import load

    hung = load("allocator", "hungarian")()
    for k in range(len(pool)):
        p = problem_of(pool, k, int(pool.seeds[k]))
        ref = float(sum(p.cost[i, j] for i, j in hung.allocate(p).pairs))
        for name, alloc in allocators.items():
            p = problem_of(pool, k, int(pool.seeds[k]))
            a = alloc.allocate(p)
            total = float(sum(p.cost[i, j] for i, j in a.pairs))
            r = res[name]
            full = len(a.pairs) == min(p.n_agents, p.n_tasks)
            if full:  # an instance left incomplete would look cheap: its gap is not counted
                r["gap"].append((total - ref) / ref if ref > 0 else 0.0)
            r["cf"].append(ours(a, p.n_tasks))
            r["cf_paper"].append(paper_reading(a))
            r["complete"].append(full)
            r["rounds"].append(a.rounds)
    return {name: {k: float(np.mean(v)) if v else float("nan") for k, v in r.items()}
            for name, r in res.items()}


def main(argv=None) -> int:
    from allocators.magnnet.allocator import clear_model_cache
    from allocators.magnnet.problems import load_pool
    from dispatch.api.registry import load

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=50)
    p.add_argument("--sizes", type=int, nargs="*", default=[4, 8, 12, 20])
    p.add_argument("--checkpoint", nargs="*", default=[],
                   help="N=path: a candidate paper checkpoint, shown as 'new'")
    p.add_argument("--no-shipped", action="store_true",
                   help="leave out the shipped paper checkpoints")
    args = p.parse_args(argv)
    cand = {}
    for item in args.checkpoint:
        n, _, path = item.partition("=")
        cand.setdefault(int(n), []).append(path)
    magnnet = load("allocator", "magnnet")
    hdr = (f"{'N':>3} {'method':<22} {'gap %':>7} {'cf %':>6} {'cf paper %':>10} "
           f"{'all %':>6} {'rounds':>6}")
    print(hdr)
    print("-" * len(hdr))
    for n in args.sizes:
        pool = load_pool(n, args.count, "eval", workers=2)
        clear_model_cache()
        allocs = {"greedy": load("allocator", "greedy")()}
        if not args.no_shipped:
            allocs["magnnet:paper (shipped)"] = magnnet(variant="paper")
        for k, path in enumerate(cand.get(n, [])):
            allocs[f"new{k or ''}"] = magnnet(variant="paper", checkpoint=path)
        res = evaluate(pool, allocs)
        for name, r in res.items():
            print(f"{n:>3} {name:<22} {100 * r['gap']:>7.2f} {100 * r['cf']:>6.1f} "
                  f"{100 * r['cf_paper']:>10.1f} {100 * r['complete']:>6.1f} "
                  f"{r['rounds']:>6.1f}")
        if n in PAPER:
            _, g, s = PAPER[n]
            print(f"{'':>3} {'paper MAGNNET':<22} {g:>7.1f} {s:>6.1f}")
        print(f"{'':>3} ({len(pool)} instances, seeds {pool.seeds[0]}..{pool.seeds[-1]})",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
