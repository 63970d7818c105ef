"""The candidate cut: a decision over thousands of open tasks offers each vehicle its nearest.

A decision's work grows with the open tasks it considers (a cost column each: on a voxel grid a
distance field, computed again every decision once the planner's field cache cannot hold them
all), so a batch with thousands of open tasks and few vehicles fell off a cliff: Poisson 100
tasks/s that live 120 s (up to 12,000 open), 4 vehicles, batched 5 s, reached 85 of 120
simulated seconds in 5 minutes. Past :data:`CUT_TASKS` open tasks a decision therefore
considers only

* each idle vehicle's :func:`per_vehicle` nearest open tasks by straight-line distance, and
* the open tasks released first, one per vehicle (``fcfs`` serves in release order, and a task
  far from every vehicle keeps its turn as it ages),

at most ``N x (per_vehicle(N) + 1)`` tasks (132 for 4 vehicles) however many are open; the
cut itself scans every open task once (positions and distances, about 1.5 µs a task). The
tasks left out stay open: neither offered nor rejected (a ``ttl`` or ``max_wait`` still
expires them). Each decision counts them: the ``n_cut`` column of the ``decisions`` table. At
or below :data:`CUT_TASKS` open tasks nothing is cut (every shipped scenario decides over at
most 70), so results there are those of the whole problem; the run budget
(:mod:`dispatch.scenario.budget`) counts a cut decision's work with :func:`considered`.
"""

from __future__ import annotations

import numpy as np

#: Open tasks past which a decision offers each vehicle only its nearest (see the module doc).
#: Above the most a run within the budget's task-decision bound can hold with static tasks
#: (M^2 / 2 <= 600,000: 1,095), so that no static run is cut.
CUT_TASKS = 2_000
#: The fewest nearest tasks each vehicle is offered when the cut binds (see :func:`per_vehicle`).
NEAREST = 32


def per_vehicle(n_agents: int) -> int:
    """The nearest open tasks each of ``n_agents`` vehicles is offered when the cut binds:
    twice the fleet's, at least :data:`NEAREST`. An optimal assignment of N vehicles gives each
    one of its N cheapest tasks (were it another, one of those N is held by none of the other
    N - 1 and cheaper), so the
    N nearest keep the optimum wherever the straight-line order is the cost order; the rest
    leave room for the detours obstacles and roads make."""
    return max(NEAREST, 2 * n_agents)


def cut(open_tasks: list, agents, space, keep=()) -> tuple[list, int]:
    """``(tasks, left_out)``: ``open_tasks`` (in their order) when there are at most
    :data:`CUT_TASKS` of them; else the candidates of the module doc (their order kept) and
    how many were left out. ``agents`` are the decision's vehicles (``.loc`` each),
    ``space`` places locations (:meth:`Space.positions`); tasks whose id is in ``keep`` (a
    re-assignment's held tasks) are always kept. Ties in distance go to the task listed first."""
    m, n = len(open_tasks), len(agents)
    if m <= CUT_TASKS or n == 0:
        return open_tasks, 0
    k = per_vehicle(n)
    chosen = np.zeros(m, dtype=bool)
    chosen[:n] = True  # the first released, one per vehicle
    if keep:
        chosen |= np.fromiter((t.id in keep for t in open_tasks), bool, m)
    tpos = space.positions([t.loc for t in open_tasks])
    apos = space.positions([a.loc for a in agents])
    if k < m:
        for p in apos:
            d = tpos - p
            d *= d
            d2 = d.sum(axis=1)
            kth = np.partition(d2, k - 1)[k - 1]
            near = d2 < kth
            ties = np.flatnonzero(d2 == kth)[: k - int(near.sum())]
            chosen |= near
            chosen[ties] = True
    else:
        chosen[:] = True
    kept = np.flatnonzero(chosen).tolist()
    if len(kept) == m:
        return open_tasks, 0
    return [open_tasks[i] for i in kept], m - len(kept)


def considered(open_tasks, n_agents: int):
    """The most tasks a decision of ``n_agents`` vehicles over ``open_tasks`` open ones
    considers (a number or an array of them; for the run budget, :mod:`dispatch.scenario.budget`):
    all of them up to :data:`CUT_TASKS`, past it at most each vehicle's :func:`per_vehicle`
    nearest and one more per vehicle (the oldest)."""
    most = n_agents * (per_vehicle(n_agents) + 1)
    return np.where(np.asarray(open_tasks) <= CUT_TASKS, open_tasks,
                    np.minimum(open_tasks, most))
