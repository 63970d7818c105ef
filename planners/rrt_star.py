"""The ``rrt_star`` planner: RRT* in the continuous world, paths snapped back to the grid.

How it works
    * **One tree per goal.** For every (goal cell, movement model) an RRT* tree (Karaman &
      Frazzoli 2011) is grown *from the goal*: its root is the goal cell's centre and every node
      knows the length of its tree path to the goal. One tree answers every agent: an agent's
      start (its cell centre) is joined to the visible tree node minimizing
      ``|start - node| + cost(node)``. A cost matrix therefore grows one tree per task and
      movement model, not one per pair (400 pairs at N = M = 20 cost 20 or 40 trees).
    * **Continuous space.** UAVs sample the box ``[c, X - c] x [c, Y - c] x [c, Z - c]``
      (``c`` = clearance), UGVs the ground plane ``z = cell / 2``. Steering moves at most
      ``step`` metres; the rewiring radius is ``min(rewire_radius, gamma (log n / n)^(1/d))``
      with ``gamma`` the RRT* constant of the sampled region's measure. With probability
      ``goal_bias`` the sample is one of the agent starts the tree still has to reach.
    * **Collisions by PyBullet ray tests, batched.** Obstacle boxes inflated by ``clearance``
      (a fraction of a cell) live in the planner's own DIRECT client
      (:class:`planners.sampling.RayWorld`); each iteration tests the new node against its
      nearest node and all its near nodes in one ``p.rayTestBatch`` call, and an agent is joined
      to its tree by batches of 64 candidate rays. Points are tested against the same boxes.
    * **Snapping.** The continuous path (start, tree nodes, goal) is turned into grid cells by a
      supercover walk of each segment; loops are cut, face steps merged into diagonal steps
      where the motion rules allow, and any illegal step repaired by a short local A*
      (:func:`planners.sampling.snap_polyline`). The returned path always passes
      :func:`dispatch.api.motion.check_path`; its length is ``>=`` the exact shortest path.
    * **Costs** are the snapped path's length in metres divided by the agent's speed: ``inf``
      for a UGV and a task above the ground layer, for pairs in different connected components
      of the grid (checked once per grid, no sampling wasted on them), and for pairs the tree
      could not join after ``max_rounds`` growth rounds. Paths are cached per
      ``(task, agent cell)``: :meth:`RRTStarPlanner.plan` returns exactly the path that was
      costed, and later decisions reuse it until :meth:`task_closed`.
    * **Growth rounds.** A new tree is grown ``max_iterations`` iterations, biased toward the
      starts of that query. A start the tree cannot see triggers up to ``max_rounds`` further
      rounds of ``max_iterations // 2`` iterations biased toward the unjoined starts.

Determinism
    Each tree has its own ``numpy.random.Generator`` seeded by ``(seed, flies, goal cell)``; no
    global random state. A tree's shape depends on the starts it was asked about first, so the
    same queries in the same order give the same costs and paths (as in a seeded run).

Parameters (``[dispatch.planner_params]``): ``max_iterations`` (1000), ``step`` (metres, 4.0),
``rewire_radius`` (metres, 10.0), ``goal_bias`` (0.1), ``seed`` (0), ``clearance`` (cells,
0.25), ``max_rounds`` (4).

Statistics (``stats.extra``): ``trees``, ``iterations``, ``nodes``, ``rays``, ``ray_batches``,
``joins_failed`` (pairs left ``inf`` although connected on the grid), ``snap_repairs``.
"""

from __future__ import annotations

import math

import numpy as np

from dispatch.api.contracts import Planner
from dispatch.api.motion import path_length
from dispatch.api.problem import AgentView, TaskView
from dispatch.locations import Cell
from dispatch.space.world import World
from planners.sampling import (GoalCache, RayWorld, connected, on_lattice, snap_polyline,
                               unit_ball_volume)

#: Trees kept for goals that are no task's (``plan`` called directly); oldest dropped first.
MAX_LOOSE_TREES = 64
_JOIN_BATCH = 64


def sampled_region(world: World, clearance: float, flies: bool):
    """``(lo, hi, dim, measure, gamma)`` of a movement model's sampled region: its corners
    (metres), dimension (3 for UAVs, 2 on the ground plane for UGVs), measure (volume or area)
    and the RRT* rewiring constant ``gamma`` of that measure."""
    cell = world.cell
    clear = clearance * cell
    size = np.asarray(world.size, dtype=float)
    lo = np.array([clear, clear, clear if flies else 0.5 * cell])
    hi = np.array([size[0] - clear, size[1] - clear, size[2] - clear if flies else 0.5 * cell])
    d = 3 if flies else 2
    measure = float(np.prod((hi - lo)[:d]))
    gamma = 2.0 * (1 + 1 / d) ** (1 / d) * (measure / unit_ball_volume(d)) ** (1 / d)
    return lo, hi, d, measure, gamma


class _Tree:
    """One RRT* tree rooted at a goal point; node 0 is the root."""

    def __init__(self, planner: RRTStarPlanner, goal: Cell, flies: bool) -> None:
        self.pl = planner
        self.flies = flies
        self.goal = goal
        world = planner.world
        cell = world.cell
        self.lo, self.hi, self.dim, _, self.gamma = sampled_region(world, planner.clearance,
                                                                   flies)
        gi, gj, gk = goal
        seq = np.random.SeedSequence(entropy=planner.seed,
                                     spawn_key=(int(flies), int(gi), int(gj), int(gk)))
        self.rng = np.random.default_rng(seq)
        cap = 256
        self.xt = np.empty((3, cap))  # node positions, one row per axis (fast distances)
        self.cost = np.empty(cap)
        self.parent = np.empty(cap, dtype=np.int64)
        self.children: list[list[int]] = [[]]
        root = np.array(world.grid.centre(goal), dtype=float)
        if not flies:
            root[2] = 0.5 * cell
        self.xt[:, 0] = root
        self.cost[0] = 0.0
        self.parent[0] = -1
        self.n = 1
        self.iterations = 0
        # agent cell -> (metres, cells) or None
        self.paths: dict[Cell, tuple[float, list[Cell]] | None] = {}

    def points(self, idx) -> np.ndarray:
        """Positions ``(k, 3)`` of the nodes ``idx``."""
        return self.xt[:, idx].T

    # ------------------------------------------------------------------ growth
    def _grow_arrays(self) -> None:
        cap = 2 * len(self.cost)
        xt = np.empty((3, cap))
        xt[:, : self.n] = self.xt[:, : self.n]
        self.xt = xt
        for name in ("cost", "parent"):
            old = getattr(self, name)
            new = np.empty(cap, dtype=old.dtype)
            new[: self.n] = old[: self.n]
            setattr(self, name, new)

    def grow(self, iterations: int, targets: np.ndarray) -> None:
        """Run ``iterations`` RRT* iterations; ``targets`` (k, 3) are biased samples."""
        pl, rng, rays = self.pl, self.rng, self.pl.rays
        dim, step, rmax = self.dim, pl.step, pl.rewire_radius
        bias = pl.goal_bias if len(targets) else 0.0
        # every random draw of this round at once (same generator, same order: deterministic)
        samples = self.lo + rng.random((iterations, 3)) * (self.hi - self.lo)
        if bias:
            use = rng.random(iterations) < bias
            pick = rng.integers(len(targets), size=iterations)
            samples[use] = targets[pick[use]]
        boxes = list(zip(rays.lo.tolist(), rays.hi.tolist()))
        gamma, inv_dim = self.gamma, 1.0 / dim
        log, sqrt = math.log, math.sqrt
        for xr in samples:
            n = self.n
            xt = self.xt[:, :n]
            D = xt - xr[:, None]
            D *= D
            d2 = D.sum(axis=0)
            near0 = int(d2.argmin())
            dist = sqrt(float(d2[near0]))
            if dist < 1e-9:
                continue
            base = xt[:, near0]
            xn = base + (xr - base) * (step / dist if dist > step else 1.0)
            px, py, pz = xn.tolist()
            if any(a < px < d and b < py < e and c < pz < f
                   for (a, b, c), (d, e, f) in boxes):
                continue
            radius = min(rmax, gamma * (log(n + 1) / (n + 1)) ** inv_dim)
            radius = max(radius, min(step, dist))  # the nearest node is always a candidate
            D = xt - xn[:, None]
            D *= D
            dn2 = D.sum(axis=0)
            near = np.flatnonzero(dn2 <= radius * radius + 1e-9)
            if near.size == 0:
                near = np.array([near0])
            frm = np.empty((near.size, 3))
            frm[:] = xn
            vis = rays.visible(frm, xt[:, near].T)
            if not vis.any():
                continue
            near = near[vis]
            dnear = np.sqrt(dn2[near])
            cnear = self.cost[near]
            through = cnear + dnear
            best = int(through.argmin())
            if n == len(self.cost):
                self._grow_arrays()
            self.xt[:, n] = xn
            cn = float(through[best])
            self.cost[n] = cn
            parent = int(near[best])
            self.parent[n] = parent
            self.children.append([])
            self.children[parent].append(n)
            self.n = n + 1
            # rewire: near nodes reached more cheaply through the new node
            better = np.flatnonzero(cn + dnear < cnear - 1e-12)
            for b in better.tolist():
                j = int(near[b])
                if j == 0:
                    continue
                self.children[int(self.parent[j])].remove(j)
                self.parent[j] = n
                self.children[n].append(j)
                delta = cn + float(dnear[b]) - float(self.cost[j])
                stack = [j]
                while stack:
                    m = stack.pop()
                    self.cost[m] += delta
                    stack.extend(self.children[m])
        self.iterations += iterations
        pl.stats.extra["iterations"] += iterations

    # ------------------------------------------------------------------ joining
    def join(self, start: np.ndarray) -> list[int] | None:
        """Node path ``[node, parent, ..., 0]`` of the best visible join of ``start``, or None."""
        n = self.n
        D = self.xt[:, :n] - start[:, None]
        D *= D
        score = self.cost[:n] + np.sqrt(D.sum(axis=0))
        order = np.argsort(score, kind="stable")
        for s in range(0, n, _JOIN_BATCH):
            cand = order[s:s + _JOIN_BATCH]
            frm = np.empty((cand.size, 3))
            frm[:] = start
            vis = self.pl.rays.visible(frm, self.points(cand))
            if vis.any():
                node = int(cand[int(np.argmax(vis))])
                chain = [node]
                while chain[-1] != 0:
                    chain.append(int(self.parent[chain[-1]]))
                return chain
        return None


class RRTStarPlanner(Planner):
    """RRT* from each goal in the continuous world (PyBullet ray tests), snapped to the grid."""

    name = "rrt_star"
    spaces = ("voxel",)

    def __init__(self, world: World, *, max_iterations: int = 1000, step: float = 4.0,
                 rewire_radius: float = 10.0, goal_bias: float = 0.1, seed: int = 0,
                 clearance: float = 0.25, max_rounds: int = 4) -> None:
        super().__init__(world)
        if int(max_iterations) < 1:
            raise ValueError(f"max_iterations must be >= 1, got {max_iterations!r}")
        if not step > 0 or not rewire_radius > 0:
            raise ValueError("step and rewire_radius must be > 0 metres")
        if not 0.0 <= goal_bias <= 1.0:
            raise ValueError(f"goal_bias must be in [0, 1], got {goal_bias!r}")
        if not 0.0 < clearance < 0.5:
            raise ValueError(f"clearance must be in (0, 0.5) cells, got {clearance!r}")
        if int(max_rounds) < 0:
            raise ValueError(f"max_rounds must be >= 0, got {max_rounds!r}")
        self.max_iterations = int(max_iterations)
        self.step = float(step)
        self.rewire_radius = float(rewire_radius)
        self.goal_bias = float(goal_bias)
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
            raise ValueError(f"seed must be an integer in [0, 2^63), got {seed!r}")
        self.seed = int(seed)
        self.clearance = float(clearance)
        self.max_rounds = int(max_rounds)
        self._rays: RayWorld | None = None
        self._cache = GoalCache(self._new_tree, MAX_LOOSE_TREES)  # (flies, goal) -> _Tree
        for k in ("trees", "iterations", "nodes", "rays", "ray_batches", "joins_failed",
                  "snap_repairs"):
            self.stats.extra.setdefault(k, 0)

    #: Tree iterations of one run past which ``dispatch validate`` refuses it (see
    #: :meth:`budget`): about 20 s on one core (an iteration scans every node of its tree).
    MAX_RUN_ITERATIONS = 60_000
    #: Ray tests of one run past which ``dispatch validate`` refuses it (see :meth:`budget`):
    #: about 20 s on one core (1.4 µs a ray, batched, measured on the paper's world).
    MAX_RUN_RAYS = 15_000_000

    def budget(self, *, agents: int, tasks: float, duration: float) -> str | None:
        """Why a run of ``tasks`` tasks would not finish (None: it would): each task's goal
        grows a tree of ``max_iterations`` iterations per movement model that serves it
        (two for a ground task), so a run costs about ``2 × tasks × max_iterations``
        iterations; and each iteration tests its new node against its rewiring neighbours
        (:meth:`tree_rays`), which a tiny ``step`` makes every node of the tree (see
        :mod:`dispatch.scenario.budget`)."""
        work = 2 * tasks * self.max_iterations
        if work > self.MAX_RUN_ITERATIONS:
            return (f"about {work:.3g} tree iterations (2 trees x {tasks:,.0f} tasks x "
                    f"max_iterations = {self.max_iterations:,}; more than "
                    f"{self.MAX_RUN_ITERATIONS:,}, about 20 s): lower max_iterations or use "
                    "astar")
        (uav, iters, reach), (ugv, _, _) = self.tree_rays(True), self.tree_rays(False)
        rays = tasks * (uav + ugv)
        if rays <= self.MAX_RUN_RAYS:
            return None
        why = (f"step = {self.step:g} m keeps a tree of {iters:,} iterations within "
               f"{reach:.3g} m of its goal, so every node is a rewiring neighbour of every new "
               f"one" if reach < self.rewire_radius else
               f"{iters:,} iterations a tree, each testing its new node against its rewiring "
               f"neighbours (rewire_radius = {self.rewire_radius:g} m)")
        return (f"about {rays:.3g} ray tests ({tasks:,.0f} tasks x a UAV and a UGV tree of "
                f"{uav:.3g} and {ugv:.3g}: {why}; more than {self.MAX_RUN_RAYS:,}, about 20 s): "
                "raise step (default 4 m), lower max_iterations or use astar")

    def tree_rays(self, flies: bool) -> tuple[float, int, float]:
        """``(rays, iterations, reach)``: the ray tests one tree of a movement model is
        expected to make while it grows, its iterations and how far (metres) they can take it
        from its goal (``iterations × step``).

        Iteration ``n`` tests its new node against the nodes within the rewiring radius
        ``r_n = min(rewire_radius, gamma (log n / n)^(1/d))``: about ``n`` times the share of
        the tree's region that ball covers, the region being the sampled one or, when the
        tree cannot reach that far, the ball of radius ``n × step`` (a lower bound of the
        share: nodes crowd nearer the goal). A tree whose every iteration together cannot
        leave its goal's cell (``iterations × step`` below a cell) cannot go around an
        obstacle: a start its goal does not see spends all ``max_rounds`` rounds of
        ``max_iterations // 2``, which are then counted (in a world with obstacles)."""
        _, _, d, measure, gamma = sampled_region(self.world, self.clearance, flies)
        rounds = self.max_rounds * max(1, self.max_iterations // 2)
        iters = self.max_iterations
        if (iters + rounds) * self.step < self.world.cell and self.world.boxes:
            iters += rounds
        n = np.arange(1, iters + 1, dtype=float)
        radius = np.minimum(self.rewire_radius, gamma * (np.log(n + 1) / (n + 1)) ** (1 / d))
        ball = unit_ball_volume(d)
        share = radius**d / np.minimum(measure / ball, (n * self.step) ** d)
        near = n * np.minimum(1.0, share)
        return float(near.sum()), iters, iters * self.step

    # ------------------------------------------------------------------ plumbing
    @property
    def rays(self) -> RayWorld:
        if self._rays is None:
            self._rays = RayWorld(self.world, self.clearance * self.world.cell)
        return self._rays

    def close(self) -> None:
        """Release the private PyBullet client (also done when the planner is collected)."""
        if self._rays is not None:
            self._rays.close()
            self._rays = None

    def _tree(self, goal: Cell, flies: bool, task_id: int | None) -> _Tree:
        return self._cache.get((flies, goal), task_id)

    def _new_tree(self, key: tuple[bool, Cell]) -> _Tree:
        self.stats.extra["trees"] += 1
        return _Tree(self, key[1], key[0])

    def _start_point(self, cell: Cell, flies: bool) -> np.ndarray:
        p = np.array(self.world.grid.centre(cell))
        if not flies:
            p[2] = 0.5 * self.world.cell
        return p

    def _paths(self, tree: _Tree, starts: list[Cell]) -> None:
        """Make sure ``tree.paths`` answers every cell of ``starts`` (grow the tree if needed)."""
        grid, flies = self.world.grid, tree.flies
        todo = [c for c in dict.fromkeys(starts) if c not in tree.paths]
        if not todo:
            return
        for c in todo:
            if c == tree.goal:
                tree.paths[c] = (0.0, [c])
            elif not connected(grid, c, tree.goal, flies):
                tree.paths[c] = None
        todo = [c for c in todo if c not in tree.paths]
        if not todo:
            return
        points = {c: self._start_point(c, flies) for c in todo}
        if tree.iterations == 0:
            tree.grow(self.max_iterations, np.array([points[c] for c in todo]))
        for round_ in range(self.max_rounds + 1):
            left = []
            for c in todo:
                chain = tree.join(points[c])
                if chain is None:
                    left.append(c)
                    continue
                poly = np.vstack([points[c][None], tree.points(chain)])
                cells = snap_polyline(grid, poly, flies, self.stats.extra)
                if cells is None:
                    left.append(c)
                    continue
                tree.paths[c] = (path_length(cells) * grid.cell, cells)
            todo = left
            if not todo or round_ == self.max_rounds:
                break
            tree.grow(max(1, self.max_iterations // 2),
                      np.array([points[c] for c in todo]))
        for c in todo:
            tree.paths[c] = None
            self.stats.extra["joins_failed"] += 1
        self.stats.extra["nodes"] = sum(t.n for t in self._cache.entries.values())
        self.stats.extra["rays"] = self.rays.rays
        self.stats.extra["ray_batches"] = self.rays.batches

    # ------------------------------------------------------------------ contract
    def costs(self, agents: tuple[AgentView, ...], tasks: tuple[TaskView, ...]) -> np.ndarray:
        """``(len(agents), len(tasks))`` travel seconds along snapped RRT* paths (see module)."""
        self.stats.cost_queries += 1
        grid = self.world.grid
        out = np.full((len(agents), len(tasks)), np.inf)
        for t, task in enumerate(tasks):
            goal = tuple(int(v) for v in task.cell)
            for flies in (True, False):
                rows = [a for a, ag in enumerate(agents)
                        if ag.flies == flies and on_lattice(grid, ag.cell, flies)]
                if not rows or not on_lattice(grid, goal, flies):
                    continue
                if not flies and task.kind != "ground":
                    continue
                tree = self._tree(goal, flies, task.id)
                starts = [tuple(int(v) for v in agents[a].cell) for a in rows]
                self._paths(tree, starts)
                for a, c in zip(rows, starts):
                    hit = tree.paths[c]
                    if hit is not None:
                        out[a, t] = hit[0] / agents[a].speed
        return out

    def plan(self, agent: AgentView, goal: Cell) -> list[Cell] | None:
        """The snapped RRT* path from ``agent.cell`` to ``goal`` (the one costed), or None."""
        self.stats.plans += 1
        grid, flies = self.world.grid, agent.flies
        goal = tuple(int(v) for v in goal)
        start = tuple(int(v) for v in agent.cell)
        if not (on_lattice(grid, start, flies) and on_lattice(grid, goal, flies)):
            return None
        tree = self._tree(goal, flies, None)
        self._paths(tree, [start])
        hit = tree.paths[start]
        return None if hit is None else list(hit[1])

    def task_closed(self, task_id: int) -> None:
        """Drop the task's trees unless another open task shares the goal cell."""
        self._cache.task_closed(task_id)
