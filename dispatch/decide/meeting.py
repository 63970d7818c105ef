"""Meeting points: a rider walks to a boarding point near the origin and from an alighting point
near the destination, and the decision chooses both with the stops.

A request with ``max_walk`` > 0 (``[tasks] max_walk`` or its trace row's) may board at any
network node within ``max_walk`` metres' walk of its origin and alight at any within
``max_walk`` of its destination (KaRRi's pickup and drop-off locations, MATSim's
``maxWalkDistance``). **Walking distance** is the road network's distance ignoring one-way
streets (the network's edges as an undirected graph, each edge as long as the longer of its
recorded length and the straight line between its ends; the networks shipped carry no
pedestrian network), by Dijkstra bounded at ``max_walk`` (:class:`Walks`). Of the nodes within
the radius the ``[tasks] meeting_points`` nearest (origin and destination included, at 0 m) are
its candidates, found once per request; the points left out by that bound are counted
(:attr:`Walks.cut`).

A candidate pair (boarding point ``b``, alighting point ``a``) is the request with its pickup
at ``b``, no earlier than the rider gets there (release + walk / ``walk_speed``; a booked
ride's release is its requested departure, so it boards no sooner even at its origin), by the same
latest pickup (release + ``max_wait``: the wait at the point counts), and its drop-off at
``a`` by the door-to-door latest arrival less the walk from ``a`` (release + direct drive +
``max_delay`` - walk / ``walk_speed``: the walk counts in the rider's total trip time and in
``max_delay``). :func:`meeting_costs` costs every (vehicle, candidate pair) by the compiled
insertion (:func:`dispatch.plan.insertion.insertion_costs`, an empty plan as a plan of no stops) and
keeps each (vehicle, request)'s cheapest: minimum over (board point, alight point, positions);
ties go to the pair listed first (the nearest points: door to door before any walk). The
choice rides with the insertion handed out (:attr:`dispatch.plan.insertion.Insertion.meeting`) and
the operator puts the request's stops there (:class:`Meeting`; the vehicle waits at a boarding
point for a rider still walking).

Allocators that hand out pairs (every allocator costing insertions) get the meeting points of
the pair's cheapest insertion. An allocator routing several requests (``rtv``; its decision's
``one_point``) plans with one pair of points per request: of the pairs whose boarding point the
rider reaches before any vehicle of the decision could drive there, counted from when the ride
may start (now; a booked ride's requested departure), the pair of the request's cheapest
insertion; the allocator sees the request's view at those points (:func:`view_at`: its pickup
no earlier than the rider gets there, :attr:`dispatch.api.problem.TaskView.earliest`, which its
routes wait for) and every vehicle's cost of that pair (see the how-to).

With ``max_walk`` = 0 everywhere nothing here runs (the decision has no candidate step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from scipy.sparse import csr_matrix

from dispatch.api.problem import TaskView
from dispatch.plan.insertion import insertion_costs

if TYPE_CHECKING:
    from dispatch.api.contracts import Planner
    from dispatch.plan.operator import Operator
    from dispatch.plan.tasks import Task
    from dispatch.plan.vehicles import Fleet
    from dispatch.space.roads import RoadNetwork


@dataclass(frozen=True, slots=True)
class Meeting:
    """Where a rider boards and alights (network nodes), the metres walked to the one and from
    the other, the boarding's earliest time (the rider's arrival there; ``-inf``: no walk) and
    the drop-off's latest (the door-to-door latest arrival less the walk from the alighting
    point)."""

    board: int
    alight: int
    walk_to_board: float
    walk_from_alight: float
    earliest: float
    latest_drop: float


class Candidates(NamedTuple):
    """A request's candidate points: boarding nodes and the metres walked to each, alighting
    nodes and the metres walked from each, nearest first (the origin / destination first)."""

    board: np.ndarray
    board_m: np.ndarray
    alight: np.ndarray
    alight_m: np.ndarray


class Walks:
    """Walking distances on a road network ignoring one-way streets, and each request's
    candidate points (at most ``k`` per end, the nearest), found once per request."""

    def __init__(self, network: RoadNetwork, k: int) -> None:
        self.k = int(k)
        length = network.length.tocoo()
        xy = network.xy
        # an edge is walked at least as far as the straight line between its ends (so the
        # straight line from the origin to a point never exceeds the walk recorded to it)
        chord = np.hypot(*(xy[length.row] - xy[length.col]).T)
        w = np.maximum(np.asarray(length.data, float), chord)
        w = np.where(w > 0, w, 1e-9)  # (a zero-length edge stays an edge)
        self.graph = csr_matrix((w, (length.row, length.col)), shape=length.shape)
        self.xy = xy
        self._of: dict[int, tuple[tuple, Candidates]] = {}
        #: what the bound left out: nodes within the radius beyond the ``k`` nearest, summed
        #: over requests and ends; and the candidate points found (requests x ends x points)
        self.cut = 0
        self.points = 0

    def near(self, node: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """``(nodes, metres)``: the ``k`` nodes nearest to ``node`` within ``radius`` metres'
        walk (``node`` first, at 0), nearest first (ties by node)."""
        if radius <= 0:
            return np.array([node], np.int64), np.zeros(1)
        # (imported here: scipy's graph module costs a run that never asks 0.07 s)
        from scipy.sparse.csgraph import dijkstra

        d = dijkstra(self.graph, directed=False, indices=int(node), limit=radius)
        nodes = np.flatnonzero(d <= radius)
        order = np.lexsort((nodes, d[nodes]))
        self.cut += max(0, nodes.size - self.k)
        nodes = nodes[order][: self.k]
        return nodes.astype(np.int64), d[nodes]

    def of(self, task: Task) -> Candidates:
        """``task``'s candidate points (kept per task while its origin and destination stay;
        a point task, a transfer or a rider without ``max_walk`` has its own two only)."""
        key = (task.loc, task.dropoff, task.transfers)
        got = self._of.get(task.id)
        if got is not None and got[0] == key:
            return got[1]
        walk = task.max_walk if task.dropoff is not None and not task.transfers else 0.0
        b, bm = self.near(int(task.loc), walk)
        drop = task.loc if task.dropoff is None else task.dropoff
        a, am = self.near(int(drop), walk)
        self.points += b.size + a.size
        c = Candidates(b, bm, a, am)
        self._of[task.id] = (key, c)
        return c

    def forget(self, task_ids) -> None:
        """Drop the candidates of requests no longer open."""
        for t in task_ids:
            self._of.pop(t, None)


class MeetingInserts:
    """Where a decision's stops go with meeting points (as
    :class:`dispatch.decide.plan_costs.Inserts`):
    for each feasible (row, col) the insertion of its cheapest candidate pair, with its
    :class:`Meeting`, for idle and busy vehicles alike."""

    def __init__(self, ins, q_of: dict, meet: list) -> None:
        self._ins, self._q, self._meet = ins, q_of, meet

    def __bool__(self) -> bool:
        return bool(self._q)

    def kept(self, servable: np.ndarray) -> MeetingInserts:
        """The same, for the columns of ``servable`` only (renumbered as they are kept)."""
        col = np.cumsum(servable) - 1
        q = {(r, int(col[c])): v for (r, c), v in self._q.items() if servable[c]}
        return MeetingInserts(self._ins, q, self._meet)

    def get(self, key, default=None):
        q = self._q.get((int(key[0]), int(key[1])))
        if q is None:
            return default
        return self._ins.of(q)._replace(meeting=self._meet[q])

    def __contains__(self, key) -> bool:
        return (int(key[0]), int(key[1])) in self._q

    def pairs(self):
        """``(rows, cols, insertions)`` as :meth:`dispatch.decide.plan_costs.Inserts.pairs`: every
        feasible
        pair kept and the insertion arrays of its cheapest candidate pair of points."""
        rows = np.fromiter((k[0] for k in self._q), np.int64, len(self._q))
        cols = np.fromiter((k[1] for k in self._q), np.int64, len(self._q))
        q = np.fromiter(self._q.values(), np.int64, len(self._q))
        return rows, cols, self._ins.take(q)


def _pairs(walks: Walks, tasks: list, svc: float, planner: Planner):
    """The candidate pairs of ``tasks`` as columns: each one's task index, boarding and
    alighting node, metres walked, earliest pickup, latest pickup and drop-off, passengers,
    service at pickup / drop-off and drive between the points."""
    col, b, a, wb, wa, spd = [], [], [], [], [], []
    for c, t in enumerate(tasks):
        cand = walks.of(t)
        nb, na = cand.board.size, cand.alight.size
        col.append(np.full(nb * na, c, np.int64))
        b.append(np.repeat(cand.board, na))
        wb.append(np.repeat(cand.board_m, na))
        a.append(np.tile(cand.alight, nb))
        wa.append(np.tile(cand.alight_m, nb))
        spd.append(np.full(nb * na, t.walk_speed))
    col, b, a = np.concatenate(col), np.concatenate(b), np.concatenate(a)
    wb, wa, spd = np.concatenate(wb), np.concatenate(wa), np.concatenate(spd)
    release = np.array([t.released_at for t in tasks])[col]
    point = np.array([t.dropoff is None for t in tasks])[col]
    lp = np.array([t.deadline for t in tasks])[col]
    ld = np.array([t.dropoff_deadline for t in tasks])[col] - wa / spd
    # boarding no sooner than the rider gets there, nor than a booked ride's requested departure
    e = np.where(wb > 0, release + wb / spd, np.array([t.earliest_pickup for t in tasks])[col])
    n = np.array([0 if t.dropoff is None else t.passengers for t in tasks], np.int64)[col]
    trips = np.flatnonzero(~point)
    pd = np.zeros(col.size)
    if trips.size:
        pd[trips] = planner.between(b[trips].tolist(), a[trips].tolist(), pairwise=True)
    svc_p = np.where(point, svc, 0.0)
    svc_d = np.where(point, 0.0, svc)
    return col, b, a, wb, wa, e, lp, ld, n, svc_p, svc_d, pd


def meeting_costs(walks: Walks, cost: np.ndarray, slots: np.ndarray, agents, tasks: list,
                  now: float, *, holders: set, fleet: Fleet, operator: Operator,
                  planner: Planner, objective: int, one_point: bool = False):
    """A decision's costs with meeting points (what
    :func:`dispatch.decide.plan_costs.insertion_costs_of`
    is door to door): for each vehicle (``slots``, views ``agents``) and request of ``tasks``
    the minimum over its candidate pairs of the cheapest feasible insertion (an empty plan: the
    pickup and drop-off in that order), ``inf`` where none keeps every limit. ``cost`` (the
    drives to the origins) gives the shape. Returns ``(costs by the objective, where the stops
    go, {})`` for every finite pair.

    ``one_point`` (allocators that route several requests, ``rtv``): one candidate pair per
    request for every vehicle, the one of its cheapest insertion among the pairs whose
    boarding point the rider reaches before any vehicle of the decision can, counted from when
    the ride may start (release + walk time <= max(now, release) + the shortest drive there;
    for a request released by now: no route of these vehicles waits for the walk, whatever
    its order; a booked ride's pickup waits for its requested departure anyway, and the
    allocator's routes wait for its ``earliest``); the third item maps each such request's
    index to its :class:`Meeting`."""
    n_v, m = cost.shape
    out = np.full((n_v, m), np.inf)
    if not n_v or not m:
        return out, MeetingInserts(None, {}, []), {}
    col, b, a, wb, wa, e, lp, ld, n_req, svc_p, svc_d, pd = _pairs(
        walks, tasks, operator.service_time, planner)
    ub, b_at = np.unique(b, return_inverse=True)
    cap = fleet.capacity[slots]
    planned = fleet.busy_mask[slots]
    if holders:  # [dispatch] reassign: a holder decides as if its plan were empty
        planned = planned & ~np.isin(fleet.ids[slots], list(holders))
    ready = np.where(planned, np.maximum(fleet.free_at[slots], now), now)
    drive = np.asarray(planner.between([ag.loc for ag in agents], ub.tolist()), float)
    first = drive[:, b_at]  # (vehicles, candidate pairs)
    # a boarding point the rider reaches after the pickup window closes is none: the rule
    # checks a stop's arrival against its latest time, and a vehicle on time there would
    # wait for the rider past it (release + walk / speed > release + max_wait)
    ok = (ready[:, None] + first <= lp + 1e-9) & (e <= lp + 1e-9)[None, :] \
        & (n_req <= cap[:, None])
    if one_point:  # boarding points the rider reaches first, from when the ride may start
        start = np.maximum(np.array([t.released_at for t in tasks])[col], now)
        ok &= (e <= start + first.min(axis=0) + 1e-9)[None, :]
    rows, vcols = np.nonzero(ok)
    if not rows.size:
        return out, MeetingInserts(None, {}, []), {}
    used = np.unique(rows)
    remap = np.full(n_v, -1, np.int64)
    remap[used] = np.arange(used.size)
    off, s_arr, s_svc, s_latest, s_occ, locs, s_e, load = [0], [], [], [], [], [], [], []
    vehicles = fleet.vehicles
    for r in used.tolist():
        v = vehicles[int(slots[r])]
        if planned[r]:
            times, svcs, latest, occ, where, earliest = v.plan.arrays(now)
            s_arr += times
            s_svc += svcs
            s_latest += latest
            s_occ += occ
            locs += where
            s_e += earliest
            load.append(v.load)
        else:
            load.append(0)
        off.append(len(locs))
    uc = np.unique(vcols)
    cmap = np.full(col.size, -1, np.int64)
    cmap[uc] = np.arange(uc.size)
    picks, drops = b[uc].tolist(), a[uc].tolist()
    if locs:
        to_p, from_p = planner.between(locs, picks), planner.between(picks, locs)
        to_d, from_d = planner.between(locs, drops), planner.between(drops, locs)
    else:
        to_p = to_d = np.zeros((0, uc.size))
        from_p = from_d = np.zeros((uc.size, 0))
    ins = insertion_costs(
        remap[rows], cmap[vcols], ready=ready[used], first_tt=first[rows, vcols], off=off,
        s_arr=s_arr, s_svc=s_svc, s_latest=s_latest, s_occ=s_occ, load=load, cap=cap[used],
        to_p=to_p, from_p=from_p, to_d=to_d, from_d=from_d, pd_tt=pd[uc], req_n=n_req[uc],
        req_lp=lp[uc], req_ld=ld[uc], req_svc_p=svc_p[uc], req_svc_d=svc_d[uc],
        objective=objective, s_earliest=s_e, req_earliest=e[uc])
    task_of = col[vcols]
    chosen: dict[int, Meeting] = {}
    if one_point:  # each request's pair: its cheapest insertion's (then the pair first listed)
        order = np.lexsort((vcols, ins.cost, task_of))
        head = np.ones(order.size, bool)
        head[1:] = task_of[order][1:] != task_of[order][:-1]
        pick = np.full(m, -1, np.int64)
        pick[task_of[order[head]]] = vcols[order[head]]
        best = np.flatnonzero((vcols == pick[task_of]) & np.isfinite(ins.cost))
        for k in np.unique(vcols[best]).tolist():
            chosen[int(col[k])] = _meeting(k, b, a, wb, wa, e, ld=ld)
    else:  # each (vehicle, request)'s cheapest candidate pair (then the pair first listed)
        key = rows * m + task_of
        order = np.lexsort((vcols, ins.cost, key))
        head = np.ones(order.size, bool)
        head[1:] = key[order][1:] != key[order][:-1]
        best = order[head]
        best = best[np.isfinite(ins.cost[best])]
    out[rows[best], task_of[best]] = ins.cost[best]
    meet: list = [None] * rows.size
    q_of = {}
    for q in best.tolist():
        meet[q] = _meeting(int(vcols[q]), b, a, wb, wa, e, ld=ld)
        q_of[(int(rows[q]), int(task_of[q]))] = q
    return out, MeetingInserts(ins, q_of, meet), chosen


def _meeting(k: int, b, a, wb, wa, e, *, ld) -> Meeting:
    return Meeting(int(b[k]), int(a[k]), float(wb[k]), float(wa[k]), float(e[k]), float(ld[k]))


def view_at(t: Task, m: Meeting) -> TaskView:
    """``t``'s view with its pickup and drop-off at the meeting points ``m``, the drop-off
    limit less the walk from it and the boarding no earlier than the rider gets there (what an
    allocator routing several requests plans with)."""
    return TaskView(t.id, t.kind, m.board, t.released_at, m.alight,  # type: ignore[arg-type]
                    t.deadline, t.passengers, m.latest_drop, m.earliest)


def walk_m(t: Task) -> tuple[float, float]:
    """Metres ``t``'s rider walked to board and from alighting (0, 0 door to door; nan for a
    request never handed out)."""
    if t.agent_id < 0:
        return math.nan, math.nan
    m = t.meeting
    return (0.0, 0.0) if m is None else (m.walk_to_board, m.walk_from_alight)
