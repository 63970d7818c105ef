"""Benchmark: one DAgger gradient step of the view model, per view against padded batches.

Views are collected as DAgger collects them (the plugin's two-hop rule with the shipped
``view.pt`` on random sub-problems of the cached training pools, N = 8 to 50, 10-30 m ranges)
and labelled by the teacher. The same batches of ``--batch`` views are then fitted twice:

* **per view** (the reference, as training did before): one forward and backward pass per
  view, :func:`allocators.magnnet.views.view_loss`;
* **batched**: :func:`allocators.magnnet.view_batch.batch_loss` (views of similar size padded
  together, the first linear map of each layer split by input block).

Printed: milliseconds of wall and CPU time per step (forward, backward; no optimizer step),
the ratio, and the largest difference of the two losses (they are the same number).

Run: ``.venv/bin/python benchmarks/view_fit.py [--steps 40] [--batch 16] [--threads 2]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv=None) -> int:
    import torch

    from allocators.magnnet.allocator import MagnnetAllocator, shipped
    from allocators.magnnet.ppo import load_checkpoint
    from allocators.magnnet.problems import load_pool
    from allocators.magnnet.view_batch import batch_loss, prepare
    from allocators.magnnet.views import label, play_problem, sub_problem, view_loss

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    pools = [load_pool(20, 600, "train", workers=2), load_pool(50, 200, "train", workers=2)]
    match, _ = load_checkpoint(shipped("match"))
    model, _ = load_checkpoint(shipped("view"))
    policy = MagnnetAllocator.with_models(match, model, view_hops=2, view_confidence=0.5,
                                          view_patience=5)
    rng = np.random.default_rng(0)
    data = []
    for _ in range(args.episodes):
        pool = pools[rng.integers(2)]
        n = int(rng.choice([s for s in (8, 12, 20, 30, 50) if s <= pool.cost.shape[1]]))
        prob = sub_problem(pool, int(rng.integers(len(pool))), n,
                           float(rng.choice([10.0, 20.0, 30.0])), 0.0, rng)
        alloc, views = play_problem(prob, policy)
        data.extend(label(prob, alloc, views))
    prepared = [prepare(s) for s in data]
    batches = [rng.integers(len(data), size=args.batch) for _ in range(args.steps)]
    model.train()
    worst = 0.0
    times = {}
    for name in ("per view", "batched"):
        wall, cpu = time.perf_counter(), time.process_time()
        for idx in batches:
            if name == "per view":
                loss = sum(view_loss(model, data[i]) for i in idx) / len(idx)
            else:
                loss = batch_loss(model, [prepared[i] for i in idx])
            model.zero_grad()
            loss.backward()
            times.setdefault(name + " losses", []).append(loss.item())
        times[name] = ((time.perf_counter() - wall) / args.steps * 1e3,
                       (time.process_time() - cpu) / args.steps * 1e3)
    worst = max(abs(a - b) for a, b in zip(times["per view losses"], times["batched losses"]))
    edges = np.mean([s[0].size for s in data])
    print(f"{len(data)} views (mean {edges:.0f} edges), {args.steps} steps of {args.batch}, "
          f"{args.threads} torch threads")
    print(f"{'method':<10} {'wall ms':>8} {'cpu ms':>8}")
    for name in ("per view", "batched"):
        print(f"{name:<10} {times[name][0]:>8.1f} {times[name][1]:>8.1f}")
    print(f"ratio per view / batched: wall {times['per view'][0] / times['batched'][0]:.2f}, "
          f"cpu {times['per view'][1] / times['batched'][1]:.2f}; largest loss difference "
          f"{worst:.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
