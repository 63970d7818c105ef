"""Hungarian allocator: the optimal centralized assignment (the paper's reference method).

Promise: among all assignments that pair each agent with at most one task and each task with at
most one agent, using only pairs of finite cost, the answer serves as many tasks as possible
(maximum cardinality) and, among those, has the smallest total cost. Pairs of cost ``inf`` are
never chosen. Works for any ``N x M`` (rectangular either way, or empty).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem


class HungarianAllocator(Allocator):
    """Centralized optimal assignment via :func:`scipy.optimize.linear_sum_assignment`.

    Maximum number of assigned tasks first, then minimum total cost among those; never an
    ``inf`` pair. Deterministic: it draws nothing from ``problem.rng``.
    """

    name = "hungarian"
    decentralized = False
    minimizes_total_cost = True  # maximum cardinality, then minimum total cost; no rng
    one_by_minimum = True  # one task: the first cheapest finite row (see optimal_pairs)
    nearest_cut = True  # ... found among the vehicles a lower bound cannot rule out

    def __init__(self, value: str | None = None, value_weight: float | None = None,
                 value_reward: float | None = None) -> None:
        """``value``: a learned value of where vehicles end up (a file of ``dispatch train
        value``, see :mod:`learning.value`): each pair's cost becomes its cost less the
        discounted value of the vehicle's zone and time after the trip, plus its value now
        (``value_weight`` seconds per unit of value; default: the file's). Still maximum
        cardinality, then the minimum of these costs; the cost recorded for a pair stays
        its travel time. With plans (shared rides, the ``added_time`` objective) the value is
        of where each pair's insertion leaves the vehicle's plan ending, and its free seats
        (:func:`dispatch.api.value.value_costs`). ``value_reward``: seconds one served request
        is worth; with it (and a value) the answer is no longer of maximum cardinality but of
        the greatest total worth, ``value_reward`` less each pair's adjusted cost, and a pair
        worth nothing is left for a later batch (:func:`gated_pairs`)."""
        self.value = None
        if value is not None or value_reward is not None:
            from learning.value import ValueOption

            self.value = ValueOption.of(value, value_weight, value_reward)
            self.value_function = self.value.value
            self.minimizes_total_cost = False  # of the adjusted costs, not problem.cost
            self.one_by_minimum = self.nearest_cut = False

    def allocate(self, problem: AllocationProblem) -> Allocation:
        if self.value is None:
            return Allocation.centralized(problem, optimal_pairs(problem.cost))
        cost = self.value.costs(problem)
        if self.value.reward is not None:
            return Allocation.centralized(problem, gated_pairs(cost - self.value.reward))
        return Allocation.centralized(problem, optimal_pairs(cost))


def gated_pairs(score: np.ndarray) -> list[tuple[int, int]]:
    """Index pairs ``(agent, task)`` of an assignment of the least total ``score`` among pairs
    of negative score: a maximum-weight matching of the worths ``-score`` (not a
    maximum-cardinality one), an agent or task left out wherever no negative pair is worth its
    place; ``inf`` and non-negative pairs are never chosen. (Every pair that cannot gain is set
    to 0, the worth of leaving both out, and the full assignment of that matrix is solved: its
    pairs at 0 are the ones left out.)"""
    score = np.asarray(score, dtype=float)
    if score.ndim != 2 or not score.size:
        return []
    gain = np.where(np.isfinite(score) & (score < 0), score, 0.0)
    rows = np.flatnonzero((gain < 0).any(axis=1))
    cols = np.flatnonzero((gain < 0).any(axis=0))
    if not len(rows):
        return []
    sub = gain[np.ix_(rows, cols)]
    r, c = linear_sum_assignment(sub)
    keep = sub[r, c] < 0
    return [(int(rows[a]), int(cols[t])) for a, t in zip(r[keep], c[keep])]


def optimal_pairs(cost: np.ndarray) -> list[tuple[int, int]]:
    """Index pairs ``(agent, task)`` of a maximum-cardinality, then minimum-cost assignment.

    Rows and columns without any finite entry are dropped first (they can never be served).
    If the rest admits a complete assignment of its smaller side, scipy solves it exactly with
    ``inf`` as forbidden. Otherwise every ``inf`` is replaced by a penalty ``big`` larger than
    any possible difference of finite totals, so one more real pair always beats any saving in
    cost; the pairs that land on a penalty are then dropped. Costs are shifted to start at 0
    first (every candidate has the same number of pairs, so a shift changes no choice), which
    keeps ``big`` as small as the data allows: ``(k + 1) * span`` with ``k = min(N, M)`` and
    ``span`` the range of the finite costs.
    """
    cost = np.asarray(cost, dtype=float)
    if cost.ndim == 2 and cost.shape[1] == 1 and cost.shape[0]:
        # one task (an immediate decision's problem): the cheapest finite row, the first of
        # equal ones, as scipy's solve picks it (its first augmenting path from zero duals
        # takes the first unassigned minimum); a nan or no finite row takes the general path
        a = int(np.argmin(cost[:, 0]))
        if math.isfinite(cost[a, 0]):
            return [(a, 0)]
    if cost.ndim == 2 and cost.size and math.isfinite(np.add.reduce(cost, axis=None)):
        # every pair finite (a finite sum has no inf and no nan): no row or column to drop,
        # the same solve on the matrix itself, without the masks and the submatrix copy
        # (a city day's batch: half the allocator's time)
        r, c = linear_sum_assignment(cost)
        return list(zip(r.tolist(), c.tolist()))
    finite = np.isfinite(cost)
    if cost.ndim != 2 or not finite.any():
        return []
    rows = np.flatnonzero(finite.any(axis=1))
    cols = np.flatnonzero(finite.any(axis=0))
    sub = cost[np.ix_(rows, cols)]
    sub_finite = finite[np.ix_(rows, cols)]
    try:
        r, c = linear_sum_assignment(sub)
    except ValueError:  # no complete assignment of finite pairs: penalize the forbidden ones
        low, high = sub[sub_finite].min(), sub[sub_finite].max()
        span = high - low
        k = min(sub.shape)
        big = (k + 1) * span if span > 0 else 1.0
        r, c = linear_sum_assignment(np.where(sub_finite, sub - low, big))
    keep = sub_finite[r, c]
    return [(int(rows[a]), int(cols[t])) for a, t in zip(r[keep], c[keep])]
