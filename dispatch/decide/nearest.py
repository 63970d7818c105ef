"""The exact vehicle cut: a one-request decision by a cost minimum costs the nearest vehicles.

An allocator that declares :attr:`dispatch.api.contracts.Allocator.nearest_cut` gives a
request of its own to the vehicle of least cost (the lowest id among equal costs), so only
the vehicles that might have that cost matter. Where the space promises a top speed
(:attr:`dispatch.api.space.Space.top_speed`, and slower ones with their slack) and the
planner that no cost beats it (:attr:`dispatch.api.contracts.Planner.drive_floor`), each
idle vehicle's straight line to the pickup over that speed (:func:`seconds`), times the
floor, is a lower bound of its drive there, and every cost a decision gives an idle vehicle
(the drive; with plans the drive plus the service and the direct trip; ``inf`` past a limit)
is at least its drive. :func:`visit` therefore takes the idle vehicles standing nearest
first, ring by ring of the fleet's index (:class:`dispatch.plan.idle_places.IdlePlaces`),
costs those whose bound is at most the least cost found so far, and stops once every vehicle
not yet reached is bound to cost more, or to arrive after the request's deadline. Vehicles it never costs cost more than the least cost
found (strictly: a vehicle bound to cost exactly as much is costed, as it may have a lower
id), so the decision over the vehicles it costed, in id order, takes the vehicle the whole
column takes, at the same cost. Idle vehicles that are driving (repositioning) and, with
shared rides, busy vehicles with a free seat are costed always (their costs have no such
bound).

The decision still counts every candidate vehicle (``n_idle`` of the ``decisions`` table), so
its rows are those of the whole column. A decision of fewer than :data:`MIN_CANDIDATES`
candidates costs the whole column (it takes fewer operations); :data:`FULL` (a test switch)
turns the cut off.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable

import numpy as np

from dispatch.decide.meeting import meeting_costs
from dispatch.decide.plan_costs import insertion_costs_of, ride_seconds
from dispatch.decide.planner_costs import deadlines, reject_late

#: True: every decision costs the whole column (tests compare the two)
FULL = False
#: The fewest candidate vehicles a decision is cut at. Below it the whole column costs fewer
#: operations than the search: with the road planner a vehicle's cost is one read of the
#: pickup's cached field (a gather over the column), while the search pays a fixed few dozen
#: array operations per decision (the rings, the bounds, a costing per batch, the parts
#: joined). Tests set it to 0.
MIN_CANDIDATES = 2048
#: Vehicles gathered from the rings before they are costed (unless the rings end or the next
#: ring is bound to be dearer first): fewer, larger costings.
BATCH = 4
#: :func:`search`'s answer where only the whole column can tell
WHOLE = object()
#: Relative slack taken off every bound: the rounding of a long path's summed edge times, and
#: of the top speed itself, can never lift a bound above the cost it bounds.
SLACK = 1e-9


def seconds(metres, speeds: tuple[tuple[float, float], ...]):
    """The least seconds in which a drive covers ``metres`` of straight line (a number or an
    array): the largest of ``(metres - slack) / speed`` over the promises ``speeds``
    (``(speed, slack)`` pairs: the top speed with no slack, and slower speeds with theirs: see
    :attr:`dispatch.api.space.Space.speed_slacks`), at least 0, less :data:`SLACK` of itself."""
    if isinstance(metres, float):
        return max(0.0, *((metres - slack) / speed for speed, slack in speeds)) * (1.0 - SLACK)
    out = np.zeros(np.shape(metres))
    for speed, slack in speeds:
        np.maximum(out, (metres - slack) / speed, out=out)
    return out * (1.0 - SLACK)


def cap(deadline: float, now: float) -> float:
    """Seconds of drive past which a vehicle reaches a pickup of ``deadline`` too late at
    ``now`` (the decision's limit is ``now + cost <= deadline + 1e-9``), with room for the
    rounding of that sum."""
    return deadline - now + 1e-9 + 1e-9 * (abs(deadline) + abs(now) + 1.0)


def visit(rings: Iterable[tuple[list[int], float]], bound: Callable[[np.ndarray], np.ndarray],
          cost: Callable[[np.ndarray], float], *, speeds: tuple[tuple[float, float], ...],
          best: float = math.inf, late: float = math.inf) -> float:
    """Cost the vehicles of ``rings`` (``(slots, beyond)`` ring by ring, as
    :meth:`dispatch.plan.idle_places.IdlePlaces.rings` yields them: ``beyond`` the metres
    every later vehicle stands at least away) while one may cost at most the least cost found;
    return that least cost (``inf``: none found).

    ``bound(slots)``: a lower bound of each vehicle's cost (seconds); ``cost(slots)``: costs
    those vehicles (ascending positions), returns their least cost; ``speeds``: the
    ``(speed, slack)`` promises that turn ``beyond`` into a bound (:func:`seconds`); ``best``:
    the least cost of vehicles costed before; ``late``: seconds of bound past which a
    vehicle's cost is ``inf`` anyway.

    Every vehicle whose bound is at most the returned cost (and at most ``late``) is costed,
    each once. Rings are gathered until :data:`BATCH` vehicles wait or the next ring is bound
    to cost more than the least cost found: the vehicles waiting are then costed together."""
    got: list[int] = []  # gathered, not yet bounded
    slots, bounds = np.zeros(0, np.int64), np.zeros(0)
    for ring, beyond in rings:
        got.extend(ring)
        edge = seconds(float(beyond), speeds)
        last = math.isinf(beyond)
        if edge <= min(best, late) and len(got) + slots.size < BATCH and not last:
            continue
        if got:
            new = np.array(got, np.int64)
            slots, bounds = np.concatenate((slots, new)), np.concatenate((bounds, bound(new)))
            got = []
        take = bounds <= min(best, late)
        if take.any():
            best = min(best, cost(np.sort(slots[take])))
            slots, bounds = slots[~take], bounds[~take]
        if edge > min(best, late) or last:
            break
    return best


class Parts:
    """The vehicles a cut decision costed, part by part (each part's positions ascending),
    and what each part's costing gave: the planner's drives, the decision's costs and where a
    busy vehicle's stops would go (the first part's only: later parts are idle vehicles)."""

    def __init__(self) -> None:
        self.slots: list[np.ndarray] = []
        self.drive: list[np.ndarray] = []
        self.cost: list[np.ndarray] = []
        self.inserts = None

    def add(self, slots: np.ndarray, drive: np.ndarray, cost: np.ndarray, inserts) -> float:
        """Keep one part; its least cost."""
        if inserts:
            if self.slots:
                raise ValueError("only the first part may hold busy vehicles' insertions")
            self.inserts = inserts
        self.slots.append(slots)
        self.drive.append(drive)
        self.cost.append(cost)
        return float(cost.min()) if cost.size else math.inf

    def joined(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, object]:
        """``(slots, drive, cost, inserts)`` of every part, in ascending positions (the
        insertions' rows renumbered to match; ``{}`` without any)."""
        if not self.slots:
            return np.zeros(0, np.int64), np.zeros((0, 1)), np.zeros((0, 1)), {}
        slots = np.concatenate(self.slots)
        order = np.argsort(slots, kind="stable")
        drive = np.concatenate(self.drive)[order]
        cost = np.concatenate(self.cost)[order]
        inserts = {}
        if self.inserts:
            rank = np.empty(order.size, np.int64)
            rank[order] = np.arange(order.size)
            inserts = self.inserts.moved(rank[:self.slots[0].size])
        return slots[order], drive, cost, inserts


def search(pipe, now: float):
    """The exact cut of the decision at ``now`` of pipeline ``pipe``
    (:class:`dispatch.decide.pipeline.Pipeline`, whose one open request it decides): ``(n,
    requests, views, slots, cost, inserts, t0)``, the number of candidate vehicles, the
    request and its view, the fleet positions of the vehicles it costed (ascending), their
    costs and where a busy one's stops would go, and when it began (``perf_counter``); None
    where the decision has nothing to decide (no candidate vehicle; or none serves the
    request in time, which is then closed as the whole column would close it); :data:`WHOLE`
    where the whole column is costed instead (fewer than :data:`MIN_CANDIDATES` candidates)
    or only it can tell (the request is not on a node; no vehicle found to serve it, and more
    than its deadline might say why)."""
    fleet, t0 = pipe.fleet, time.perf_counter()
    task = next(iter(pipe.book.open.values()))
    node, _, off = pipe.space.stands(task.loc)
    if off:
        return WHOLE
    mask = fleet.idle_mask | (fleet.busy_mask & fleet.room) if pipe.pooled else fleet.idle_mask
    n = int(np.count_nonzero(mask))
    if not n:
        return None
    if n < MIN_CANDIDATES:
        return WHOLE
    requests, views, parts = [task], (task.view(),), Parts()

    def cost(slots: np.ndarray) -> float:
        return parts.add(slots, *costed(pipe, now, slots, requests, views))

    places, best, speeds = fleet.places, math.inf, pipe.speeds
    first = np.array(sorted(places.moving), np.int64)
    if pipe.pooled:  # busy vehicles with a free seat: no bound, costed always
        first = np.union1d(first, np.flatnonzero(fleet.busy_mask & fleet.room))
    if first.size:
        best = cost(np.sort(first))
    xy = places.xy
    x, y = xy[node]

    def bound(slots: np.ndarray) -> np.ndarray:
        d = xy[fleet.node[slots]] - (x, y)
        return seconds(np.hypot(d[:, 0], d[:, 1]), speeds)

    best = visit(places.rings(x, y), bound, cost, speeds=speeds, best=best,
                 late=cap(task.deadline, now))
    slots, drive, cost_col, inserts = parts.joined()
    if math.isfinite(best):
        return n, requests, views, slots, cost_col, inserts, t0
    # none serves it in time: the whole column would reject it where only its deadline (or
    # the plans' limits) rule every vehicle out and some vehicle reaches it at all
    if pipe.energy_filter is not None or pipe.shifts is not None \
            or not (pipe.plans or task.deadline < math.inf):
        return WHOLE
    if not np.isfinite(drive).any():
        one = np.array(places.standing()[:1], np.int64)
        if not one.size or not np.isfinite(costed(pipe, now, one, requests, views)[0]).any():
            return WHOLE
    pipe.tally.cost_seconds += time.perf_counter() - t0
    reject_late(pipe.book, requests, cost_col, np.ones(1, bool), pipe.reject)
    return None


def costed(pipe, now: float, slots: np.ndarray, requests: list, views: tuple):
    """``(drive, cost, inserts)`` of the vehicles at fleet positions ``slots`` (ascending) for
    ``requests`` (``views``: theirs), as the pipeline ``pipe`` costs them
    (:meth:`dispatch.decide.pipeline.Pipeline.build`) but closing nothing: the planner's drives,
    the costs within every limit (with plans by the objective), where a busy vehicle's stops
    would go."""
    agents = pipe.fleet.views(slots, now, ascending=True)
    drive = pipe.costs(agents, views)[0]
    pipe.costs.reachable(drive)  # (a nan is the planner's error)
    return (drive, *within_limits(pipe, now, drive, slots, requests, agents=agents))


def within_limits(pipe, now: float, drive: np.ndarray, slots: np.ndarray, requests: list, *,
                  agents, holders: frozenset = frozenset()):
    """``(cost, inserts)``: the drives ``drive`` from the vehicles at fleet positions ``slots``
    (views ``agents``) to the pickups of ``requests`` costed as the pipeline ``pipe`` costs a
    decision's pairs: with plans each pair's cheapest feasible insertion by the objective (with
    meeting points the best of the request's boarding and alighting pairs), else the drive
    within the pickup deadline; then ``inf`` below a battery's reserve after the trip or past a
    shift's end. ``holders``: ids of vehicles driving to a pickup they may give up
    (``[dispatch] reassign``), whose plans count as empty; ``inserts`` maps a ``(row, col)``
    pair to where its stops go."""
    cost, inserts = drive, {}
    if pipe.plans and pipe.walks is not None:
        cost, inserts, _ = meeting_costs(pipe.walks, drive, slots, agents, requests, now,
                                         holders=holders, fleet=pipe.fleet,
                                         operator=pipe.operator, planner=pipe.planner,
                                         objective=pipe.objective)
    elif pipe.plans:
        cost, inserts = insertion_costs_of(drive, slots, requests, now, holders, fleet=pipe.fleet,
                                           operator=pipe.operator, planner=pipe.planner,
                                           objective=pipe.objective, table=pipe.table)
    else:
        limits = np.array([t.deadline for t in requests])
        if (limits < math.inf).any():
            cost = deadlines(drive, limits, now)
    if pipe.energy_filter is not None:
        cost = pipe.energy_filter(cost, drive, slots, requests, holders)
    if pipe.shifts is not None:
        cost = pipe.shifts.limit(cost, drive, now, slots, requests, inserts, plans=pipe.plans,
                                 ride=ride_seconds(pipe.planner, requests, congested_only=True),
                                 holders=holders)
    return cost, inserts
