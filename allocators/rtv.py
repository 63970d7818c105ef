"""RTV: batched multi-request assignment (Alonso-Mora et al., PNAS 2017; FleetPy's RV/RTV).

Each decision (a batch of open requests, the idle vehicles and the busy ones with a free seat):

1. **Pairwise shareability** (the RR graph): two requests are shareable when a vehicle standing
   at one of their pickups now could serve both within their limits (a necessary condition
   for any vehicle: a real one arrives there later; drives obey the triangle inequality).
2. **Feasible groups per vehicle** (the RTV graph): size 1, the requests whose insertion cost
   in ``problem.cost`` is finite (the ``max_vehicles`` cheapest vehicles of each request,
   the ``max_requests`` cheapest requests of each vehicle); size ``k``, each
   union of a feasible ``(k-1)``-group with one more of the vehicle's requests whose every
   ``(k-1)``-subgroup is feasible for the vehicle and whose pairs are shareable (feasibility
   is closed under taking subgroups, so nothing feasible is missed), up to the vehicle's
   seats. Each candidate gets its best stop order: every order of the group's pickups and
   drop-offs merged into the vehicle's plan (the plan's own order kept), on the planner's
   travel times (``problem.travel``), compiled (:mod:`allocators._rtv_kernel`). With
   ``reorder`` (Alonso-Mora et al.'s and FleetPy's whole-trip routing) every order of the
   plan's stops and the group's together: each pickup before its drop-off (a request on board
   has only its drop-off), every limit (a plan's stop by ``max(latest, planned arrival)``, as
   the kernel checks) and the capacity kept; any stop may come first (the kernel re-routes a
   vehicle whose first stop changes: it finishes the edge it is on, then drives to the new
   one). Then a request whose insertion into a busy vehicle's plan is infeasible
   (``problem.cost`` inf) may still fit once the plan is reordered: such pairs are candidates
   too when the vehicle could drive straight to the pickup by its deadline (each request's
   ``max_vehicles`` nearest; after the feasible insertions in ``max_requests``).
3. **Assignment**: at most one group per vehicle, each request in at most one group, the most
   requests served, then the least total cost: an integer program on
   :func:`scipy.optimize.milp` (HiGHS) with a time limit; the greedy assignment (largest
   groups first, then cheapest) is the fallback and the floor (the better of the two is
   taken). A batch whose groups are all single requests is a linear assignment
   (:func:`allocators.hungarian.optimal_pairs`, exact).

Times: every order is timed by the kernel's one schedule rule (:mod:`dispatch.plan.stops`): a stop
reached before its earliest time waits (a booked request's pickup, ``TaskView.earliest``: its
requested departure; a plan's stop, ``StopView.earliest``), and with driver shifts a route ends
(leaves its last stop) by its vehicle's ``problem.until`` (shift end plus grace). Waits only
delay, so feasibility stays closed under taking subgroups and the pair test stays a necessary
condition (it waits too).

Costs (``objective``): ``delay`` (default): the new requests' delays (drop-off time - release -
direct drive) plus how much later the plan's own drop-offs come; ``added_time``: how much later
the vehicle's plan ends.

Look-ahead (``value``, a file of ``dispatch train value``; ``value_weight`` seconds per unit of
value, default the file's): the assignment compares each candidate's score, its cost less
``value_weight`` x (the value of where and when its route ends -- the kernel's end of its best
order -- discounted to now, with the seats its vehicle then holds free, minus the same of the
vehicle taking nothing: where and when its own plan ends, an idle one where it is now), instead of its cost (:meth:`_Batch.value_scores`, one vectorised
call per batch; :mod:`dispatch.api.value`). Still the most requests first; the requests record
their costs. A value of zero decides exactly as no value.

Bounds and what they cut (``stats``, also :meth:`describe`): ``max_vehicles`` candidate vehicles
per request (the cheapest; None: all) and ``max_requests`` candidate requests per vehicle
(``pairs_cut``: feasible pairs left out by either), ``max_groups`` groups per vehicle
(``groups_cut``: candidate groups never evaluated), ``max_nodes`` search nodes per candidate
order (``orders_cut``), ``time_limit`` seconds per batch for the groups and the integer
program (``levels_cut``: vehicles whose larger groups were not grown; ``ilp_time_limit``:
programs stopped at the limit; ``greedy``: batches decided greedily).

Exactness: with no bound cutting (small batches), the answer serves as many requests as any
assignment of groups and, among those, has the least total cost (tested against brute force,
with ``reorder`` against every order of all the stops). ``reorder`` searches a superset of the
orders, so on the same decision it never serves fewer nor, serving as many, costs more (unless
a bound cuts). ``stats["reordered"]`` (with ``reorder`` only): routes handed out that change
the order of the plan's own stops; a pair feasible only by reordering records its request's
cost as inf (it has no insertion; the dispatcher times it from the route).

A vehicle without a plan that is still serving its last stop leaves at ``problem.ready`` (the
kernel gives it for shared rides); a problem without ``ready`` and with ``service_time > 0``
is read conservatively (every plan-less vehicle leaves after a full service time).
"""

from __future__ import annotations

import math
import time

import numpy as np

from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem, Bid

OBJECTIVES = {"delay": 0, "added_time": 1}
TOL = 5e-10  # (the kernel checks limits with +1e-9; half of it absorbs rounding differences)


def _positive_int(name: str, v, allow_none: bool = False):
    if v is None and allow_none:
        return v
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise TypeError(f"{name} must be a positive integer{' or None' if allow_none else ''}, "
                        f"got {v!r}")
    return v


class RtvAllocator(Allocator):
    """Batch pooling by the request-trip-vehicle graph and an integer program (see the module
    docstring). Deterministic: draws nothing from ``problem.rng``."""

    name = "rtv"
    decentralized = False
    multi_request = True

    def __init__(self, objective: str = "delay", max_group: int | None = None,
                 max_vehicles: int | None = 30, max_requests: int = 24,
                 max_groups: int = 200, max_nodes: int = 50_000,
                 time_limit: float = 10.0, solver: str = "milp",
                 reorder: bool = False, value: str | None = None,
                 value_weight: float | None = None,
                 value_reward: float | None = None) -> None:
        if objective not in OBJECTIVES:
            raise TypeError(f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
        if solver not in ("milp", "greedy"):
            raise TypeError(f"solver must be 'milp' or 'greedy', got {solver!r}")
        if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float)) \
                or not time_limit > 0:
            raise TypeError(f"time_limit must be a number of seconds > 0, got {time_limit!r}")
        self.objective = objective
        self.max_group = _positive_int("max_group", max_group, allow_none=True)
        self.max_vehicles = _positive_int("max_vehicles", max_vehicles, allow_none=True)
        self.max_requests = _positive_int("max_requests", max_requests)
        self.max_groups = _positive_int("max_groups", max_groups)
        self.max_nodes = _positive_int("max_nodes", max_nodes)
        self.time_limit = float(time_limit)
        if not isinstance(reorder, bool):
            raise TypeError(f"reorder must be true or false, got {reorder!r}")
        self.solver = solver
        self.reorder = reorder
        #: a learned value of where a route leaves its vehicle (module doc, "Look-ahead")
        self.value = None
        if value is not None or value_reward is not None:
            from learning.value import ValueOption

            self.value = ValueOption.of(value, value_weight, value_reward)
            self.value_function = self.value.value
        self.stats = {k: 0 for k in (
            "batches", "groups", "groups_feasible", "largest_group", "pairs_cut", "groups_cut",
            "orders_cut", "levels_cut", "ilp", "lp_whole", "ilp_time_limit", "ilp_failed",
            "greedy", "assignment", "multi")}
        if reorder:  # routes that change the order of the plan's own stops
            self.stats["reordered"] = 0
        self.stats["seconds"] = self.stats["seconds_max"] = 0.0

    def describe(self) -> dict[str, str]:
        out = {"objective": self.objective, "max_group": str(self.max_group),
               "max_vehicles": str(self.max_vehicles),
               "max_requests": str(self.max_requests), "max_groups": str(self.max_groups),
               "max_nodes": str(self.max_nodes), "time_limit": str(self.time_limit),
               "solver": self.solver}
        if self.reorder:  # (only then: the answers and summaries of reorder = false as before)
            out["reorder"] = "True"
        if self.value is not None:
            from pathlib import Path

            out.update(value=Path(self.value.path).name, value_weight=f"{self.value.weight:g}")
            if self.value.reward is not None:
                out["value_reward"] = f"{self.value.reward:g}"
        if self.stats["batches"]:
            out.update({k: (f"{v:.3f}" if isinstance(v, float) else str(v))
                        for k, v in self.stats.items()})
        return out

    # ------------------------------------------------------------------ the decision
    def allocate(self, problem: AllocationProblem) -> Allocation:
        _warm()  # compile first: the time limit counts the decision's work, not numba's
        t_start = time.perf_counter()
        n, m = problem.n_agents, problem.n_tasks
        if not n or not m or not (np.isfinite(problem.cost).any()
                                  or (self.reorder and len(problem.plans))):
            return Allocation(pairs=())
        self.stats["batches"] += 1
        try:
            return self._allocate(problem, t_start)
        finally:
            dt = time.perf_counter() - t_start
            self.stats["seconds"] += dt
            self.stats["seconds_max"] = max(self.stats["seconds_max"], dt)

    def _allocate(self, problem: AllocationProblem, t_start: float) -> Allocation:
        from allocators.hungarian import optimal_pairs

        cost = problem.cost if self.value is None else self.value.costs(problem)
        if problem.travel is None:  # no routing between arbitrary places: one request each
            return Allocation.centralized(problem, optimal_pairs(cost))
        b = _Batch(problem, self)
        if b.empty:
            return Allocation(pairs=())
        groups, gveh, gcost, gorder = b.groups(t_start)
        self.stats["groups_feasible"] += len(gveh)
        if not len(gveh):
            return Allocation(pairs=())
        score = gcost if self.value is None \
            else b.value_scores(groups, gveh, gcost, gorder, self.value)
        if self.value is not None and self.value.reward is not None:
            # worth, not count: each request is worth the reward (seconds), a candidate its
            # requests' worth less its score; one worth nothing is never taken
            score = score - self.value.reward * (groups >= 0).sum(axis=1)
            keep = np.flatnonzero(score < 0)
            if not len(keep):
                return Allocation(pairs=())
            groups, gveh, score, gorder = groups[keep], gveh[keep], score[keep], gorder[keep]
            chosen = self._assign(b, groups, gveh, score, t_start, most=False)
        else:
            chosen = self._assign(b, groups, gveh, score, t_start)
        return b.answer(chosen, groups, gveh, gorder)

    def _assign(self, b, groups, gveh, gcost, t_start: float, most: bool = True) -> list[int]:
        """Indices of the chosen (vehicle, group) candidates: the most requests, then the least
        total ``gcost``; with ``most`` False the least total ``gcost`` alone (all negative:
        the worths of :class:`learning.value.ValueOption`'s reward)."""
        sizes = (groups >= 0).sum(axis=1)
        if sizes.max() == 1:  # a linear assignment: exact
            from allocators.hungarian import gated_pairs, optimal_pairs

            self.stats["assignment"] += 1
            c = np.full((b.nv, b.m), np.inf)
            c[gveh, groups[:, 0]] = gcost
            where = {(int(j), int(r)): g for g, (j, r) in enumerate(zip(gveh, groups[:, 0]))}
            return [where[(j, r)] for j, r in (optimal_pairs(c) if most else gated_pairs(c))]
        if not most:  # the programs below count requests first: here a request counts 0
            sizes = np.zeros_like(sizes)
        if self.solver == "greedy":
            self.stats["greedy"] += 1
            return _greedy(groups, gveh, gcost, sizes)
        left = self.time_limit - (time.perf_counter() - t_start)
        got = _milp(groups, gveh, gcost, sizes, b.nv, b.m, max(left, 0.2))
        if got is None:
            self.stats["ilp_failed"] += 1
            self.stats["greedy"] += 1
            return _greedy(groups, gveh, gcost, sizes)
        chosen, status = got
        self.stats["ilp"] += 1
        if status == 2:  # the relaxation's optimum, whole: optimal
            self.stats["lp_whole"] += 1
            return chosen
        if status == 1:
            self.stats["ilp_time_limit"] += 1
        greedy = _greedy(groups, gveh, gcost, sizes)

        def value(sel):
            return (-int(sizes[sel].sum()), float(gcost[sel].sum())) if len(sel) else (0, 0.0)

        if value(greedy) < value(chosen):
            self.stats["greedy"] += 1
            return greedy
        return chosen


_WARM: set = set()
#: the arrays a mode of :func:`allocators._rtv_kernel.best_orders` does not read
_NO_F, _NO_I = np.zeros(0), np.zeros(0, np.int64)


def _warm() -> None:
    """Compile the kernels (once per process; from the disk cache where there is one). One
    compiled search serves both orders (``reorder`` is an argument, not a specialization)."""
    if "order" in _WARM:
        return
    from allocators._rtv_kernel import best_orders, pair_shareable

    z, i = np.zeros(1), np.zeros(1, np.int64)
    best_orders(np.zeros((1, 1), np.int64), i, z, z, i, np.ones(1, np.int64),
                np.zeros(2, np.int64), i, z, z, z, np.zeros(1, bool), z, z,
                np.full(1, -1, np.int64), z, np.zeros(2, np.int64), z, np.zeros((1, 2)),
                np.zeros((1, 2)), np.zeros((2, 1)), np.zeros((2, 2)), i, z + 1, z + 1, z, z,
                np.ones(1, bool), z - np.inf, z + np.inf, z, 0.0, 0, 10, TOL, False,
                np.zeros(1), np.zeros((1, 3), np.int64), np.zeros(1, bool), np.zeros(1))
    pair_shareable(0.0, np.zeros((2, 2)), i, z, z, z - np.inf, 0.0, 1, TOL)
    _WARM.add("order")


def _greedy(groups, gveh, gcost, sizes) -> list[int]:
    """Largest groups first, then the cheapest; a group whose vehicle or any request is taken
    is skipped."""
    order = np.lexsort((gcost, -sizes))
    used_v: set[int] = set()
    used_r: set[int] = set()
    out = []
    for g in order.tolist():
        j = int(gveh[g])
        if j in used_v:
            continue
        rs = [int(r) for r in groups[g] if r >= 0]
        if any(r in used_r for r in rs):
            continue
        used_v.add(j)
        used_r.update(rs)
        out.append(g)
    return out


def _milp(groups, gveh, gcost, sizes, nv: int, m: int, time_limit: float):
    """The integer program: ``(chosen candidates, status)`` (status 0 optimal, 1 stopped at the
    time limit with a solution, 2 the relaxation's optimum was whole) or None (no
    solution)."""
    from scipy.optimize import Bounds, LinearConstraint, linprog, milp
    from scipy.sparse import csr_array

    G = len(gveh)
    # most requests first: one more request outweighs any difference in cost
    scale = float(np.abs(gcost).sum()) + 1.0
    c = gcost / scale - sizes
    rows, cols = [gveh.astype(np.int64)], [np.arange(G)]
    gi, ki = np.nonzero(groups >= 0)
    rows.append(nv + groups[gi, ki].astype(np.int64))
    cols.append(gi)
    a = csr_array((np.ones(sum(len(r) for r in rows)), (np.concatenate(rows),
                                                        np.concatenate(cols))),
                  shape=(nv + m, G))
    t0 = time.perf_counter()
    try:  # the relaxation first: when its optimum is whole, it is the program's (and cheap)
        lp = linprog(c, A_ub=a, b_ub=np.ones(nv + m), bounds=(0.0, 1.0), method="highs",
                     options={"time_limit": float(time_limit)})
    except Exception:  # noqa: BLE001 - the program below decides
        lp = None
    if lp is not None and lp.status == 0 and lp.x is not None:
        x = lp.x
        if np.all((x < 1e-7) | (x > 1.0 - 1e-7)):
            return np.flatnonzero(x > 0.5).tolist(), 2
    left = max(float(time_limit) - (time.perf_counter() - t0), 0.1)
    try:
        res = milp(c, constraints=LinearConstraint(a, -np.inf, 1.0), integrality=np.ones(G),
                   bounds=Bounds(0.0, 1.0), options={"time_limit": left, "mip_rel_gap": 1e-9})
    except Exception:  # noqa: BLE001 - the greedy answer stands in
        return None
    if res.x is None:
        return None
    return np.flatnonzero(res.x > 0.5).tolist(), (0 if res.status == 0 else 1)


def _where(agents, rows: np.ndarray) -> tuple[list, np.ndarray]:
    """Where the vehicles ``rows`` of ``agents`` are: ``(a node each and the seconds left to
    it)`` where the agents are on a road network, else ``(a location each, zeros)``."""
    nodes = getattr(agents, "nodes", None)
    if nodes is not None:
        return nodes[rows].tolist(), np.asarray(agents.remaining, float)[rows]
    return [agents[int(k)].loc for k in rows.tolist()], np.zeros(rows.size)


def _nearest(pairs: np.ndarray, value: np.ndarray, alloc: RtvAllocator) -> np.ndarray:
    """``pairs`` (vehicles x requests, bool) with each request's pairs cut to the
    ``alloc.max_vehicles`` of least ``value`` (a new array where any is cut; ``pairs`` itself
    is not changed); the pairs cut counted in ``alloc.stats["pairs_cut"]``."""
    kv = alloc.max_vehicles
    if kv is None or pairs.shape[0] <= kv:
        return pairs
    count = pairs.sum(axis=0)
    over = np.flatnonzero(count > kv)
    if not over.size:
        return pairs
    sub = np.where(pairs[:, over], value[:, over], np.inf)
    keep = np.argpartition(sub, kv - 1, axis=0)[:kv]
    mask = np.zeros_like(sub, dtype=bool)
    np.put_along_axis(mask, keep, True, axis=0)
    pairs = pairs.copy()
    pairs[:, over] &= mask
    alloc.stats["pairs_cut"] += int((count[over] - kv).sum())
    return pairs


class _Batch:
    """One decision's arrays: candidate vehicles (rows with a finite pair), requests, the plans,
    the drives between everything a group's order may visit."""

    def __init__(self, problem: AllocationProblem, alloc: RtvAllocator) -> None:
        self.problem, self.alloc = problem, alloc
        cost = problem.cost
        finite = _nearest(np.isfinite(cost), cost, alloc)  # each request: its kv cheapest vehicles
        self.finite = finite
        self.extra = None
        if alloc.reorder and len(problem.plans):
            self.extra, self.reach = self._reorder_pairs(np.isfinite(cost))
        vrows = np.flatnonzero(finite.any(axis=1) if self.extra is None
                               else finite.any(axis=1) | self.extra.any(axis=1))
        self.vrows = vrows
        self.nv = nv = vrows.size
        self.empty = not nv
        if self.empty:
            return
        tasks = problem.tasks
        self.m = m = len(tasks)
        now = float(problem.time)
        self.now = now
        travel = problem.travel
        svc = self.svc = float(problem.service_time)
        caps = (np.ones(problem.n_agents, np.int64) if problem.capacity is None
                else np.asarray(problem.capacity, np.int64))
        self.cap = caps[vrows]
        ids = problem.agent_ids
        self.aids = ids[vrows]
        plans = problem.plans
        self.plans = [plans.get(int(a), ()) if len(plans) else () for a in self.aids.tolist()]
        # requests
        self.hasdrop = np.array([t.dropoff is not None for t in tasks])
        self.pax = np.array([t.passengers if t.dropoff is not None else 0 for t in tasks],
                            np.int64)
        self.lp = np.array([t.deadline for t in tasks], float)
        self.ld = np.array([t.dropoff_deadline if t.dropoff is not None else math.inf
                            for t in tasks], float)
        self.rel = np.array([t.released_at for t in tasks], float)
        # a pickup waits for its earliest time (a booked request's requested departure)
        self.r_e = np.array([t.earliest for t in tasks], float)
        new_locs = []
        for t in tasks:
            new_locs += [t.loc, t.loc if t.dropoff is None else t.dropoff]
        self.new_locs = new_locs
        nn = np.asarray(travel(new_locs, new_locs), float)
        self.nn = np.ascontiguousarray(nn)
        self.direct = np.where(self.hasdrop, nn[2 * np.arange(m), 2 * np.arange(m) + 1], 0.0)
        # vehicles: where they are (a node and the seconds left to it, or a location)
        src, rem = _where(problem.agents, vrows)
        self.src = src
        self.vn = np.ascontiguousarray(np.asarray(travel(src, new_locs), float) + rem[:, None])
        # plans, flat
        off = [0]
        flat = []
        for p in self.plans:
            flat += p
            off.append(len(flat))
        self.off = np.array(off, np.int64)
        self.flat = flat
        S = len(flat)
        self.p_pax = np.array([s.passengers for s in flat], np.int64)
        self.p_eta = np.array([s.eta for s in flat], float)
        self.p_limit = np.maximum(np.array([s.latest for s in flat], float), self.p_eta)
        self.p_drop = np.array([s.kind == "dropoff" for s in flat], bool)
        self.p_e = np.array([s.earliest for s in flat], float)
        completes = []
        for p in self.plans:
            drops = {s.task_id for s in p if s.kind == "dropoff"}
            completes += [s.kind == "dropoff" or s.task_id not in drops for s in p]
        self.p_svc = np.where(np.array(completes, bool), svc, 0.0) if S else np.zeros(0)
        load = np.zeros(nv, np.int64)
        start = np.full(nv, now)
        first_eta = np.full(nv, now)
        old_end = np.full(nv, now)
        if S:
            plocs = [s.loc for s in flat]
            self.pn = np.ascontiguousarray(np.asarray(travel(plocs, new_locs), float))
            self.np_ = np.ascontiguousarray(np.asarray(travel(new_locs, plocs), float))
            self.pp = np.zeros(S)
            if S > 1:
                self.pp[:-1] = np.asarray(travel(plocs[:-1], plocs[1:], pairwise=True), float)
            if alloc.reorder:
                self._reorder_arrays(flat, src, rem)
            has = np.flatnonzero(self.off[1:] > self.off[:-1])
            firsts = self.off[has]
            lasts = self.off[has + 1] - 1
            to_first = np.asarray(travel([src[k] for k in has.tolist()],
                                         [plocs[k] for k in firsts.tolist()], pairwise=True),
                                  float) + rem[has]
            first_eta[has] = self.p_eta[firsts]
            start[has] = np.maximum(now, self.p_eta[firsts] - to_first)
            load[has] = [flat[k].occupancy - flat[k].passengers for k in firsts.tolist()]
            old_end[has] = np.maximum(self.p_eta[lasts], self.p_e[lasts]) + self.p_svc[lasts]
        else:
            self.pn = np.zeros((0, 2 * m))
            self.np_ = np.zeros((2 * m, 0))
            self.pp = np.zeros(0)
            self.p_pred, self.vp, self.ppa = np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
            self.poff = np.zeros(nv + 1, np.int64)
        bare = self.off[1:] == self.off[:-1]
        if problem.ready is not None:  # a plan-less vehicle may be in service at its last stop
            r = np.maximum(np.asarray(problem.ready, float)[vrows], now)
            start[bare] = r[bare]
            old_end[bare] = r[bare]
        elif svc > 0:  # no ready times given: assume a full service ahead (module doc)
            start[bare] = now + svc
            old_end[bare] = now + svc
        self.start, self.first_eta, self.load, self.old_end = start, first_eta, load, old_end
        # when each vehicle's route must end (its shift's end plus the grace; inf: never)
        self.until = (np.full(nv, np.inf) if problem.until is None
                      else np.asarray(problem.until, float)[vrows])
        # candidate requests per vehicle: the cheapest max_requests finite pairs (with reorder
        # then, in the room left, the pairs feasible only by reordering, nearest first)
        sub = np.where(finite[vrows], cost[vrows], np.inf)
        if self.extra is not None:  # ranks: the insertions' costs, then 1e12 + the drive
            sub = np.where(self.extra[vrows], 1e12 + self.reach[vrows], sub)
            self.rank = sub
        self.cand: list[np.ndarray] = []
        cut = 0
        k = alloc.max_requests
        for j in range(nv):
            row = sub[j]
            ok = np.flatnonzero(np.isfinite(row))
            if ok.size > k:
                cut += ok.size - k
                ok = ok[np.argsort(row[ok], kind="stable")[:k]]
                ok.sort()
            self.cand.append(ok)
        alloc.stats["pairs_cut"] += cut
        from allocators._rtv_kernel import pair_shareable

        self.rr = pair_shareable(now, self.nn, self.pax, self.lp, self.ld, self.r_e, svc,
                                 int(self.cap.max()), TOL)
        point = ~self.hasdrop
        if point.any():  # point tasks: no pair test
            self.rr[point, :] = True
            self.rr[:, point] = True
            np.fill_diagonal(self.rr, False)

    def _reorder_pairs(self, feasible: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """With ``reorder``: the pairs whose request has no feasible insertion into the
        vehicle's plan (``problem.cost`` is inf) but might fit once the plan is reordered: the
        vehicle has a plan and could drive straight to the pickup by its deadline (a necessary
        condition; the search decides), each request's ``max_vehicles`` nearest such vehicles.
        ``(pairs (n_agents, m) bool, seconds from now to the pickup)``."""
        problem, alloc = self.problem, self.alloc
        n, tasks = problem.n_agents, problem.tasks
        plans = problem.plans
        ids = problem.agent_ids.tolist()
        rows = np.array([k for k, a in enumerate(ids) if plans.get(int(a))], np.int64)
        out = np.zeros((n, len(tasks)), bool)
        reach = np.full((n, len(tasks)), np.inf)
        if not rows.size:
            return out, reach
        now = float(problem.time)
        src, rem = _where(problem.agents, rows)
        leave = np.full(rows.size, now) if problem.ready is None else \
            np.maximum(np.asarray(problem.ready, float)[rows], now)
        t = np.asarray(problem.travel(src, [t.loc for t in tasks]), float) + rem[:, None] \
            + (leave - now)[:, None]
        caps = (np.ones(n, np.int64) if problem.capacity is None
                else np.asarray(problem.capacity, np.int64))[rows]
        lp = np.array([t.deadline for t in tasks], float)
        pax = np.array([t.passengers if t.dropoff is not None else 0 for t in tasks])
        ok = (now + t <= lp + TOL) & ~feasible[rows] & (pax[None, :] <= caps[:, None])
        ok = _nearest(ok, t, alloc)  # each request: its kv nearest such vehicles
        out[rows] = ok
        reach[rows] = np.where(ok, t, np.inf)
        return out, reach

    def _reorder_arrays(self, flat: list, src: list, rem: np.ndarray) -> None:
        """What :func:`allocators._rtv_kernel.best_orders` needs besides to reorder: each plan
        stop's pickup in the plan (``p_pred``), the drive from its vehicle to it (``vp``), the
        drives between the stops of each plan (``poff``, ``ppa``)."""
        travel = self.problem.travel
        plocs = [s.loc for s in flat]
        owner = np.repeat(np.arange(self.nv), np.diff(self.off))
        self.p_pred = np.full(len(flat), -1, np.int64)
        for j, p in enumerate(self.plans):
            a = int(self.off[j])
            picks = {s.task_id: a + u for u, s in enumerate(p) if s.kind == "pickup"}
            for u, s in enumerate(p):
                if s.kind == "dropoff" and s.task_id in picks:
                    self.p_pred[a + u] = picks[s.task_id]
        self.vp = np.asarray(travel([src[j] for j in owner.tolist()], plocs, pairwise=True),
                             float) + rem[owner]
        n = np.diff(self.off)
        self.poff = np.zeros(self.nv + 1, np.int64)
        np.cumsum(n * n, out=self.poff[1:])
        us, ws = [], []
        for j in np.flatnonzero(n > 1).tolist():
            a, k = int(self.off[j]), int(n[j])
            idx = np.arange(a, a + k)
            us.append(np.repeat(idx, k))
            ws.append(np.tile(idx, k))
        self.ppa = np.zeros(int(self.poff[-1]))
        if us:
            u, w = np.concatenate(us), np.concatenate(ws)
            got = np.asarray(travel([plocs[i] for i in u.tolist()],
                                    [plocs[i] for i in w.tolist()], pairwise=True), float)
            # (a plan of one stop has no drive between its stops: its block stays 0)
            keep = np.flatnonzero(n > 1)
            pos = np.concatenate([np.arange(self.poff[j], self.poff[j + 1]) for j in
                                  keep.tolist()])
            self.ppa[pos] = got

    def evaluate(self, groups: np.ndarray, gveh: np.ndarray):
        """Best orders of candidates ``groups`` (rows of request indices, -1 padded) on the
        vehicles ``gveh``: ``(cost, order codes, cut, end)`` (``end``: when the order leaves
        its last stop); with ``reorder`` the plan's stops
        are reordered too (:func:`allocators._rtv_kernel.best_orders` with ``reorder``)."""
        G, K = groups.shape
        plan_len = int((self.off[1:] - self.off[:-1]).max()) if self.nv else 0
        L = max(plan_len + 2 * K, 1)
        if not (G and self.alloc.reorder):
            return self._evaluate_in_order(groups, gveh, L)
        from allocators._rtv_kernel import best_orders

        cost, end = np.empty(G), np.empty(G)
        order = np.full((G, L), -99, np.int64)
        cut = np.zeros(G, bool)
        lens = (self.off[1:] - self.off[:-1])[gveh] + 2 * (groups >= 0).sum(axis=1)
        fits = lens <= 62  # the search's bit masks; longer plans keep their order
        if fits.all():
            sel = slice(None)
        else:
            sel = np.flatnonzero(fits)
            rest = np.flatnonzero(~fits)
            c2, o2, k2, e2 = self._evaluate_in_order(groups[rest], gveh[rest], L)
            cost[rest], order[rest], cut[rest], end[rest] = c2, o2, k2, e2
        c1, o1, k1 = np.empty(len(groups[sel])), order[sel].copy(), cut[sel].copy()
        e1 = np.empty(len(c1))
        best_orders(np.ascontiguousarray(groups[sel], np.int64),
                    np.ascontiguousarray(gveh[sel], np.int64), self.start, self.first_eta,
                    self.load, self.cap, self.off, self.p_pax, self.p_limit, self.p_svc,
                    self.p_eta, self.p_drop, self.p_e, _NO_F, self.p_pred, self.vp, self.poff,
                    self.ppa, self.vn, self.pn, self.np_, self.nn, self.pax, self.lp, self.ld,
                    self.rel, self.direct, self.hasdrop, self.r_e, self.until, self.old_end,
                    self.svc, OBJECTIVES[self.alloc.objective], self.alloc.max_nodes, TOL, True,
                    c1, o1, k1, e1)
        cost[sel], order[sel], cut[sel], end[sel] = c1, o1, k1, e1
        return cost, order, cut, end

    def _evaluate_in_order(self, groups: np.ndarray, gveh: np.ndarray, L: int):
        """:meth:`evaluate` with the plan's stops in their order (:func:`allocators._rtv_kernel.
        best_orders` without ``reorder``)."""
        from allocators._rtv_kernel import best_orders

        G = len(groups)
        cost, end = np.empty(G), np.empty(G)
        order = np.full((G, L), -99, np.int64)
        cut = np.zeros(G, bool)
        if G:
            best_orders(np.ascontiguousarray(groups, np.int64),
                        np.ascontiguousarray(gveh, np.int64), self.start, self.first_eta,
                        self.load, self.cap, self.off, self.p_pax, self.p_limit, self.p_svc,
                        self.p_eta, self.p_drop, self.p_e, self.pp, _NO_I, _NO_F, _NO_I, _NO_F,
                        self.vn, self.pn, self.np_, self.nn, self.pax, self.lp, self.ld,
                        self.rel, self.direct, self.hasdrop, self.r_e, self.until,
                        self.old_end, self.svc, OBJECTIVES[self.alloc.objective],
                        self.alloc.max_nodes, TOL, False, cost, order, cut, end)
        return cost, order, cut, end

    def groups(self, t_start: float):
        """All feasible (vehicle, group) candidates: ``(groups (G, K) -1 padded, vehicles,
        costs, orders)``."""
        alloc, stats = self.alloc, self.alloc.stats
        kmax = int(self.cap.max()) if alloc.max_group is None else min(alloc.max_group,
                                                                        int(self.cap.max()))
        # size 1
        gveh = np.concatenate([np.full(c.size, j, np.int64) for j, c in enumerate(self.cand)])
        g1 = np.concatenate(self.cand).astype(np.int64)[:, None]
        cost, order, cut, end = self.evaluate(g1, gveh)
        stats["groups"] += len(gveh)
        stats["orders_cut"] += int(cut.sum())
        ok = np.isfinite(cost)
        out = [(g1[ok], gveh[ok], cost[ok], order[ok])]
        self.ends = [end[ok]]  # when each feasible candidate's route ends (its value's time)
        stats["largest_group"] = max(stats["largest_group"], 1 if ok.any() else 0)
        feasible: list[set] = [set() for _ in range(self.nv)]
        for j, r in zip(gveh[ok].tolist(), g1[ok, 0].tolist()):
            feasible[j].add((r,))
        count = [len(f) for f in feasible]
        rr = self.rr
        cap = self.cap
        for k in range(2, kmax + 1):
            if time.perf_counter() - t_start > alloc.time_limit * 0.5:
                stats["levels_cut"] += sum(1 for f in feasible if len(f) > 1)
                break
            cand_rows, cand_veh = [], []
            for j in range(self.nv):
                prev = feasible[j]
                if len(prev) < k or cap[j] < k:  # a k-group needs k feasible (k-1)-subgroups
                    continue
                singles = sorted({r for g in prev for r in g})
                room = alloc.max_groups - count[j]
                got = []
                for g in sorted(prev):
                    last = g[-1]
                    for r in singles:
                        if r <= last or not rr[last, r]:
                            continue
                        if not all(rr[q, r] for q in g[:-1]):
                            continue
                        new = g + (r,)
                        if k > 2 and not all(new[:i] + new[i + 1:] in prev for i in range(k - 1)):
                            continue
                        got.append(new)
                if not got:
                    continue
                if len(got) > room:
                    stats["groups_cut"] += len(got) - room
                    if room <= 0:
                        continue
                    c1 = self.rank[j] if self.extra is not None \
                        else self.problem.cost[self.vrows[j]]
                    got.sort(key=lambda g: (sum(c1[r] for r in g), g))
                    got = got[:room]
                cand_rows += got
                cand_veh += [j] * len(got)
            if not cand_rows:
                break
            gk = np.array(cand_rows, np.int64)
            gv = np.array(cand_veh, np.int64)
            cost, order, cut, end = self.evaluate(gk, gv)
            stats["groups"] += len(gv)
            stats["orders_cut"] += int(cut.sum())
            ok = np.isfinite(cost)
            if not ok.any():
                break
            stats["largest_group"] = max(stats["largest_group"], k)
            out.append((gk[ok], gv[ok], cost[ok], order[ok]))
            self.ends.append(end[ok])
            nxt: list[set] = [set() for _ in range(self.nv)]
            for j, g in zip(gv[ok].tolist(), gk[ok].tolist()):
                nxt[j].add(tuple(g))
                count[j] += 1
            feasible = nxt
        K = max(g.shape[1] for g, *_ in out)
        L = max(o.shape[1] for *_, o in out)
        groups = np.concatenate([np.pad(g, ((0, 0), (0, K - g.shape[1])), constant_values=-1)
                                 for g, *_ in out])
        orders = np.concatenate([np.pad(o, ((0, 0), (0, L - o.shape[1])), constant_values=-99)
                                 for *_, o in out])
        return (groups, np.concatenate([v for _, v, _, _ in out]),
                np.concatenate([c for _, _, c, _ in out]), orders)

    def value_scores(self, groups, gveh, gcost, gorder, option) -> np.ndarray:
        """Each candidate's cost less ``weight`` x (the discounted value of where and when its
        route ends, with the seats its vehicle then holds free, minus the same of its vehicle
        taking nothing): the scores the assignment compares (module doc, "Look-ahead")."""
        vf, w = option.value, option.weight
        G = len(gveh)
        ints = all(isinstance(x, (int, np.integer)) for x in (*self.new_locs, *self.src,
                                                                *(s.loc for s in self.flat)))
        if w == 0 or not G or not ints:  # (no value, or locations that are not nodes)
            return gcost
        vf.check(self.problem)
        end = np.concatenate(self.ends)
        n_codes = (gorder != -99).sum(axis=1)
        last = gorder[np.arange(G), np.maximum(n_codes - 1, 0)]
        new = last >= 0  # the route ends at a new request's stop, else at a plan's stop
        r = groups[np.arange(G), np.where(new, last // 2, 0)]
        new_nodes = np.asarray(self.new_locs, np.int64)
        plan_nodes = np.array([s.loc for s in self.flat], np.int64)
        place = np.empty(G, np.int64)
        place[new] = new_nodes[2 * r[new] + last[new] % 2]
        if (~new).any():
            place[~new] = plan_nodes[self.off[gveh[~new]] + (-last[~new] - 1)]
        # seats free after the decision: the seats less who is aboard, who the plan will pick
        # up and the group's passengers (as the trainer counts them: requests held)
        owner = np.repeat(np.arange(self.nv), self.off[1:] - self.off[:-1])
        pending = np.bincount(owner, weights=np.where(self.p_drop, 0, self.p_pax),
                              minlength=self.nv)
        held = self.load + pending.astype(np.int64)
        gpax = np.where(groups >= 0, self.pax[np.maximum(groups, 0)], 0).sum(axis=1)
        seats = np.maximum(self.cap[gveh] - held[gveh] - gpax, 0)
        now = self.now
        after = np.power(vf.gamma, np.maximum(end - now, 0.0)) * vf.value(place, end, seats)
        # taking nothing: the vehicle's own plan ends where and when it ends now (an idle one:
        # where it is, now), its seats less who it holds
        busy = self.off[1:] > self.off[:-1]
        rest_place = np.asarray(self.src, np.int64).copy()
        if busy.any():
            rest_place[busy] = plan_nodes[self.off[1:][busy] - 1]
        rest_end = np.where(busy, np.maximum(self.old_end, now), now)
        before = np.power(vf.gamma, rest_end - now) * vf.value(
            rest_place, rest_end, np.maximum(self.cap - held, 0))
        return gcost - w * (after - before[gveh])

    def answer(self, chosen, groups, gveh, gorder) -> Allocation:
        """The allocation of the chosen candidates: pairs, and each vehicle's whole route."""
        problem = self.problem
        tids = problem.task_ids
        pairs, reqs, routes = [], [], {}
        multi = reordered = 0
        for g in sorted(chosen, key=lambda g: int(gveh[g])):
            j = int(gveh[g])
            aid = int(self.aids[j])
            rs = [int(r) for r in groups[g] if r >= 0]
            plan = self.plans[j]
            route = []
            for code in gorder[g].tolist():
                if code == -99:
                    break
                if code < 0:
                    s = plan[-code - 1]
                    route.append((s.kind, int(s.task_id)))
                else:
                    tid = int(tids[rs[code // 2]])
                    route.append(("pickup" if code % 2 == 0 else "dropoff", tid))
            routes[aid] = tuple(route)
            multi += len(rs) > 1
            mine = [code for code in gorder[g].tolist() if -99 < code < 0]
            reordered += mine != sorted(mine, reverse=True)
            for r in rs:
                tid = int(tids[r])
                pairs.append((aid, tid))
                reqs.append(Bid(round=0, agent_id=aid, task_id=tid,
                                    cost=float(problem.cost[self.vrows[j], r]), won=True))
        self.alloc.stats["multi"] += multi
        if self.alloc.reorder:
            self.alloc.stats["reordered"] += reordered
        return Allocation(pairs=tuple(pairs), rounds=1, requests=tuple(reqs), messages=0,
                          routes=routes)


__all__ = ["RtvAllocator"]
