"""Benchmark: the ``astar`` planner's N x M cost matrix against scipy Dijkstra fields.

The paper's world (``scenarios/paper_static.toml``: 50 x 50 x 30 m, 1 m cells, 10 obstacles),
its fleet (half UAVs at 5 m/s, 26-connected; half UGVs at 3 m/s, 8-connected on the ground)
and N = M tasks on distinct free ground cells. For each N:

* **reference**: what the planner did before: one ``scipy.sparse.csgraph.dijkstra`` field per
  task and movement model on the explicit adjacency (built once per world, not timed), read at
  the agents' cells, divided by their speeds (fields kept until the matrix is done, as the
  planner keeps its own);
* **cold**: a fresh :class:`planners.astar.AStarPlanner` (no field cached anywhere) computes the
  same matrix: one compiled Dijkstra field per new (task, model), on ``FIELD_THREADS`` threads,
  and again on one thread;
* **warm**: the matrix again after every vehicle moved to another free cell, tasks unchanged:
  the fields are reused, only read at the new cells.

Every matrix is checked against the reference (equal to 1e-9, same ``inf`` pattern). Times are
the best of a few repeats (the machine may be shared); ratios are reference / ours, measured in
the same process. numba's one-time cost (compiling the kernels, or loading them from its disk
cache) is paid when :mod:`planners.graph` is imported and printed separately, as is the
per-world preprocessing.

Run: ``.venv/bin/python benchmarks/costs.py [--sizes 20 100 1000] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy.sparse.csgraph import dijkstra  # noqa: E402

from dispatch.api.problem import AgentView, TaskView  # noqa: E402
from dispatch.fleet.placement import place_fleet
from dispatch.plan.demand import VoxelDemand  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402
from dispatch.space.world import world_for  # noqa: E402
from dispatch.streams import STREAM_FLEET, STREAM_TASKS, rng_for  # noqa: E402

t_import = time.perf_counter()
from planners import _fast  # noqa: E402
from planners import graph as G  # noqa: E402
from planners.astar import AStarPlanner  # noqa: E402

t_import = time.perf_counter() - t_import


def instance(scenario, n: int, seed: int):
    """The paper's world, fleet of ``n`` and ``n`` ground tasks on distinct cells."""
    spec = scenario.runs(allocator="hungarian", agents=n, seed=seed)[0]
    world = world_for(scenario.world, seed)
    agents = tuple(v.view() for v in place_fleet(world, spec, rng_for(seed, STREAM_FLEET)))
    demand = VoxelDemand(world.grid, scenario.tasks.ground_fraction, rng_for(seed, STREAM_TASKS))
    cells: dict = {}
    while len(cells) < n:
        req = demand.draw()
        kind, cell = req.kind, req.loc
        cells.setdefault(cell, kind)
    tasks = tuple(TaskView(i, kind, cell, 0.0) for i, (cell, kind) in enumerate(cells.items()))
    return world, agents, tasks


def moved(world, agents, rng) -> tuple[AgentView, ...]:
    """Every vehicle on another free cell of its kind (UAVs anywhere, UGVs on the ground)."""
    free = world.grid.free_cells()
    ground = free[free[:, 2] == 0]
    out = []
    for a in agents:
        pool = free if a.flies else ground
        c = pool[rng.integers(len(pool))]
        out.append(AgentView(a.id, a.kind, (int(c[0]), int(c[1]), int(c[2])), a.speed))
    return tuple(out)


def reference(world, agents, tasks) -> np.ndarray:
    """One scipy Dijkstra field per task and movement model, read at the agents' cells.

    The fields are kept until the matrix is done, as the planner keeps its own (the previous
    planner cached exactly these): both sides pay for fresh memory alike."""
    grid = world.grid
    out = np.full((len(agents), len(tasks)), np.inf)
    kept = []
    for flies in (True, False):
        g = G.graph(grid, flies)
        rows = [a for a, ag in enumerate(agents) if ag.flies == flies and grid.is_free(ag.cell)
                and (flies or ag.cell[2] == 0)]
        nodes = np.array([g.node(agents[a].cell) for a in rows], dtype=np.int64)
        speed = np.array([agents[a].speed for a in rows])
        for t, task in enumerate(tasks):
            if not flies and (task.kind != "ground" or task.cell[2] != 0):
                continue
            field = dijkstra(g.csr, directed=True, indices=g.node(task.cell))
            out[rows, t] = field[nodes] / speed
            kept.append(field)
    return out


def check(ours: np.ndarray, ref: np.ndarray) -> float:
    fin = np.isfinite(ref)
    if not np.array_equal(fin, np.isfinite(ours)):
        raise SystemExit("MISMATCH: the inf patterns differ")
    err = float(np.abs(ours[fin] - ref[fin]).max()) if fin.any() else 0.0
    if err > 1e-9:
        raise SystemExit(f"MISMATCH: max |ours - reference| = {err:.3e} s")
    return err


def cold(world, agents, tasks, threads: int) -> tuple[float, np.ndarray]:
    """Seconds for a fresh planner's first matrix (nothing cached) on ``threads`` threads."""
    saved = G.FIELD_THREADS
    G.FIELD_THREADS = threads
    try:
        world.grid.cache.pop(G._FIELDS_KEY, None)
        planner = AStarPlanner(world)
        t0 = time.perf_counter()
        cost = planner.costs(agents, tasks)
        return time.perf_counter() - t0, cost
    finally:
        G.FIELD_THREADS = saved


def best(fn, reps: int):
    times, out = [], None
    for _ in range(reps):
        t, out = fn()
        times.append(t)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 100, 1000])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    scenario = load_scenario(ROOT / "scenarios" / "paper_static.toml")

    # one-time costs, outside every timing below
    world, agents, tasks = instance(scenario, 4, args.seed)
    t0 = time.perf_counter()
    G.graph(world.grid, True)
    G.graph(world.grid, False)
    t_masks = time.perf_counter() - t0
    t0 = time.perf_counter()
    G.graph(world.grid, True).csr
    G.graph(world.grid, False).csr
    t_csr = time.perf_counter() - t0
    hits = sum(sum(k.stats.cache_hits.values()) for k in (_fast.dijkstra_field, _fast.astar))
    print(f"paper world seed {args.seed}: {world.grid.shape} cells, "
          f"{int(world.grid.occupied.sum())} blocked; numba {_fast.numba.__version__}, "
          f"FIELD_THREADS = {G.FIELD_THREADS}")
    print(f"one-time: import planners {t_import * 1e3:.0f} ms (kernels "
          f"{'loaded from the numba disk cache' if hits else 'JIT-compiled'} at import); "
          f"move masks {t_masks * 1e3:.1f} ms (ours, per world); "
          f"scipy adjacency {t_csr * 1e3:.0f} ms (reference, per world)")
    print()
    head = (f"{'N=M':>5} {'reference':>11} {'cold':>10} {'ratio':>6} {'cold 1 thr':>11} "
            f"{'ratio':>6} {'warm':>9} {'warm p50':>9} {'max err':>9}")
    print(head)
    print("-" * len(head))
    for n in args.sizes:
        world, agents, tasks = instance(scenario, n, args.seed)
        reps = 5 if n <= 20 else 2 if n <= 100 else 1
        ts = []
        for _ in range(reps if n <= 100 else 1):
            t0 = time.perf_counter()
            ref = reference(world, agents, tasks)
            ts.append(time.perf_counter() - t0)
        t_ref = min(ts)
        t_cold, ours = best(lambda: cold(world, agents, tasks, G.FIELD_THREADS), reps)
        err = check(ours, ref)
        t_cold1, ours1 = best(lambda: cold(world, agents, tasks, 1), reps)
        err = max(err, check(ours1, ref))
        # warm: same planner, tasks unchanged, vehicles moved
        world.grid.cache.pop(G._FIELDS_KEY, None)
        planner = AStarPlanner(world)
        planner.costs(agents, tasks)
        rng = np.random.default_rng(1000 + n)
        warm = []
        for r in range(30 if n <= 100 else 5):
            now = moved(world, agents, rng)
            t0 = time.perf_counter()
            cost = planner.costs(now, tasks)
            warm.append(time.perf_counter() - t0)
            if r < (2 if n <= 100 else 1):  # exact after moving too
                err = max(err, check(cost, reference(world, now, tasks)))
        print(f"{n:>5} {t_ref * 1e3:>8.1f} ms {t_cold * 1e3:>7.1f} ms {t_ref / t_cold:>5.1f}x "
              f"{t_cold1 * 1e3:>8.1f} ms {t_ref / t_cold1:>5.1f}x {min(warm) * 1e3:>6.3f} ms "
              f"{statistics.median(warm) * 1e3:>6.3f} ms {err:>9.1e}")
        del planner, ours, ours1
        world.grid.cache.pop(G._FIELDS_KEY, None)
    print()
    print("reference: scipy.sparse.csgraph.dijkstra, one field per task and model; cold: first "
          "matrix of a fresh planner; warm: after all vehicles moved (best and median); times "
          "are best of repeats; ratio = reference / ours. Targets: cold >= 10x, warm <= 1 ms "
          "at N = M = 20.")


if __name__ == "__main__":
    main()
