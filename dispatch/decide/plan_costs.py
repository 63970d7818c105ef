"""A decision's costs when vehicles have plans (shared rides, drop-off limits, the
added-time objective): where a new request's stops go in a vehicle's plan and what that adds.

* :func:`insertion_costs_of`: the cost matrix with plans, from the drives to each pickup; an
  empty plan takes the pickup and drop-off in that order, a busy vehicle's plan the cheapest
  feasible insertion (:func:`dispatch.plan.insertion.insertion_costs`); :class:`Inserts` keeps where
  the stops go for the pairs handed out;
* :class:`Plans`: the agents' stop lists as an allocation problem shows them
  (:attr:`AllocationProblem.plans`), read from the vehicles when asked;
* :class:`PlanTable`: the fleet's plans kept as arrays between decisions, gathered for the
  busy vehicles of a decision without a Python loop over their stops.

The dispatcher (:mod:`dispatch.decide.dispatcher`) decides; this is the plan machinery it asks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from dispatch.api.contracts import Planner
from dispatch.api.problem import StopView
from dispatch.plan.insertion import Insertion, candidate_pairs, gather_rows, insertion_costs
from dispatch.plan.stops import PICKUP_TIME
from dispatch.plan.vehicle_plan import starts_now

if TYPE_CHECKING:
    from dispatch.plan.operator import Operator
    from dispatch.plan.vehicles import Fleet


class Inserts:
    """Where a decision's stops go (:class:`dispatch.plan.insertion.Insertion`), for its busy
    vehicles' feasible pairs, by ``(row, col)``: kept as the arrays the insertion computed and
    looked up only for the pairs handed out (a pooled batch has thousands of feasible pairs
    and hands out a few dozen)."""

    def __init__(self, ins, rows: np.ndarray, cols: np.ndarray, m: int) -> None:
        ok = np.isfinite(ins.cost)
        self._ins, self._q = ins, np.flatnonzero(ok)
        self._rows, self._cols, self._m = rows[ok], cols[ok], m
        self._keys = None

    def __bool__(self) -> bool:
        return bool(self._q.size)

    def kept(self, servable: np.ndarray) -> Inserts:
        """The same, for the columns of ``servable`` only (renumbered as they are kept)."""
        col = np.cumsum(servable) - 1
        keep = servable[self._cols]
        out = object.__new__(Inserts)
        out._ins, out._q = self._ins, self._q[keep]
        out._rows, out._cols = self._rows[keep], col[self._cols[keep]]
        out._m, out._keys = int(servable.sum()), None
        return out

    def moved(self, rows: np.ndarray) -> Inserts:
        """The same, with row ``r`` renumbered ``rows[r]`` (a decision whose vehicles were
        costed in parts: :mod:`dispatch.decide.nearest`)."""
        out = object.__new__(Inserts)
        out._ins, out._q, out._cols, out._m = self._ins, self._q, self._cols, self._m
        out._rows, out._keys = np.asarray(rows)[self._rows], None
        return out

    def pairs(self):
        """``(rows, cols, insertions)``: every feasible pair kept and its insertion's arrays
        (:class:`dispatch.plan.insertion.Insertions`, aligned with the pairs)."""
        ins, q = self._ins, self._q
        return self._rows, self._cols, ins.take(q)

    def _find(self, key) -> int:
        if self._keys is None:
            keys = self._rows.astype(np.int64) * self._m + self._cols
            order = np.argsort(keys, kind="stable")
            self._keys, self._order = keys[order], order
        r, c = key
        k = int(r) * self._m + int(c)
        i = int(np.searchsorted(self._keys, k))
        return int(self._order[i]) if i < self._keys.size and self._keys[i] == k else -1

    def get(self, key, default=None) -> Insertion | None:
        i = self._find(key)
        return default if i < 0 else self._ins.of(int(self._q[i]))

    def __contains__(self, key) -> bool:
        return self._find(key) >= 0


class Plans(Mapping):
    """:attr:`AllocationProblem.plans`: the stop lists of a decision's agents that have one,
    read from the vehicles when asked (within the decision: nothing moves meanwhile)."""

    def __init__(self, fleet: Fleet, slots: np.ndarray, now: float) -> None:
        self._fleet, self._slots, self._now = fleet, slots, now
        self._by_id: dict | None = None  # agent id -> vehicle, of those with stops (on use)
        self._cache: dict[int, tuple] = {}

    @property
    def _ids(self) -> dict:
        if self._by_id is None:
            vs = self._fleet.vehicles
            self._by_id = {v.id: v for v in (vs[k] for k in self._slots.tolist())
                           if v.plan.kept()}
        return self._by_id

    def __getitem__(self, agent_id: int) -> tuple[StopView, ...]:
        got = self._cache.get(agent_id)
        if got is None:
            v = self._ids[agent_id]
            times = v.plan.arrays(self._now)[0]
            got = self._cache[agent_id] = tuple(
                StopView(s.kind, -1 if s.task is None else s.task.id, s.loc, s.passengers,
                         s.latest, s.occupancy, t, s.earliest)
                for s, t in zip(v.plan, times))
        return got

    def __iter__(self):
        return iter(self._ids)

    def __len__(self) -> int:
        return len(self._ids)


class PlanTable:
    """The fleet's plans as the compiled insertion reads them: for each vehicle (by fleet
    position) a row of each field of :meth:`dispatch.plan.vehicle_plan.Plan.arrays` (planned
    arrival, service, latest, occupancy, earliest; the locations as node ids where every stop
    lies on a node, else kept as the lists), so that a decision gathers the plans of its busy
    vehicles with a few numpy operations (:meth:`gather`) instead of concatenating lists
    vehicle by vehicle.

    A row is written when the vehicle's plan arrays are not the ones it was written from
    (``Plan.arrays`` answers the same tuple until the plan, the drive along it or, for a
    standing vehicle, the clock changes): a decision rewrites the few plans that changed
    since the last one. The values are those lists' (the same doubles, in the same order)."""

    def __init__(self, n: int, width: int = 8) -> None:
        self._src: list = [None] * n  # the Plan.arrays tuple each row was written from
        #: the vehicle's ``plan_version`` when its row was last checked (-1: never)
        self._checked = np.full(n, -1, dtype=np.int64)
        self.length = np.zeros(n, dtype=np.int64)
        #: every stop written so far lies on a node (an integer): ``nodes`` holds them
        self.on_nodes = True
        self._fields = self._alloc(n, width, ())

    def _alloc(self, n: int, width: int, old: tuple) -> tuple:
        """The fields (arrival, service, latest, occupancy, earliest, node), ``width`` stops
        wide, holding the ``old`` fields' values."""
        self.width = width
        fields = (np.zeros((n, width)), np.zeros((n, width)), np.zeros((n, width)),
                  np.zeros((n, width), dtype=np.int64), np.zeros((n, width)),
                  np.zeros((n, width), dtype=np.int64))
        for new, was in zip(fields, old):
            new[:, :was.shape[1]] = was
        return fields

    def _write(self, k: int, arrays) -> None:
        times, svcs, latest, occ, where, earliest = arrays
        n = len(times)
        if n > self.width:
            self._fields = self._alloc(len(self._src), max(n, 2 * self.width), self._fields)
        arr, svc, lat, oc, ear, node = self._fields
        arr[k, :n] = times
        svc[k, :n] = svcs
        lat[k, :n] = latest
        oc[k, :n] = occ
        ear[k, :n] = earliest
        if self.on_nodes:
            if all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) for x in where):
                node[k, :n] = where
            else:
                self.on_nodes = False
        self.length[k] = n
        self._src[k] = arrays

    def gather(self, fleet: Fleet, slots: np.ndarray, now: float):
        """``(off, arrival, service, latest, occupancy, locations, earliest, load)`` of the
        vehicles at fleet positions ``slots`` (each vehicle's ``plan.arrays(now)``), flat as
        :func:`dispatch.plan.insertion.insertion_costs` takes them: vehicle ``i``'s stops are
        ``off[i]:off[i + 1]``; the locations an int64 array of nodes where every stop is on a
        node, else a list; ``load`` on board now, per vehicle.

        A vehicle's plan is asked only where its arrays may differ from its row's: a
        ``plan_version`` since the row was checked, or its times starting at ``now``
        (:func:`dispatch.plan.vehicle_plan.starts_now`, the rule the plan's own cache is keyed
        by); the others' rows are read as they are."""
        src, write, checked = self._src, self._write, self._checked
        idx = np.asarray(slots, dtype=np.int64)
        version = fleet.plan_version.take(idx)
        ask = (checked.take(idx) != version) \
            | starts_now(fleet.heading_none.take(idx), fleet.waiting.take(idx),
                         fleet.free_at.take(idx), now)
        if ask.any():
            vehicles = fleet.vehicles
            for k in idx[ask].tolist():
                got = vehicles[k].plan.arrays(now)
                if got is not src[k]:
                    write(k, got)
            checked[idx[ask]] = version[ask]
        # the rows' stops, flat (compiled: one loop, no index arrays built per decision)
        off, arr, svc, lat, oc, ear, node = gather_rows(idx, self.length, self._fields)
        if self.on_nodes:
            locs = node
        else:
            locs = [x for k in idx.tolist() for x in src[k][4]]
        return off, arr, svc, lat, oc, locs, ear, fleet.load.take(idx)


def ride_seconds(planner: Planner, tasks: list, congested_only: bool = False
                 ) -> np.ndarray | None:
    """Each request's drive from its pickup to its drop-off (0 for a point task): its
    free-flow ``direct_time``, but the drive at this hour on a congested planner
    (:mod:`dispatch.space.congestion`) and, for a rider transferred after a breakdown, the
    drive from where the rider waits now (``direct_time`` stays the original trip's: the
    ``tasks`` row reports it). ``congested_only``: None where every value is the
    ``direct_time`` (no congestion, no transfer)."""
    congested = planner.free_flow is not planner
    trips = [k for k, t in enumerate(tasks)
             if t.dropoff is not None and (congested or t.transfers)]
    if congested_only and not trips:
        return None
    pd = np.array([0.0 if t.dropoff is None else t.direct_time for t in tasks])
    if trips:
        pd[trips] = planner.between([tasks[k].loc for k in trips],
                                    [tasks[k].dropoff for k in trips], pairwise=True)
    return pd


def insertion_costs_of(cost: np.ndarray, slots: np.ndarray, tasks: list, now: float,
                       holders: set, *, fleet: Fleet, operator: Operator, planner: Planner,
                       objective: int, table: PlanTable) -> tuple[np.ndarray, Inserts | dict]:
    """A decision's costs with plans (see :mod:`dispatch.plan.stops`): for a vehicle with an
    empty plan (idle, or about to give its task up) the request's pickup and drop-off in
    that order; for a busy one the cheapest feasible insertion into its plan; ``inf``
    where none keeps the capacity and every limit. ``cost`` holds the drives from each
    vehicle to each pickup. Returns ``(costs by the objective, {(row, col): where the
    stops go})`` for the busy vehicles' finite pairs. ``table``: the run's
    :class:`PlanTable` (the busy vehicles' plans are read through it)."""
    svc = operator.service_time
    m = len(tasks)
    slots = np.asarray(slots, dtype=np.int64)
    lp = np.array([t.deadline for t in tasks])
    ld = np.array([t.dropoff_deadline for t in tasks])
    n_req = np.array([0 if t.dropoff is None else t.passengers for t in tasks], np.int64)
    # a booked request's pickup opens at its requested departure (dispatch.decide.prebook)
    ep = np.array([t.earliest_pickup for t in tasks])
    point = np.array([t.dropoff is None for t in tasks])
    pd = ride_seconds(planner, tasks)
    svc_p = np.where(point, svc, 0.0)
    svc_d = np.where(point, 0.0, svc)
    planned = fleet.busy_mask.take(slots)  # (a busy vehicle has stops or is serving)
    if holders:  # [dispatch] reassign: a holder decides as if its plan were empty
        planned = planned & ~np.isin(fleet.ids[slots], list(holders))
    out = np.full(cost.shape, np.inf)
    # the empty plans' costs into ``out``, the busy vehicles' candidate pairs (by row, then
    # column), compiled: one loop instead of some seventy numpy calls per decision
    rows, cols, row_of, used, ready, seats, ucols, pcol, first_tt = candidate_pairs(
        cost, now, slots, planned, cap=fleet.capacity, free_at=fleet.free_at, lp=lp, ld=ld,
        n_req=n_req, ep=ep, svc_p=svc_p, svc_d=svc_d, pd=pd,
        pickup_time=objective == PICKUP_TIME, out=out)
    if not rows.size:
        return out, {}
    off, s_arr, s_svc, s_latest, s_occ, locs, s_e, load = table.gather(
        fleet, slots.take(used), now)
    picks = [tasks[c].loc for c in ucols.tolist()]
    drops = [tasks[c].loc if tasks[c].dropoff is None else tasks[c].dropoff
             for c in ucols.tolist()]
    between = planner.between
    g = off[-1]
    if g:
        to_p, from_p = between(locs, picks), between(picks, locs)
        to_d, from_d = between(locs, drops), between(drops, locs)
    else:
        to_p = to_d = np.zeros((0, ucols.size))
        from_p = from_d = np.zeros((ucols.size, 0))
    if ucols.size < m:  # the requests of the pairs only
        pd, n_req, lp, ld = pd[ucols], n_req[ucols], lp[ucols], ld[ucols]
        svc_p, svc_d, ep = svc_p[ucols], svc_d[ucols], ep[ucols]
    ins = insertion_costs(
        row_of, pcol, ready=ready, first_tt=first_tt, off=off, s_arr=s_arr, s_svc=s_svc,
        s_latest=s_latest, s_occ=s_occ, load=load, cap=seats, to_p=to_p, from_p=from_p,
        to_d=to_d, from_d=from_d, pd_tt=pd, req_n=n_req, req_lp=lp, req_ld=ld,
        req_svc_p=svc_p, req_svc_d=svc_d, objective=objective, s_earliest=s_e,
        req_earliest=ep)
    out[rows, cols] = ins.cost
    return out, Inserts(ins, rows, cols, m)


class PlanEnds:
    """:attr:`AllocationProblem.post` of a decision with plans: for each (vehicle, request)
    pair, where and when the vehicle's plan ends once the request is inserted the cheapest way,
    and its free seats (:class:`dispatch.api.value.PostDecision`), computed when an allocator
    asks (a value of the post-decision state, :mod:`dispatch.api.value`), never otherwise.

    An empty plan ends at the request's drop-off, the pair's cost plus (pickup-time objective)
    the service and the direct drive after now; a busy vehicle's at the drop-off when it is
    inserted after the plan's last stop, else at the last stop, later by the insertion's
    shift (an upper bound where a stop's wait absorbs some of it). Free seats: the seats less
    the most on board along the plan and the request's passengers (none below 0). Each
    vehicle taking nothing (``rest``): a busy one's plan ends at its last stop as planned, its
    seats less the most on board; an idle one stays where it is, now."""

    def __init__(self, now: float, slots: np.ndarray, tasks: list, inserts, table: PlanTable, *,
                 fleet: Fleet, objective: int, service: float) -> None:
        self.now, self.slots, self.inserts = now, slots, inserts
        self.objective, self.service = objective, service
        # the requests' drop-offs, riders and direct drives (arrays: nothing of the kernel's
        # tasks is kept)
        self.drops = np.array([t.loc if t.dropoff is None else t.dropoff for t in tasks],
                              np.int64)
        self.n_req = np.array([0 if t.dropoff is None else t.passengers for t in tasks],
                              np.int64)
        self.trip = np.array([0.0 if t.dropoff is None else t.direct_time for t in tasks])
        # the busy vehicles' plans as the decision's insertion read them (the table's rows)
        self.length = table.length[slots].copy()
        last = np.maximum(self.length - 1, 0)
        arr, svc, _, occ, _, node = table._fields
        self.last_node = node[slots, last].copy()
        self.last_end = arr[slots, last] + svc[slots, last]
        width = occ.shape[1]
        used = np.arange(width)[None, :] < self.length[:, None]
        # (only a busy vehicle's row is current: the decision gathered it)
        most = np.where(used, occ[slots], 0).max(axis=1, initial=0)
        self.busy = fleet.busy_mask[slots] & (self.length > 0)
        self.most = np.maximum(np.where(fleet.busy_mask[slots], most, 0), fleet.load[slots])
        self.cap = fleet.capacity[slots].astype(np.int64)

    def __call__(self, problem):
        from dispatch.api.value import PostDecision, nodes_of

        cost = np.asarray(problem.cost, dtype=float)
        n, m = cost.shape
        drops, n_req = self.drops, self.n_req
        place = np.broadcast_to(drops[None, :], (n, m)).copy()
        c = np.where(np.isfinite(cost), cost, 0.0)
        after = c
        if self.objective == PICKUP_TIME:  # the cost is the drive to the pickup: add the trip
            after = c + (self.trip + self.service)[None, :]
        after = after.copy()
        seats = np.maximum(self.cap[:, None] - self.most[:, None] - n_req[None, :], 0)
        if self.inserts:
            rows, cols, ins = self.inserts.pairs()
            inside = ins.j < self.length[rows]  # the drop-off before the plan's last stop
            r, k = rows[inside], cols[inside]
            place[r, k] = self.last_node[r]
            after[r, k] = self.last_end[r] + ins.shift2[inside] - self.now
            out = ~inside
            after[rows[out], cols[out]] = ins.dropoff_at[out] + self.service - self.now
        # taking nothing: a busy vehicle's plan ends as it is, an idle one stays, now
        here = nodes_of(problem)[0]
        rest = (np.where(self.busy, self.last_node, here),
                np.where(self.busy, np.maximum(self.last_end - self.now, 0.0), 0.0),
                np.maximum(self.cap - self.most, 0))
        return PostDecision(place, np.maximum(after, 0.0), seats, rest)
