"""The allocator checks (``dispatch check NAME`` of an allocator): run an allocator on random
problems and report what it gets wrong, before a simulation does.

    report = check_allocator(MyAllocator, some_param=3)   # keyword arguments: the constructor's
    assert report.ok, report                              # str(report): one line per check

Each check runs on every problem of :func:`dispatch.checks.random_problems.allocation_problems`
(no agents, no tasks, square and rectangular, rows and columns all ``inf``, ids that are not
indices, several communication components, message loss):

``construct``   the class builds with the given parameters;
``valid``       every answer is an :class:`~dispatch.api.problem.Allocation` the dispatcher accepts
                (known ids, no agent or task twice, no ``inf`` pair, whole counters);
``progress``    when some pair is finite, the answer assigns at least one;
``no-mutation`` the problem (its arrays, views and scalars) is the same after the call, even
                for a plugin that makes an array writable again or swaps an attribute;
``deterministic`` the same problem with the same seed, to a fresh instance, gives the same answer;
``rng``         the answer does not change when the global ``random`` / ``numpy.random`` state
                does (randomness only from ``problem.rng``).

An allocator that sets ``multi_request`` (batch pooling) is also run on the shared-ride
problems of :func:`dispatch.checks.random_problems.pooled_problems` (vehicles with plans, seats,
``problem.travel`` on :func:`dispatch.checks.common.small_network`); ``valid`` then also checks
each route of ``Allocation.routes`` as the dispatcher does (the agent's plan and new requests
once each, every pickup before its drop-off, the capacity and every limit on the problem's
travel times: :func:`dispatch.checks.random_problems.route_schedule`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dispatch.api.problem import Allocation, AllocationProblem
from dispatch.checks.common import (Report, constructed, describe_error, perturb_global_rng, replay,
                                    same_snapshot)
from dispatch.checks.random_problems import allocation_problems, pooled_problems, route_schedule
from dispatch.decide.answers import route_stops, validate
from dispatch.errors import AllocationError


def _snapshot(p: AllocationProblem) -> tuple:
    return (p.time, p.agents, p.tasks, p.cost.copy(), p.comm.copy(), p.max_rounds, p.loss,
            p.latency, p.cell_size, p.agent_pos.copy(), p.task_pos.copy(),
            p.cost.flags.writeable, p.comm.flags.writeable)


def _answer(a: Allocation) -> tuple:
    return (tuple(map(tuple, a.pairs)), a.rounds, a.requests, a.messages, a.hops,
            tuple(sorted((k, tuple(map(tuple, v))) for k, v in dict(a.routes).items())))


def _check_routes(problem: AllocationProblem, allocation: Allocation) -> None:
    """AllocationError unless each route of a multi-request answer holds its agent's plan and
    new requests once each, pickups first, within the capacity and every limit."""
    routes = allocation.routes
    if not routes:
        return
    by_task = {t.id: t for t in problem.tasks}
    new: dict = {}
    for aid, tid in allocation.pairs:
        new.setdefault(aid, {})[tid] = by_task[tid]
    for aid, route in routes.items():
        rows = route_stops(problem, aid, route, new.get(aid, {}))
        if rows:
            _, why = route_schedule(problem, aid, rows)
            if why:
                raise AllocationError(f"route of agent {aid} is infeasible: {why}")


def check_allocator(cls, *, seed: int = 0, **params: Any) -> Report:
    """Run every allocator check (see the module docstring) on ``cls(**params)``."""
    report, caps = constructed("allocator", cls, params)
    if not report.ok:
        return report
    problems = allocation_problems(seed)
    multi = caps.multi_request
    if multi:  # batch pooling: shared-ride problems, routes checked as the dispatcher does
        problems += pooled_problems(seed)
    invalid, stuck, mutated, differs, global_rng = [], [], [], [], []
    answers: dict[str, tuple] = {}
    called = 0  # problems whose allocate returned (the no-mutation check's)
    for label, build in problems:
        problem = build()
        before = _snapshot(problem)
        try:
            perturb_global_rng(1)
            allocation = cls(**params).allocate(problem)
        except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
            invalid.append(f"{label}: allocate raised {describe_error(e)}")
            continue
        called += 1
        if not same_snapshot(before, _snapshot(problem)):
            mutated.append(f"{label}: the problem changed during allocate")
        try:
            validate(problem, allocation, multi)
            _check_routes(problem, allocation)
        except AllocationError as e:
            invalid.append(f"{label}: {e}")
            continue
        if np.isfinite(before[3]).any() and not allocation.pairs:
            stuck.append(f"{label}: no pair assigned though some pair is finite")
        answers[label] = _answer(allocation)
    for label, build in problems:
        if label in answers:
            replay(label, lambda b=build: _answer(cls(**params).allocate(b())), answers[label],
                    differs, global_rng, show=lambda a: str(a[0]), given="problem and seed")
    n = len(problems)
    report.add("valid", invalid, f"{n} problems, every answer accepted")
    valid = len(answers)
    report.add("progress", stuck, "assigns a pair whenever one is finite", ran=valid, of=n,
               after="valid")
    report.add("no-mutation", mutated, "no problem changed", ran=called, of=n,
               after="allocate (it raised)")
    report.add("deterministic", differs, "same problem and seed, same answer", ran=valid, of=n,
               after="valid")
    report.add("rng", global_rng, "answers do not depend on the global random state", ran=valid,
               of=n, after="valid")
    return report
