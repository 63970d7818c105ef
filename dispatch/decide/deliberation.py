"""What a decision's deliberation changes (``[comms] latency``): its pairs checked again at
the hand-out, ``hops x latency`` seconds after the decision.

A decision plans each pair from the fleet as it was when the decision started. By the
hand-out the clock has run on towards every time limit (a request's pickup deadline, its
drop-off deadline, those of the riders a busy vehicle carries, a driver's shift end), a busy
vehicle has driven on (its first stops may be made, its plan's version is another), an idle
one on a repositioning move has moved, and a vehicle may have gone off duty, on a break or to
a charger. A pair handed out as it was planned then breaks the promises the decision checked:
its vehicle sets out ``delay`` seconds late, or its stops go where its plan no longer has
room.

So :func:`recheck` costs each pair again at the hand-out, as a decision at that instant costs
it (:meth:`dispatch.decide.pipeline.Pipeline.build`'s steps over that vehicle and that
request, closing nothing): the planner's drive from where the vehicle is, the insertion into
its plan as it is then (with meeting points, the cheapest candidate pair again), the
deadlines, the battery's reserve and the shift's end. A pair that no longer keeps every limit
is not handed out (its request stays open and the dispatcher decides again at once, where the
same costs rule the pair out: the decision does not come back for it); one that does is
handed out with the insertion planned at the hand-out. The decision's own costs and its row of
``decisions`` are as the allocator saw them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from dispatch.decide.nearest import within_limits

if TYPE_CHECKING:
    from dispatch.decide.pipeline import Pipeline


def limited(pipe: Pipeline, tasks) -> bool:
    """Whether a pair of ``tasks`` (``dispatch.plan.tasks.Task``) can go stale while its
    decision deliberates: vehicles with plans (insertions, drop-off limits, meeting points), a
    pickup deadline, a battery's reserve or a shift's end. Without any, a candidate vehicle of
    the decision that is still one at the hand-out serves the pair as planned."""
    return pipe.plans or pipe.energy_filter is not None or pipe.shifts is not None \
        or any(t.deadline < math.inf for t in tasks)


def candidate(pipe: Pipeline, v) -> bool:
    """Whether vehicle ``v`` is still one a decision would consider: idle, or with shared rides
    busy with a free seat in its plan (not failed, off duty, on a break or a charging visit)."""
    fleet, k = pipe.fleet, v._slot
    return bool(fleet.idle_mask[k] or (pipe.pooled and fleet.busy_mask[k] and fleet.room[k]))


def recheck(pipe: Pipeline, now: float, pairs, by_task: dict, holders: set) -> dict:
    """``{(vehicle id, task id): insertion or None}`` for each of ``pairs`` that keeps every
    limit when costed at ``now`` (see the module), with where its stops go now
    (:class:`dispatch.plan.insertion.Insertion`; None where the vehicle sets out on an empty
    plan, door to door). ``by_task``: task id -> task; ``holders``: the vehicles of ``pairs``
    that give their own task up for the new one (``[dispatch] reassign``: they are costed as
    if their plan were empty)."""
    pairs = list(pairs)
    if not pairs:
        return {}
    fleet = pipe.fleet
    if not limited(pipe, [by_task[t] for _, t in pairs]):
        return {pair: None for pair in pairs}
    slots = np.unique(np.array([fleet.by_id[a]._slot for a, _ in pairs], np.int64))
    row = {int(fleet.ids[k]): r for r, k in enumerate(slots.tolist())}
    tids = list(dict.fromkeys(t for _, t in pairs))
    col = {t: c for c, t in enumerate(tids)}
    requests = [by_task[t] for t in tids]
    agents = fleet.views(slots, now, ascending=True)
    views = tuple(t.view() for t in requests)
    drive, exact = pipe.costs(agents, views)
    pipe.costs.reachable(drive)  # (a nan is the planner's error)
    if exact is not None:  # lazy costs: the pairs' exact drives (the rest stays a bound)
        rows = np.array([row[a] for a, _ in pairs], np.int64)
        cols = np.array([col[t] for _, t in pairs], np.int64)
        drive = drive.copy()
        drive[rows, cols] = pipe.costs.exact(agents, views)(rows, cols)
    cost, inserts = within_limits(pipe, now, drive, slots, requests, agents=agents,
                                  holders=frozenset(holders))
    out = {}
    for a, t in pairs:
        ij = (row[a], col[t])
        if math.isfinite(cost[ij]):
            out[(a, t)] = inserts.get(ij) if inserts else None
    return out
