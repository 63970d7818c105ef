"""The planner checks (``dispatch check NAME`` of a planner), on random agents and tasks of the
space: ``construct``, ``costs`` (shape ``(len(agents), len(tasks))``, floats, ``>= 0`` or
``inf``, no ``nan``, also for 0 agents / 0 tasks), ``plan`` (a path from the agent's location
to the goal where the cost is finite), ``no-mutation`` (of the space's grid), ``deterministic``
and ``rng`` (:func:`dispatch.checks.common.replay`); for a planner that sets ``lower_bounds``,
``bounds`` (each bound ``<=`` the cost, ``inf`` exactly where the cost is, entries marked exact
equal to it, and ``exact`` equal to the costs, all to 1e-9 relative, each on a fresh instance).

    report = check_planner(MyPlanner)                     # on a small voxel world / road grid
    report = check_planner(MyPlanner, space)              # or on a space of your own
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from dispatch.api import registry
from dispatch.api.legs import RoadPoint
from dispatch.api.problem import AgentView, TaskView
from dispatch.api.space import KINDS, space_class
from dispatch.checks.common import Report, declared, describe_error, perturb_global_rng, replay


def check_planner(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every planner check (see the module docstring) on ``cls(space, **params)``; without
    a ``space``, on :func:`~dispatch.checks.common.small_world` and/or
    :func:`~dispatch.checks.common.small_network` (the spaces it serves)."""
    report, caps = declared("planner", cls)
    if caps is None:
        return report
    if space is None:
        spaces = [space_class(kind).small(seed) for kind in KINDS if caps.serves(kind)]
    else:
        spaces = [space]
    for sp in spaces:
        tag = f" [{sp.kind}]" if len(spaces) > 1 else ""
        _check_planner_on(report, cls, caps, sp, seed=seed, params=params, tag=tag)
    return report


def _costs(planner, agents, tasks) -> np.ndarray:
    return np.asarray(planner.costs(agents, tasks))


def _check_planner_on(report: Report, cls, caps: registry.Capabilities, space, *, seed: int,
                      params: dict, tag: str) -> None:
    try:
        cls(space, **params)
    except Exception as e:  # noqa: BLE001
        report.add("construct" + tag,
                   [f"{cls.__name__}(space, **{params!r}) raised {describe_error(e)}"], "")
        return
    report.add("construct" + tag, [], f"{cls.__name__}(<{space.kind} space>, **{params!r})")
    unchanged = GUARDED[space.kind](space)
    shapes = [(0, 3), (3, 0), (0, 0), (1, 1), (4, 6), (6, 2)]
    bad_costs, bad_plans, differs, global_rng, bad_bounds = [], [], [], [], []
    bounded = caps.lower_bounds
    replayed = 0  # query sets whose costs were valid (the deterministic and rng checks')
    for k, (n, m) in enumerate(shapes):
        agents, tasks = SAMPLERS[space.kind](space, np.random.default_rng(seed * 100 + k), n, m)
        label = f"{n} agents x {m} tasks"
        try:
            perturb_global_rng(1)
            planner = cls(space, **params)
            c = _costs(planner, agents, tasks)
        except Exception as e:  # noqa: BLE001
            bad_costs.append(f"{label}: costs raised {describe_error(e)}")
            continue
        if c.shape != (n, m):
            bad_costs.append(f"{label}: costs has shape {c.shape}, expected {(n, m)}")
            continue
        if not np.issubdtype(c.dtype, np.floating) or np.isnan(c).any() or (c < 0).any():
            bad_costs.append(f"{label}: costs must be floats >= 0 or inf (no nan), got "
                             f"{c.dtype} {c.ravel()[:6]}")
            continue
        for i, a in enumerate(agents):
            for j, t in enumerate(tasks):
                if not math.isfinite(c[i, j]):
                    continue
                try:
                    path = planner.plan(a, t.loc)
                except Exception as e:  # noqa: BLE001
                    bad_plans.append(f"{label}: plan raised {describe_error(e)}")
                    continue
                if not path or not space.reaches(path, a.loc, t.loc):
                    bad_plans.append(f"{label}: agent {a.id} -> task {t.id}: cost {c[i, j]:.3g}"
                                     f" but plan gave {path if not path else (path[0], path[-1])}")
        if bounded:
            bad_bounds += _check_bounds(cls, space, params, agents, tasks, c, label)
        replayed += 1
        replay(label, lambda a=agents, t=tasks: _costs(cls(space, **params), a, t), c, differs,
                global_rng, same=np.array_equal, show=lambda c: f"costs {c.ravel()[:4]}",
                given="queries")
    mutated = [] if unchanged is None or np.array_equal(unchanged, GUARDED[space.kind](space)) \
        else ["the world's grid changed"]
    report.add("costs" + tag, bad_costs, f"{len(shapes)} query sets, shapes and values valid")
    report.add("plan" + tag, bad_plans, "a path to the goal wherever the cost is finite")
    report.add("no-mutation" + tag, mutated, "the space is unchanged")
    report.add("deterministic" + tag, differs, "same queries, same costs", ran=replayed,
               of=len(shapes), after="costs")
    report.add("rng" + tag, global_rng, "costs do not depend on the global random state",
               ran=replayed, of=len(shapes), after="costs")
    if bounded:
        report.add("bounds" + tag, bad_bounds, "lower bounds below the costs, exact ones equal")


def _check_bounds(cls, space, params: dict, agents, tasks, c: np.ndarray,
                  label: str) -> list[str]:
    """What is wrong with a ``lower_bounds`` planner's ``bounds`` and ``exact`` against the
    costs ``c`` of the same queries (each asked of a fresh instance)."""
    bad = []
    try:
        lower, known = cls(space, **params).bounds(agents, tasks)
        lower, known = np.asarray(lower, dtype=float), np.asarray(known)
        rows, cols = np.divmod(np.arange(c.size), max(1, c.shape[1]))
        ex = np.asarray(cls(space, **params).exact(agents, tasks, rows, cols), dtype=float)
    except Exception as e:  # noqa: BLE001
        return [f"{label}: bounds or exact raised {describe_error(e)}"]
    if lower.shape != c.shape or known.shape != c.shape or known.dtype != bool:
        return [(f"{label}: bounds gave shapes {lower.shape} / {known.shape} "
                 f"({known.dtype}), expected {c.shape} and bool")]
    finite = np.isfinite(c)
    slack = 1e-9 * np.where(finite, np.abs(c), 0.0)
    with np.errstate(invalid="ignore"):  # inf - inf where both are inf: not compared
        return bad + _bound_faults(lower, known, ex, c, finite, slack, label=label)


def _bound_faults(lower, known, ex, c, finite, slack, *, label: str) -> list[str]:
    bad = []
    if not np.array_equal(np.isinf(lower), ~finite):
        bad.append(f"{label}: a bound is inf where the cost is finite or the other way round")
    elif (lower[finite] > c[finite] + slack[finite]).any():
        bad.append(f"{label}: a bound is above its cost")
    elif (np.abs(lower - c)[known & finite] > slack[known & finite]).any():
        bad.append(f"{label}: an entry marked exact differs from its cost")
    if ex.shape != (c.size,) or not np.array_equal(np.isinf(ex), ~finite.ravel()) or \
            (np.abs(ex - c.ravel())[finite.ravel()] > slack.ravel()[finite.ravel()]).any():
        bad.append(f"{label}: exact() differs from costs()")
    return bad


Views = tuple[tuple[AgentView, ...], tuple[TaskView, ...]]


def voxel_views(world, rng: np.random.Generator, n: int, m: int) -> Views:
    """``n`` agents and ``m`` tasks in a voxel world: UAVs (odd positions) in free cells up to
    2 cells high, UGVs on the ground; tasks in any free cell (``ground`` on layer 0, else
    ``air``)."""
    free = world.grid.free_cells()
    ground = free[free[:, 2] == 0]

    def pick(pool, k):
        return [tuple(int(v) for v in pool[i]) for i in rng.integers(0, len(pool), k)]

    a_cells = pick(free[free[:, 2] <= 2], n)
    kinds = ["uav" if i % 2 else "ugv" for i in range(n)]
    a_cells = [c if k == "uav" else pick(ground, 1)[0] for c, k in zip(a_cells, kinds)]
    t_cells = pick(free, m)
    agents = tuple(AgentView(100 + i, kinds[i], a_cells[i],
                             5.0 if kinds[i] == "uav" else 3.0) for i in range(n))
    tasks = tuple(TaskView(500 + j, "ground" if c[2] == 0 else "air", c, 0.0)
                  for j, c in enumerate(t_cells))
    return agents, tasks


def road_views(net, rng: np.random.Generator, n: int, m: int) -> Views:
    """``n`` cars on random nodes (as road points) and ``m`` trips to random nodes."""
    nodes = rng.integers(0, net.n, n + m)
    agents = tuple(AgentView(100 + i, "car", RoadPoint(int(nodes[i])), 10.0) for i in range(n))
    tasks = tuple(TaskView(500 + j, "trip", int(nodes[n + j]), 0.0) for j in range(m))
    return agents, tasks


#: random agent and task views of each space kind, for the checks: ``(space, rng, n, m)``
SAMPLERS: dict[str, Callable[..., Views]] = {"voxel": voxel_views, "road": road_views}

#: what of a space of each kind the ``no-mutation`` check compares before and after the
#: planner's queries, copied: ``(space) -> array or None`` (None: nothing compared)
GUARDED: dict[str, Callable[..., np.ndarray | None]] = {
    "voxel": lambda world: np.array(world.grid.occupied, copy=True),
    "road": lambda net: None}
