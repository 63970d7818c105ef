"""The ``reservation`` planner: A* costs, and SIPP routes in space-time around reservations.

Costs and untimed paths are the ``astar`` planner's (exact distance fields, A*): the allocation
sees the paper's ``c_ij`` = shortest path length / speed. Execution is reservation-based
(:mod:`dispatch.plan.traffic`): the kernel asks :meth:`ReservationPlanner.plan_timed` for a
timed
route around the other vehicles' reservations, which are intervals of continuous time per cell
(vehicles have different speeds, so there is no common time step).

SIPP (Safe Interval Path Planning, Phillips & Likhachev, ICRA 2011)
    A cell's *safe intervals* are the maximal intervals in which nobody else holds it. A search
    state is a (cell, safe interval) pair, reached at its earliest arrival time ``g``: waiting
    is allowed anywhere within a safe interval, so arriving earlier is never worse, and the
    search is A* over these states with ``f = g + h``. A successor is every safe interval of a
    neighbour cell that the step can reach: the vehicle departs at the earliest time ``>= g``
    when the neighbour is already free (its interval has begun), the step's corner cells (the
    bounding box of a diagonal) are free for the whole step, and the step ends before the
    current cell's safe interval does (the current cell is held until the step ends). A goal
    state is the goal cell in a safe interval that never ends, so the vehicle can park there.
    ``h`` is the exact static distance to the goal (:func:`planners.graph.distance_field`, the
    field the costs use) divided by the speed: admissible and consistent, and a perfect guide
    when nothing is in the way. The first goal state popped arrives earliest (optimal in arrival
    time under the model); cells that cannot reach the goal at all are never generated.

Parameters (``[dispatch.planner_params]``): ``max_expansions`` (states expanded per search
before it gives up and the vehicle waits, 200000), ``retry_after`` (seconds after which a
waiting vehicle tries again, 1.0).

Statistics (``stats.extra``): ``timed_plans`` (searches), ``timed_failures`` (no route),
``expansions`` (states expanded, all searches), ``waits_planned`` (routes with a wait in them).
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Sequence

from dispatch.api.contracts import Reservations
from dispatch.api.motion import EPS, offsets, step_box, step_seconds
from dispatch.api.problem import AgentView
from dispatch.api.voxels import Grid
from dispatch.locations import Cell
from dispatch.space.world import World
from planners.astar import AStarPlanner
from planners.graph import distance_field, graph

INF = math.inf

Interval = tuple[float, float]


class ReservationPlanner(AStarPlanner):
    """Exact A* costs; SIPP timed routes around reservations (execution with reservations)."""

    name = "reservation"
    reservation_aware = True

    def __init__(self, world: World, *, max_expansions: int = 200_000,
                 retry_after: float = 1.0, field_cache_mb: float | None = None) -> None:
        super().__init__(world, field_cache_mb=field_cache_mb)
        if int(max_expansions) < 1:
            raise ValueError(f"max_expansions must be >= 1, got {max_expansions!r}")
        if not float(retry_after) > 0:
            raise ValueError(f"retry_after must be > 0 seconds, got {retry_after!r}")
        self.max_expansions = int(max_expansions)
        self.retry_after = float(retry_after)
        for k in ("timed_plans", "timed_failures", "expansions", "waits_planned"):
            self.stats.extra.setdefault(k, 0)

    #: Retries of blocked vehicles in one run past which ``dispatch validate`` refuses it
    #: (see :meth:`budget`).
    MAX_RUN_RETRIES = 2_000_000

    def budget(self, *, agents: int, tasks: float, duration: float) -> str | None:
        """Why a run would not finish (None: it would): a vehicle that finds no timed route
        tries again every ``retry_after`` seconds, so vehicles kept waiting make up to
        ``agents × duration / retry_after`` retries, each a search (see
        :mod:`dispatch.scenario.budget`)."""
        retries = agents * duration / self.retry_after
        if retries <= self.MAX_RUN_RETRIES:
            return None
        return (f"retry_after = {self.retry_after:g} s lets {agents:,} vehicles make up to "
                f"{retries:.3g} retries in {duration:g} s (more than "
                f"{self.MAX_RUN_RETRIES:,}): a larger retry_after or a shorter duration")

    def plan_timed(self, agent: AgentView, goal: Cell | None, reservations: Reservations,
                   t0: float) -> list[tuple[float, Cell]] | None:
        """The earliest-arriving timed route from ``agent.cell`` at ``t0`` to ``goal`` (or,
        for ``goal=None``, to the nearest cell nobody reserves later) that overlaps none of
        ``reservations`` (see :meth:`dispatch.api.contracts.Planner.plan_timed`), or None when
        there is none (or the search hit ``max_expansions``)."""
        extra = self.stats.extra
        extra["timed_plans"] += 1
        route, expanded = sipp(self.world.grid, agent.flies, agent.speed, agent.cell, t0, goal,
                               reservations.blocked, self.max_expansions)
        extra["expansions"] += expanded
        if route is None:
            extra["timed_failures"] += 1
        elif any(t1 - t0_ > step_seconds(a, b, agent.speed, self.world.cell) + EPS
                 for (t0_, a), (t1, b) in zip(route, route[1:])):
            extra["waits_planned"] += 1
        return route


class _Zero:
    """A heuristic field that is 0 everywhere (parking: any cell may be the goal)."""

    def __getitem__(self, cell) -> float:
        return 0.0


_ZERO = _Zero()


def safe_intervals(blocked: Sequence[Interval], t0: float) -> list[Interval]:
    """The gaps between sorted ``blocked`` intervals that end after ``t0`` (the first gap
    starts at ``-inf``, the last ends at ``inf``; gaps shorter than EPS are dropped)."""
    out: list[Interval] = []
    lo = -INF
    for a, b in blocked:
        if b <= t0 + EPS:
            continue
        if a > lo + EPS:
            out.append((lo, a))
        lo = max(lo, b)
    if lo < INF:
        out.append((lo, INF))
    return out


def _earliest_free(t: float, dur: float, spans: list[Sequence[Interval]]) -> float:
    """The earliest ``t' >= t`` such that no interval of ``spans`` overlaps ``[t', t' + dur)``."""
    moved = True
    while moved and t < INF:
        moved = False
        for blocked in spans:
            for a, b in blocked:
                if b <= t + EPS:
                    continue
                if a >= t + dur - EPS:
                    break
                t, moved = b, True
    return t


def sipp(grid: Grid, flies: bool, speed: float, start: Cell, t0: float, goal: Cell | None,
         blocked: Callable[[Cell], Sequence[Interval]], max_expansions: int = 200_000,
         ) -> tuple[list[tuple[float, Cell]] | None, int]:
    """SIPP from ``start`` at ``t0`` to ``goal`` (see the module docstring).

    ``blocked(cell)`` gives a cell's reserved intervals, sorted and merged. Returns the route
    ``[(t0, start), (t1, c1), ..., (tn, goal)]`` (``t_i``: when the step into ``c_i`` ends) or
    None, and the number of states expanded. With ``goal=None`` the route ends in the first
    cell reachable that nobody reserves later (``h = 0``: Dijkstra in space-time).
    """
    start = tuple(int(v) for v in start)
    gg = graph(grid, flies)
    if gg.node(start) is None or grid.occupied[start]:
        return None, 0
    if goal is None:
        hfield = _ZERO
    else:
        goal = tuple(int(v) for v in goal)
        if gg.node(goal) is None or grid.occupied[goal]:
            return None, 0
        field = distance_field(grid, goal, flies)
        hfield = field if flies else field[:, :, None]  # index it by (i, j, k) either way
        if not math.isfinite(hfield[start]):
            return None, 0
    _, ny, nz = grid.shape
    nzg = nz if flies else 1
    dirs = gg.dirs
    offs = offsets(flies)
    cell_m = grid.cell
    durs = [step_seconds((0, 0, 0), d, speed, cell_m) for d in offs]
    corners = [[tuple(c) for c in step_box((0, 0, 0), d) if c != (0, 0, 0) and c != d]
               for d in offs]
    inv_speed = 1.0 / speed

    safe_cache: dict[Cell, list[Interval]] = {}

    def safe(c: Cell) -> list[Interval]:
        s = safe_cache.get(c)
        if s is None:
            s = safe_cache[c] = safe_intervals(blocked(c), t0)
        return s

    if goal is not None:
        goal_safe = safe(goal)
        if not goal_safe or goal_safe[-1][1] != INF:
            return None, 0  # someone parks on the goal for good
    first = next((i for i, (lo, hi) in enumerate(safe(start))
                  if lo <= t0 + EPS and t0 + EPS < hi), None)
    if first is None:
        return None, 0  # the start cell is not free now

    tie = itertools.count()
    best: dict[tuple[Cell, int], float] = {(start, first): t0}
    parent: dict[tuple[Cell, int], tuple[Cell, int] | None] = {(start, first): None}
    heap = [(t0 + hfield[start] * inv_speed, -t0, next(tie), start, first)]
    expanded = 0
    while heap:
        _, ng, _, c, ii = heapq.heappop(heap)
        gc = -ng
        if gc > best[(c, ii)]:
            continue  # stale
        hi_c = safe(c)[ii][1]
        if hi_c == INF and (c == goal or goal is None):
            return _route(parent, best, (c, ii)), expanded
        expanded += 1
        if expanded > max_expansions:
            return None, expanded
        mask = int(dirs[(c[0] * ny + c[1]) * nzg + c[2]])
        for b in range(len(offs)):
            if not mask >> b & 1:
                continue
            d = offs[b]
            n = (c[0] + d[0], c[1] + d[1], c[2] + d[2])
            hn = hfield[n]
            if hn == INF:
                continue
            dur = durs[b]
            latest = hi_c - dur  # leave late enough that the step ends inside c's interval
            if gc > latest + EPS:
                continue
            spans = [blocked((c[0] + o[0], c[1] + o[1], c[2] + o[2])) for o in corners[b]]
            for jj, (lo_n, hi_n) in enumerate(safe(n)):
                if lo_n > latest + EPS:
                    break
                if hi_n <= gc + dur + EPS:
                    continue
                dep = max(gc, lo_n)
                if spans:
                    dep = _earliest_free(dep, dur, spans)
                if dep > latest + EPS or dep + dur >= hi_n - EPS:
                    continue
                arr = dep + dur
                key = (n, jj)
                if arr < best.get(key, INF) - EPS:
                    best[key] = arr
                    parent[key] = (c, ii)
                    heapq.heappush(heap, (arr + hn * inv_speed, -arr, next(tie), n, jj))
    return None, expanded


def _route(parent, best, key) -> list[tuple[float, Cell]]:
    out = []
    while key is not None:
        out.append((best[key], key[0]))
        key = parent[key]
    out.reverse()
    return out
