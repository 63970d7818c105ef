"""Lazy exact costs: decide on lower bounds, compute exact costs only where the answer needs them.

With ``[dispatch] lazy_costs = true``, a planner that computes lower bounds
(:attr:`~dispatch.api.contracts.Planner.lower_bounds`) and an allocator that returns a
maximum-cardinality, minimum-total-cost assignment
(:attr:`~dispatch.api.contracts.Allocator.minimizes_total_cost`), the dispatcher does not ask for
the
exact cost matrix. It asks for a matrix ``L`` of lower bounds (exact where the planner already
knows the cost) and certifies the answer:

1. Solve the assignment on ``L``. If every chosen pair is exact, stop.
2. Otherwise compute the exact cost of the chosen pairs that were bounds, put them in ``L``
   (``inf`` where the vehicle would arrive after the request's deadline) and go to 1.

Why the answer is then optimal for the exact matrix ``C``: ``L <= C`` entry by entry, and ``L``
is finite wherever ``C`` is (a pair late or unreachable by its bound is so exactly), so every
assignment feasible in ``C`` is feasible in ``L``. The last answer ``A`` has the largest number
of pairs feasible in ``L``, hence at least as many as any assignment feasible in ``C``, and its
pairs are exact, hence feasible in ``C``: it has the largest cardinality there too. For any
assignment ``B`` of that cardinality feasible in ``C``: ``C(A) = L(A) <= L(B) <= C(B)``. Each
round makes at least one more entry exact, so the loop ends.

The deadline rules stay exact as well: a bound that misses the deadline misses it exactly; a
task whose only pairs that make it by their bounds are not exact yet gets its pairs computed
in increasing order of bound until one makes it (:func:`resolve_open`), so a task no idle
vehicle can reach in time is found (and rejected or left out) exactly as with exact costs.
Ties between assignments of equal total cost may break differently than on the exact matrix.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Slack of the deadline test (the exact dispatcher's: ``now + cost <= deadline + 1e-9``).
DEADLINE_SLACK = 1e-9

#: ``compute(rows, cols) -> exact costs`` (seconds) of the pairs ``(rows[k], cols[k])``.
Compute = Callable[[np.ndarray, np.ndarray], np.ndarray]


def in_time(values: np.ndarray, now: float, deadlines: np.ndarray) -> np.ndarray:
    """Where a vehicle of these travel seconds makes the deadline (the dispatcher's rule)."""
    return now + values <= deadlines + DEADLINE_SLACK


def settle(cost: np.ndarray, exact: np.ndarray, rows, cols, compute: Compute, now: float,
           *, deadlines: np.ndarray) -> int:
    """Replace ``cost[rows, cols]`` by the exact costs (``inf`` where late) and mark them exact,
    in place. Returns how many pairs were computed."""
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    if not rows.size:
        return 0
    values = np.asarray(compute(rows, cols), dtype=float)
    cost[rows, cols] = np.where(in_time(values, now, deadlines[cols]), values, np.inf)
    exact[rows, cols] = True
    return int(rows.size)


def resolve_open(cost: np.ndarray, exact: np.ndarray, compute: Compute, now: float,
                 deadlines: np.ndarray) -> int:
    """Make each column's feasibility exact, in place: afterwards a column has a finite entry
    iff some pair's exact cost makes its deadline. ``cost`` holds lower bounds with the
    deadline already applied (``inf`` where late by the bound). A column with a deadline, finite
    entries and none of them exact gets its pairs computed one at a time, in increasing order of
    bound, until one makes the deadline or none is left (without a deadline a finite bound means
    a finite cost, which makes it). Returns how many pairs were computed."""
    finite = np.isfinite(cost)
    doubt = np.flatnonzero(finite.any(axis=0) & ~(finite & exact).any(axis=0)
                           & np.isfinite(deadlines))
    computed = 0
    for j in doubt.tolist():
        column = cost[:, j]
        for i in np.argsort(column, kind="stable").tolist():
            if not np.isfinite(cost[i, j]):
                break  # the rest are inf (late or unreachable): exact
            computed += settle(cost, exact, [i], [j], compute, now, deadlines=deadlines)
            if np.isfinite(cost[i, j]):
                break
    return computed


def certify(ask: Callable[[np.ndarray], tuple], cost: np.ndarray, exact: np.ndarray,
            compute: Compute, now: float, deadlines: np.ndarray) -> tuple[tuple, int, int]:
    """Run the certificate loop (see the module): ``ask(cost)`` solves the assignment on a copy
    of ``cost`` and returns a tuple whose last item is the chosen ``(row, column)`` pairs.
    Returns ``(the last answer of ask, rounds, pairs computed)``; ``cost`` and ``exact`` are
    updated in place."""
    rounds = computed = 0
    while True:
        rounds += 1
        answer = ask(cost)
        todo = [(i, j) for i, j in answer[-1] if not exact[i, j]]
        if not todo:
            return answer, rounds, computed
        rows, cols = zip(*todo)
        computed += settle(cost, exact, rows, cols, compute, now, deadlines=deadlines)
