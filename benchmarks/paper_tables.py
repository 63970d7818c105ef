"""Reproduce the MAGNNET paper's Tables I and III on unseen instances, with any range and loss.

Instances: the first decision of ``scenarios/paper_static.toml`` (exact A* costs, UAV/UGV mix,
M = N tasks) for evaluation seeds 2 000 000 + k (training used seeds from 1 000 000; see
:mod:`allocators.magnnet.problems`), cached under ``.cache/magnnet``. Every allocator answers
the same :class:`~dispatch.api.problem.AllocationProblem`: the paper's complete communication
graph by default, or the graph of ``--comm-range`` metres between the agents' positions, with
``--loss`` (probability that one reception of a broadcast is lost).

Printed per N and allocator: mean total travel cost (Table I), mean gap to Hungarian, share of
instances fully assigned, conflict-free success (Table III: tasks assigned to exactly one agent
without ever being in conflict, over all tasks), mean decision rounds, messages and sequential
message hops (``magnnet``'s include its view flooding), and the
per-agent critical path of compute (ms; agents think in parallel on their own hardware; for
centralized methods the whole call). Allocators are built (models loaded, warmed up) before
any timing, and the model cache is cleared first so every process starts cold the same way.

Allocators (``name`` or ``name:variant``): ``hungarian`` (reference), ``local_hungarian``
(each agent solves its two-hop view), ``local_hungarian:component`` (each agent solves its
component; shown as ``local_hung:comp``), ``magnnet`` (default: views flooded to 6 hops,
component plans of the match model, the DAgger-trained view model otherwise; see
:mod:`allocators.magnnet.allocator`), ``magnnet:view2`` (``view_hops = 2``: the rule before
the flooding), ``magnnet:match_only`` (the match model on two-hop partial views too: what
``magnnet`` did before the view model; an ablation), ``magnnet:paper`` / ``magnnet:paper_nb`` (the
paper's network, per
N = M; left out where no checkpoint ships), ``auction`` (CBBA), ``greedy``, ``random``.

    .venv/bin/python benchmarks/paper_tables.py [--count 100] [--sizes 4 8 12 20]
        [--big-sizes 50 100] [--big-count 100] [--comm-range 20] [--loss 0.3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dispatch.api.problem import AgentView, AllocationProblem, TaskView
from dispatch.api.registry import load

PAPER = {  # Table I and III of the paper: (MAGNNET cost, gap %, success %)
    4: (20.3, 0.0, 100), 8: (61.2, 1.5, 100), 12: (134.7, 2.1, 90), 20: (321.5, 26.4, 80)}
SMALL = ["hungarian", "local_hungarian", "local_hungarian:component", "magnnet",
         "magnnet:view2", "magnnet:match_only", "magnnet:paper", "magnnet:paper_nb", "auction",
         "greedy", "random"]
BIG = ["hungarian", "local_hungarian", "local_hungarian:component", "magnnet", "magnnet:view2",
       "magnnet:match_only", "auction", "greedy", "random"]
#: Shorter labels where a table name does not fit the method column.
LABEL = {"local_hungarian:component": "local_hung:comp"}


def problem_of(pool, k: int, seed: int, comm_range: float | None = None,
               loss: float = 0.0) -> AllocationProblem:
    cost = pool.cost[k]
    n, m = cost.shape
    agents = tuple(AgentView(i, "uav" if pool.flies[k, i] else "ugv",
                             tuple(int(v) for v in np.floor(pool.agent_pos[k, i])),
                             5.0 if pool.flies[k, i] else 3.0) for i in range(n))
    tasks = tuple(TaskView(j, "ground", tuple(int(v) for v in np.floor(pool.task_pos[k, j])),
                           0.0) for j in range(m))
    from dispatch.api.comms import comm_graph

    return AllocationProblem(0.0, agents, tasks, cost.copy(),
                             comm_graph(pool.agent_pos[k], comm_range),
                             np.random.default_rng(seed), loss=loss,
                             agent_pos=pool.agent_pos[k].astype(float),
                             task_pos=pool.task_pos[k].astype(float))


def build(name: str, n: int):
    """The allocator of a table name, or None (printed) where a paper checkpoint is missing."""
    plugin, _, variant = name.partition(":")
    cls = load("allocator", plugin)
    if plugin == "local_hungarian" and variant:
        return cls(view=variant)
    if plugin != "magnnet" or not variant:
        return cls()
    if variant == "match_only":
        return cls(partial="match", view_hops=2)
    if variant == "view2":
        return cls(view_hops=2)
    from allocators.magnnet.allocator import shipped

    if not shipped(variant, n).exists():
        print(f"(no checkpoint {shipped(variant, n).name}: {name} left out at N={n})")
        return None
    return cls(variant=variant)


def evaluate(pool, names, comm_range: float | None = None, loss: float = 0.0) -> dict:
    n = pool.cost.shape[1]
    from allocators.magnnet.allocator import clear_model_cache

    clear_model_cache()
    allocs = {name: a for name in names if (a := build(name, n)) is not None}
    keys = ("cost", "gap", "complete", "success", "rounds", "messages", "hops", "time",
            "agent_time")
    res = {name: {k: [] for k in keys} for name in allocs}
    for k in range(len(pool)):
        ref = None
        for name, alloc in allocs.items():
            p = problem_of(pool, k, int(pool.seeds[k]), comm_range, loss)
            t0 = time.perf_counter()
            a = alloc.allocate(p)
            dt = time.perf_counter() - t0
            total = float(sum(p.cost[i, j] for i, j in a.pairs))  # ids are indices here
            conflicted = a.conflicted_tasks()
            ok = sum(1 for _, j in a.pairs if j not in conflicted)
            if ref is None:
                ref = total
            r = res[name]
            r["cost"].append(total)
            r["gap"].append((total - ref) / ref if ref > 0 else 0.0)
            r["complete"].append(len(a.pairs) == min(p.n_agents, p.n_tasks))
            r["success"].append(ok / p.n_tasks)
            r["rounds"].append(a.rounds)
            r["messages"].append(a.messages)
            r["hops"].append(a.hops)
            r["time"].append(dt)
            r["agent_time"].append(max(a.agent_seconds) if a.agent_seconds else dt)
    return {name: {k: float(np.mean(v)) for k, v in r.items()} for name, r in res.items()}


def main(argv=None) -> int:
    from allocators.magnnet.problems import load_pool

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--sizes", type=int, nargs="*", default=[4, 8, 12, 20])
    p.add_argument("--big-sizes", type=int, nargs="*", default=[50, 100])
    p.add_argument("--big-count", type=int, default=100)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--comm-range", type=float, default=None,
                   help="communication range in metres (default: unlimited, as in the paper)")
    p.add_argument("--loss", type=float, default=0.0,
                   help="probability that one reception of a broadcast is lost")
    p.add_argument("--allocators", nargs="*", default=None,
                   help="table names (default: all; see the module docstring)")
    args = p.parse_args(argv)
    rows = []
    for sizes, count, names in ((args.sizes, args.count, SMALL),
                                (args.big_sizes, args.big_count, BIG)):
        if args.allocators:  # the gap is to Hungarian: it always runs, first
            names = ["hungarian"] + [x for x in args.allocators
                                     if x != "hungarian" and (x in names or ":" not in x)]
        for n in sizes:
            pool = load_pool(n, count, "eval", workers=args.workers)
            rows.append((n, len(pool), evaluate(pool, names, args.comm_range, args.loss)))
    print(f"communication range: {args.comm_range or 'unlimited'} m, loss {args.loss:g}")
    print("cost: mean total travel (s); gap to Hungarian; cf: conflict-free success; "
          "all: instances fully assigned; ms: per-agent compute critical path")
    hdr = (f"{'N':>3} {'method':<18} {'cost':>7} {'gap %':>6} {'cf %':>6} {'all %':>6} "
           f"{'rounds':>6} {'msgs':>6} {'hops':>5} {'ms':>7}")
    print(hdr)
    print("-" * len(hdr))
    for n, count, res in rows:
        for name, r in res.items():
            print(f"{n:>3} {LABEL.get(name, name):<18} {r['cost']:>7.1f} "
                  f"{100 * r['gap']:>6.2f} {100 * r['success']:>6.1f} "
                  f"{100 * r['complete']:>6.1f} {r['rounds']:>6.1f} {r['messages']:>6.0f} "
                  f"{r['hops']:>5.1f} {1e3 * r['agent_time']:>7.2f}")
        if n in PAPER and args.comm_range is None and not args.loss:
            c, g, s = PAPER[n]
            print(f"{'':>3} {'paper MAGNNET':<18} {c:>7.1f} {g:>6.1f} {s:>6.1f}")
        print(f"{'':>3} ({count} instances)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
