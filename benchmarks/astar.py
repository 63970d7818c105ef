"""Benchmark: single-pair A* on the MovingAI 2D maps, ours against networkx.

For every map in ``../shared/data/movingai_2d`` (Sturtevant's benchmark, see its PROVENANCE):
the same 8-connected graph without corner cutting (a diagonal step only when both orthogonal
neighbours are passable; costs 1 and sqrt 2) is built once as a ``networkx.Graph`` (not timed),
and the same queries — scenarios spread evenly over the map's buckets, short to long — are
answered by

* **networkx**: ``networkx.astar_path_length`` with the octile heuristic;
* **ours**: :func:`planners.graph.astar` (compiled A*, binary heap on arrays, same octile
  heuristic), which also returns the path as cells.

Both answers are checked against the scenario's listed optimal length (1e-4). Times are total
seconds over the map's queries; the ratio is networkx / ours, measured in the same process.
numba's one-time cost (compiling, or loading from its disk cache) is paid at import.

Run: ``.venv/bin/python benchmarks/astar.py [--per-map 12] [--all]`` (``--all``: every
scenario, ours only — the full exactness check, a few minutes).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.api.voxels import Grid  # noqa: E402

t_import = time.perf_counter()
from planners import graph as G  # noqa: E402  (loads or compiles the numba kernels)

t_import = time.perf_counter() - t_import

DATA = ROOT.parent / "shared" / "data" / "movingai_2d"
SQRT2 = math.sqrt(2.0)


def load_map(path: Path) -> Grid:
    """A MovingAI map as a one-layer grid: shape (W, H, 1), x = column, y = row."""
    lines = path.read_text().splitlines()
    height, width = int(lines[1].split()[1]), int(lines[2].split()[1])
    chars = np.array([list(r[:width]) for r in lines[4 : 4 + height]])
    occ = ~np.isin(chars, list(".GS"))
    return Grid(np.ascontiguousarray(occ.T[:, :, None]), 1.0)


def load_scen(path: Path) -> list[tuple[int, int, int, int, int, float]]:
    """Rows ``(bucket, sx, sy, gx, gy, optimal)``."""
    rows = []
    for line in path.read_text().splitlines()[1:]:
        if line.strip():
            f = line.split("\t")
            rows.append((int(f[0]), int(f[4]), int(f[5]), int(f[6]), int(f[7]), float(f[8])))
    return rows


def spread(rows, count: int):
    """``count`` scenarios spread evenly over the rows (they are sorted by bucket)."""
    idx = np.unique(np.linspace(0, len(rows) - 1, num=min(count, len(rows))).round().astype(int))
    return [rows[i] for i in idx]


def nx_graph(grid: Grid):
    """The same graph for networkx: nodes (x, y), edges with weight 1 or sqrt 2."""
    import networkx as nx

    free = ~grid.occupied[:, :, 0]
    fp = np.zeros((free.shape[0] + 2, free.shape[1] + 2), dtype=bool)  # padded: 1 = (0, 0)
    fp[1:-1, 1:-1] = free
    cells = np.argwhere(free)
    x, y = cells[:, 0] + 1, cells[:, 1] + 1
    g = nx.Graph()
    g.add_nodes_from(map(tuple, cells.tolist()))
    for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
        ok = fp[x + dx, y + dy]
        if dx and dy:  # no corner cutting: both orthogonal neighbours free
            ok &= fp[x + dx, y] & fp[x, y + dy]
        weight = SQRT2 if dx and dy else 1.0
        g.add_weighted_edges_from(((i, j), (i + dx, j + dy), weight)
                                  for i, j in cells[ok].tolist())
    return g


def octile(a, b) -> float:
    dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dx, dy) + (SQRT2 - 1.0) * min(dx, dy)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-map", type=int, default=12, help="queries per map (default 12)")
    ap.add_argument("--all", action="store_true", help="every scenario, ours only")
    args = ap.parse_args()
    import networkx as nx

    maps = sorted(p.name for p in (DATA / "maps").glob("*.map"))
    if not maps:
        raise SystemExit(f"no MovingAI maps under {DATA}")
    hits = sum(G._fast.astar.stats.cache_hits.values())
    print(f"one-time: import planners.graph {t_import:.2f} s, kernels "
          f"{'loaded from the numba disk cache' if hits else 'JIT-compiled'} at import\n")
    head = (f"{'map':<16} {'size':>9} {'queries':>7} {'networkx s':>10} {'ours s':>9} "
            f"{'ratio':>7} {'max err':>8}")
    print(head)
    print("-" * len(head))
    tot_nx = tot_ours = 0.0
    for name in maps:
        grid = load_map(DATA / "maps" / name)
        rows = load_scen(DATA / "scen" / f"{name}.scen")
        if args.all:
            t = time.perf_counter()
            bad = 0
            for _, sx, sy, gx, gy, opt in rows:
                length, _ = G.astar(grid, (sx, sy, 0), (gx, gy, 0), False)
                bad += not abs(length - opt) < 1e-4
            print(f"{name:<16} {len(rows):>6} scenarios, {len(rows) - bad} exact, "
                  f"{time.perf_counter() - t:.1f} s")
            continue
        queries = spread(rows, args.per_map)
        g = nx_graph(grid)
        G.graph(grid, False)  # move masks: per map, like the networkx graph (not timed)
        err = 0.0
        t = time.perf_counter()
        theirs = [nx.astar_path_length(g, (sx, sy), (gx, gy), heuristic=octile, weight="weight")
                  for _, sx, sy, gx, gy, _ in queries]
        t_nx = time.perf_counter() - t
        t = time.perf_counter()
        ours = [G.astar(grid, (sx, sy, 0), (gx, gy, 0), False)[0] for _, sx, sy, gx, gy, _ in queries]
        t_ours = time.perf_counter() - t
        for q, a, b in zip(queries, theirs, ours):
            err = max(err, abs(a - q[5]), abs(b - q[5]))
        if err > 1e-4:
            raise SystemExit(f"MISMATCH on {name}: max error {err}")
        tot_nx += t_nx
        tot_ours += t_ours
        w, h, _ = grid.shape
        print(f"{name:<16} {f'{w}x{h}':>9} {len(queries):>7} {t_nx:>10.3f} {t_ours:>9.4f} "
              f"{t_nx / t_ours:>6.0f}x {err:>8.1e}")
    if not args.all:
        print("-" * len(head))
        print(f"{'all maps':<16} {'':>9} {'':>7} {tot_nx:>10.3f} {tot_ours:>9.4f} "
              f"{tot_nx / tot_ours:>6.0f}x")
        print("\nratio = networkx time / ours on the same graph and queries (target >= 50x); "
              "errors against the listed optimal lengths.")


if __name__ == "__main__":
    main()
