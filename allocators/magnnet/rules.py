"""The allocation game of the paper, and the reward shaping (magnitudes documented here).

One episode is one decision of the dispatcher: ``N`` agents, ``M`` tasks, a cost matrix
``cost[i, j]`` (travel seconds, ``inf`` where agent ``i`` cannot serve task ``j``) and the
agents' communication adjacency. It is played in *rounds*, with the rules of the shared loop
:func:`dispatch.api.decentralized.run_rounds` on a complete graph without loss (every agent hears of
every won task):

* an agent *decides* while it is unassigned and some open task is feasible for it;
* each deciding agent takes action ``0`` (reject) or ``j + 1`` (request task ``j``; only open,
  feasible tasks may be requested: the action mask says which);
* a task requested by several agents goes to the requester with the smallest cost (ties to the
  lowest agent index); the others stay unassigned and decide again next round;
* the episode ends when no agent decides, when no agent requests in a round (the shared loop
  stops there too), or after ``max_rounds`` rounds (a truncation).

Rewards (per agent, per round), the paper's shaping with our magnitudes:

* ``R_WIN - R_COST * c_ij / c_mean`` to an agent that wins task ``j`` (``c_mean``: the mean
  finite cost of the instance), so a cheap win is worth more than a dear one;
* ``R_CONFLICT`` to every requester of a task that two or more agents requested this round;
* ``R_REJECT`` to a deciding agent that rejects "without a valid reason": while it is the
  cheapest deciding contender (ties to the lowest index) for some task it could request, i.e.
  it holds back a task it would win. Waiting while a cheaper agent contends for one's tasks is
  free (that is how agents avoid conflicts over several rounds);
* at the last round, ``R_STALL`` to every agent that is still deciding (unassigned while an
  open task it can serve is left): the episode ended with it idle, so its rejects were
  "without a valid reason" (the paper's penalty against stagnation; without it a policy that
  rejects everything ends the episode at no cost and PPO finds that first, see the README);
* at the last round, ``R_TEAM * exp(-TEAM_SHARPNESS * gap)`` to every agent still in the game
  when the episode ends with as many tasks assigned as the optimum assigns, ``gap`` the total
  cost's relative gap to the optimal (Hungarian) assignment; the *team* reward used by the
  centralized critic adds it once.
"""

from __future__ import annotations

import math

import numpy as np

R_WIN = 1.0
R_COST = 1.0
R_CONFLICT = -2.0
R_REJECT = -0.05
R_TEAM = 2.0
R_STALL = -2.0
#: ``True``: only the requesters that lose a contested task pay ``R_CONFLICT`` (the cheapest
#: requester won it as the paper rewards); ``False``: every requester of it pays.
CONFLICT_LOSERS_ONLY = False
TEAM_SHARPNESS = 10.0

#: Costs are divided by this many seconds in the observations; ``inf`` and unavailable tasks
#: read as ``COST_CAP``. A fixed scale (not a statistic of the instance) keeps every agent's
#: features local.
COST_SCALE = 10.0
COST_CAP = 3.0


def cheapest_contender(cost: np.ndarray) -> np.ndarray:
    """Per task, the agent with the smallest cost (ties to the lowest index; ``inf`` where
    unavailable), ``-1`` where no agent can take it. ``cost (N, M)``."""
    if cost.shape[0] == 0:
        return np.full(cost.shape[1], -1, np.int64)
    return np.where(np.isfinite(cost).any(0), cost.argmin(0), -1)


def max_rounds_for(m: int) -> int:
    return 2 * m + 2


def optimal(cost: np.ndarray) -> tuple[int, float]:
    """Assigned count and total cost of the optimal assignment (the reference of the bonus)."""
    from allocators.hungarian import optimal_pairs

    pairs = optimal_pairs(cost)
    return len(pairs), float(sum(cost[a, t] for a, t in pairs))


def team_bonus(n_assigned: int, total: float, opt_count: int, opt_total: float) -> float:
    if n_assigned < opt_count:
        return 0.0
    gap = (total - opt_total) / opt_total if opt_total > 0 else 0.0
    return R_TEAM * math.exp(-TEAM_SHARPNESS * max(gap, 0.0))
