"""Benchmark: MAGNNET's graph convolution, dense batched (ours) vs PyTorch Geometric.

The issue asks for PyG's layers unless a dense batched form is measured faster for training.
This measures one PPO minibatch's work on the paper model's first layer: 64 games of N = M
agents and tasks, agent features ``5 + M``, forward and backward. PyG runs the same layer
(:mod:`allocators.magnnet.pyg_layer`; a test checks both give the same outputs) on a
``HeteroData`` batch of the same graphs. Two PyG times are printed: with the batch built from
the dense observations (what training would pay each minibatch) and on a prebuilt batch (the
layer alone). Ratio = PyG time / dense time.

Run: ``.venv/bin/python benchmarks/gnn_layers.py [--sizes 4 8 12 20] [--batch 64]``
(needs ``pip install -e ".[bench]"``).
"""

from __future__ import annotations

import argparse
import time

import torch

from allocators.magnnet.model import AGENT_F, TASK_F, HeteroGraphConv
from allocators.magnnet.pyg_layer import PygHeteroGraphConv, to_pyg


def best_of(fn, repeat: int = 5, number: int = 10) -> float:
    """Best mean seconds per call over ``repeat`` runs of ``number`` calls."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return min(times)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="*", default=[4, 8, 12, 20])
    p.add_argument("--batch", type=int, default=64)
    args = p.parse_args(argv)
    torch.manual_seed(0)
    torch.set_num_threads(1)  # as the trainer runs
    print(f"torch {torch.__version__}, one thread; forward + backward of one layer "
          f"(hidden 6), {args.batch} graphs per batch")
    hdr = (f"{'N=M':>4} {'dense ms':>9} {'PyG ms':>9} {'ratio':>6} {'PyG layer ms':>13} "
           f"{'ratio':>6} {'max diff':>9}")
    print(hdr)
    print("-" * len(hdr))
    for n in args.sizes:
        b = args.batch
        dense = HeteroGraphConv(AGENT_F + n, TASK_F, 2, 6)
        pyg = PygHeteroGraphConv.from_dense(dense)
        h, g = torch.randn(b, n, AGENT_F + n), torch.randn(b, n, TASK_F)
        e = torch.randn(b, n, n, 2)
        adj = torch.ones(b, n, n)

        def run_dense():
            out, tk = dense(h, g, e, adj)
            (out.sum() + tk.sum()).backward()

        def run_pyg_built():
            out, tk = pyg(to_pyg(h, g, e, adj))
            (out.sum() + tk.sum()).backward()

        batch = to_pyg(h, g, e, adj)

        def run_pyg_layer():
            out, tk = pyg(batch)
            (out.sum() + tk.sum()).backward()

        with torch.no_grad():
            diff = (pyg(batch)[0].reshape(b, n, -1) - dense(h, g, e, adj)[0]).abs().max()
        t_dense = best_of(run_dense)
        t_built = best_of(run_pyg_built, number=3)
        t_layer = best_of(run_pyg_layer)
        print(f"{n:>4} {1e3 * t_dense:>9.3f} {1e3 * t_built:>9.3f} {t_built / t_dense:>5.1f}x "
              f"{1e3 * t_layer:>13.3f} {t_layer / t_dense:>5.1f}x {float(diff):>9.1e}")
    print("ratio = PyG / dense (higher: dense is faster); PyG: batch built from the dense "
          "observations each time; PyG layer: on a prebuilt batch.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
