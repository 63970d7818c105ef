"""Checking an allocator's answer against its problem: every pair names a known agent and
task once, at a finite cost (:func:`validate`); a multi-request answer's routes hold the right
stops in a feasible order (:func:`route_stops`). Ids are looked up by binary search
(:func:`finders`), so a decision's answer is checked without a dict over all its agents.

The dispatcher checks every answer with these before the hand-out and passes it on as a
:class:`Checked`; :mod:`dispatch.checks.allocators` and plugin tests use them too.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from dispatch.api.problem import Allocation, AllocationProblem
from dispatch.errors import AllocationError
from dispatch.plan.stops import DROPOFF, PICKUP, PlannedStop


class Checked(NamedTuple):
    """An allocator's answer to ``problem`` as the dispatcher checked it: the ``allocation``,
    the allocator's ``seconds``, for a multi-request answer the checked ``routes`` (agent id
    -> (stop rows of :func:`route_stops`, planned arrival times); empty otherwise) and each
    pair's ``(row, column)`` in the problem, last (:func:`dispatch.decide.lazy.certify` reads
    an answer's last item as its pairs)."""

    problem: AllocationProblem
    allocation: Allocation
    seconds: float
    routes: dict
    index: list


def _ids(ids) -> str:
    ids = sorted(ids)
    return str(ids) if len(ids) <= 10 else f"[{', '.join(map(str, ids[:10]))}, ...] ({len(ids)})"


def validate(problem: AllocationProblem, allocation: Allocation,
             multi: bool = False) -> list[tuple[int, int]]:
    """Raise AllocationError unless every pair names a known agent and task, no agent or task
    appears twice, and no pair has infinite cost (and the counters are whole numbers >= 0).
    With ``multi`` (an allocator that sets ``multi_request``) an agent may appear in several
    pairs, and a pair of infinite single-request cost is allowed, when ``allocation.routes``
    gives the agent's stop order (checked by :func:`route_stops`).
    Returns each pair's ``(row, column)`` in the problem (its indices into ``cost``)."""
    if not isinstance(allocation, Allocation):
        raise AllocationError(f"allocator returned {type(allocation).__name__}, not an Allocation")
    for k, v in (("rounds", allocation.rounds), ("messages", allocation.messages),
                 ("hops", allocation.hops)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise AllocationError(f"Allocation.{k} must be an integer >= 0, got {v!r}")
    try:
        pairs = tuple(allocation.pairs)
    except TypeError:
        raise AllocationError(f"Allocation.pairs must be a sequence of (agent_id, task_id) "
                              f"pairs, got {type(allocation.pairs).__name__}") from None
    routes = allocation.routes or {}
    if routes and not multi:
        raise AllocationError("Allocation.routes is for allocators that set multi_request")
    if allocation.index and not routes:  # Allocation.centralized's (row, column) pairs
        index = _hinted(problem, pairs, allocation.index)
        if index is not None:
            return index
    agent_row, task_col = finders(problem)
    seen_agents: set[int] = set()
    seen_tasks: set[int] = set()
    hint = ("; pairs name agents and tasks by id, not by index (Allocation.centralized "
            "turns index pairs into id pairs)")
    n_agents, n_tasks = len(problem.agent_ids), len(problem.task_ids)
    index = []
    for pair in pairs:
        try:
            aid, tid = pair
            hash(aid), hash(tid)
        except (TypeError, ValueError):
            raise AllocationError(f"pair {pair!r} is not an (agent_id, task_id) pair") from None
        i, j = agent_row(aid), task_col(tid)
        if i < 0:
            by_index = isinstance(aid, (int, np.integer)) and 0 <= aid < n_agents
            raise AllocationError(f"unknown agent id {aid!r} (idle agents: "
                                  f"{_ids(problem.agent_ids.tolist())})"
                                  f"{hint if by_index else ''}")
        if j < 0:
            by_index = isinstance(tid, (int, np.integer)) and 0 <= tid < n_tasks
            raise AllocationError(f"unknown task id {tid!r} (open tasks: "
                                  f"{_ids(problem.task_ids.tolist())}){hint if by_index else ''}")
        if tid in seen_tasks:
            raise AllocationError(f"task {tid} is given to more than one agent")
        routed = multi and aid in routes
        if aid in seen_agents and not routed:
            raise AllocationError(f"agent {aid} is given more than one task"
                                  + (" without a route (Allocation.routes)" if multi else ""))
        if not routed and not math.isfinite(problem.cost[i, j]):
            raise AllocationError(f"agent {aid} cannot serve task {tid} (infinite cost)")
        seen_agents.add(aid)
        seen_tasks.add(tid)
        index.append((i, j))
    for aid in routes:
        if aid not in seen_agents:
            raise AllocationError(f"Allocation.routes names agent {aid!r}, which is given no "
                                  "task in pairs")
    return index


def _hinted(problem: AllocationProblem, pairs: tuple, hint) -> list[tuple[int, int]] | None:
    """What :func:`validate` returns for ``pairs`` where ``hint`` (the ``(row, column)`` of
    each pair, as :meth:`Allocation.centralized` was given them) holds: every hinted row and
    column in range and naming that pair's ids, no row or column twice, every pair of finite
    cost; None otherwise (the full check then says what is wrong). The same checks as the
    full one, by index instead of by id lookup."""
    if len(hint) != len(pairs):
        return None
    agent_ids, task_ids, cost = problem.agent_ids, problem.task_ids, problem.cost
    n, m = len(agent_ids), len(task_ids)
    rows: set[int] = set()
    cols: set[int] = set()
    index = []
    for pair, (i, j) in zip(pairs, hint):
        if type(i) is not int or type(j) is not int:  # (numpy integers, as the ids would)
            if not (isinstance(i, np.integer) and isinstance(j, np.integer)):
                return None
            i, j = int(i), int(j)
        if not (0 <= i < n and 0 <= j < m) or i in rows or j in cols:
            return None
        try:
            aid, tid = pair
        except (TypeError, ValueError):
            return None
        if type(aid) is not int or type(tid) is not int or aid != agent_ids[i] \
                or tid != task_ids[j] or not math.isfinite(cost[i, j]):
            return None
        rows.add(i)
        cols.add(j)
        index.append((i, j))
    return index


def route_stops(problem: AllocationProblem, aid: int, route, new: dict) -> list[PlannedStop]:
    """Agent ``aid``'s new stop order from ``Allocation.routes`` as
    :class:`dispatch.plan.stops.PlannedStop` rows, or AllocationError: it must hold every stop of
    the agent's plan (``problem.plans``) and the pickup and drop-off of each request of
    ``new`` (task id -> TaskView given to it), each once, every pickup before its drop-off."""
    plan = {(s.kind, s.task_id): s for s in problem.plans.get(aid, ())}
    try:
        keys = [(str(k), int(t)) for k, t in route]
    except (TypeError, ValueError):
        raise AllocationError(f"route of agent {aid} must be (kind, task_id) pairs, got "
                              f"{route!r:.200}") from None
    want = set(plan)
    for tid, t in new.items():
        want.add((PICKUP, tid))
        if t.dropoff is not None:
            want.add((DROPOFF, tid))
    if len(keys) != len(set(keys)) or set(keys) != want:
        missing, extra = sorted(want - set(keys)), sorted(set(keys) - want)
        raise AllocationError(f"route of agent {aid} must hold its plan's stops and its new "
                              f"requests' pickups and drop-offs once each (missing {missing}, "
                              f"unexpected {extra}, or repeated)")
    where = {k: n for n, k in enumerate(keys)}
    rows = []
    for kind, tid in keys:
        if kind == DROPOFF and where.get((PICKUP, tid), -1) > where[(kind, tid)]:
            raise AllocationError(f"route of agent {aid}: request {tid}'s drop-off comes "
                                  "before its pickup")
        s = plan.get((kind, tid))
        if s is not None:
            rows.append(PlannedStop(s.kind, tid, s.loc, s.passengers, s.latest, None,
                                    s.earliest))
            continue
        t = new[tid]
        point = t.dropoff is None
        if kind == PICKUP:
            rows.append(PlannedStop(PICKUP, tid, t.loc, 0 if point else t.passengers,
                                    t.deadline, point, t.earliest))
        else:
            rows.append(PlannedStop(DROPOFF, tid, t.dropoff, -t.passengers,
                                    t.dropoff_deadline, True))
    return rows


def finders(problem: AllocationProblem):
    """``(agent row finder, task column finder)`` of a problem (see :func:`_rows`); cheap to
    make (a dict of a few ids, else a sort only where the ids do not ascend), so callers that
    look up many ids make them once."""
    return _rows(problem.agent_ids, problem.agents.ascending), _rows(problem.task_ids)


def _rows(ids: np.ndarray, ascending: bool = False) -> Callable[[object], int]:
    """``find(id) -> row`` of ``id`` in ``ids`` (unique int64), or -1: a binary search, so a
    decision's answer is checked without a dict over all its agents. Ids match by value, as
    dict keys would (``True`` is 1, ``2.0`` is 2); anything that is not a whole number is
    unknown."""
    if ids.size <= 64:  # a few ids (a decision's tasks): a dict is cheapest
        index = {int(x): i for i, x in enumerate(ids.tolist())}

        def small(x) -> int:
            if isinstance(x, (float, np.floating)) and float(x).is_integer():
                x = int(x)
            if not isinstance(x, (int, np.integer)):
                return -1
            return index.get(int(x), -1)

        return small
    order = None if ascending or ids.size < 2 or bool((ids[1:] > ids[:-1]).all()) \
        else np.argsort(ids)
    keys = ids if order is None else ids[order]
    size = keys.size

    def find(x) -> int:
        if isinstance(x, (float, np.floating)) and float(x).is_integer():
            x = int(x)
        if not isinstance(x, (int, np.integer)) or not -2**63 <= x < 2**63:
            return -1
        k = int(keys.searchsorted(x))
        if k >= size or keys[k] != x:
            return -1
        return k if order is None else int(order[k])

    return find
