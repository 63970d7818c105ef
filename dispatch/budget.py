"""Work bounds: what ``validate``, ``run`` and ``sweep`` refuse because it would not finish.

The size bounds of :class:`dispatch.config.Limits` (cells, vehicles, releases, ...) keep a
run in memory; these keep it in time. Each estimates the work of a run from the scenario
alone, before anything is built, and refuses past a bound with the estimate, the bound and
what to change (``--force`` runs anyway), as the size bounds do:

* **task-decisions** (voxel worlds): every decision looks at every open task (a distance field
  each, recomputed when the field cache cannot hold them all), so a run's work is about
  *decisions × open tasks*. Static tasks: M decisions (one per completion) over up to M open
  tasks when the fleet is smaller than M, else one decision of N × M pairs. Generated tasks
  (periodic, Poisson): one decision per release (or per batch window) over the tasks that can
  be open at once: all released so far, unless ``max_active`` caps them or ``ttl`` /
  ``max_wait`` makes them expire (rate × that lifetime). The bound, 600,000 on a grid of up
  to 75,000 cells (the paper's 50 × 50 × 30 m world: about 20 s on one core), shrinks in
  proportion for larger grids (the fields grow with the grid).
* **a planner's own work**: a planner plugin may define ``budget(agents, tasks, duration)``,
  returning a sentence when a run of that many vehicles and tasks over that many simulated
  seconds is past its own bound (``rrt_star``: tree iterations; ``reservation``: the retries
  of blocked vehicles, ``agents × duration / retry_after``); :func:`check_planner_budget`
  calls it.

Road networks have no task-decision bound: a decision reads cached Dijkstra trees (a city
day of 100,000 trips takes about a minute), and their size bounds are the releases'.
"""

from __future__ import annotations

#: Task-decisions (decisions × open tasks) of one run on a grid of :data:`REFERENCE_CELLS`.
TASK_DECISIONS = 600_000
#: The grid the bound is measured on (the paper's 50 × 50 × 30 one-metre cells).
REFERENCE_CELLS = 75_000


def expected_tasks(spec) -> float:
    """The tasks a run releases: static M, the releases of a generated source (capped by
    ``count``), a trace's trips, an empirical day's trips over the duration."""
    sc = spec.scenario
    t = sc.tasks
    if t.source == "static":
        return float(spec.n_static_tasks)
    if t.source in ("periodic", "poisson"):
        n = sc.duration / t.interval if t.source == "periodic" else sc.duration * t.rate
        return float(min(n, t.count) if t.count is not None else n)
    if t.trips is not None:
        return float(len(t.trips))
    if t.trips_per_day is not None:
        return float(t.trips_per_day) * min(sc.duration, 86400.0) / 86400.0
    return 0.0


def task_decisions(spec) -> tuple[float, str]:
    """(decisions × open tasks, how it was counted) of one voxel run (see the module doc)."""
    sc, t = spec.scenario, spec.scenario.tasks
    n = spec.agents
    if t.source == "static":
        m = spec.n_static_tasks
        if n >= m:
            return float(n) * m, f"one decision of {n:,} vehicles x {m:,} tasks"
        return float(m) * m / 2, (f"{m:,} static tasks on {n:,} vehicles: a decision per "
                                  f"completion over up to {m:,} open tasks")
    if t.source not in ("periodic", "poisson"):
        return 0.0, ""
    releases = expected_tasks(spec)
    rate = 1 / t.interval if t.source == "periodic" else t.rate
    window = sc.dispatch.batch_window
    decisions = min(releases, sc.duration / window) if window > 0 else releases
    lifetimes = [x for x in (t.ttl, t.max_wait) if x is not None]
    open_max = releases
    why = "no max_active, ttl or max_wait: every release stays open until served"
    if t.max_active is not None and t.max_active < open_max:
        open_max, why = t.max_active, f"max_active = {t.max_active:,}"
    if lifetimes and rate * min(lifetimes) < open_max:
        open_max, why = rate * min(lifetimes), "rate x ttl / max_wait"
    return float(decisions) * open_max, (f"about {decisions:,.0f} decisions over up to "
                                         f"{open_max:,.0f} open tasks ({why})")


def check_work(sc, specs, refuse) -> None:
    """Refuse (``refuse(key, what)``, a ScenarioError) a voxel run past :data:`TASK_DECISIONS`
    (scaled to its grid)."""
    from dispatch.space import space_class

    cells = space_class(sc.world.space).work_cells(sc.world)
    if cells is None or not specs:  # no bound in this space (road networks)
        return
    bound = TASK_DECISIONS * REFERENCE_CELLS / max(cells, REFERENCE_CELLS)
    worst = max(specs, key=lambda s: task_decisions(s)[0])
    work, how = task_decisions(worst)
    if work <= bound:
        return
    t = sc.tasks
    if t.source == "static":
        key = ("sweep.agents" if sc.sweep.agents and t.count is None else
               "tasks.count" if t.count is not None else "fleet.agents")
        fix = "fewer tasks (tasks.count) or vehicles"
    else:
        key = "tasks.max_active" if t.max_active is None else "tasks.rate"
        fix = "set tasks.max_active or tasks.ttl, or a lower rate or shorter duration"
    grid = f" on a grid of {cells:,} cells" if cells > REFERENCE_CELLS else ""
    raise refuse(key, f"about {work:.3g} task-decisions ({how}){grid}: more than "
                      f"{bound:,.0f}, which take about 20 s; {fix}")


def check_planner_budget(sc, specs, planner, name: str) -> None:
    """Ask ``planner`` (built with the scenario's parameters) whether the runs of ``specs``
    that use it are within its own bound; raise ScenarioError (key
    ``dispatch.planner_params``) with its sentence when not."""
    from dispatch.errors import ScenarioError
    from dispatch.errors import FORCE_HINT

    budget = getattr(planner, "budget", None)
    if not callable(budget):
        return
    seen = set()
    for s in specs:
        if s.planner != name:
            continue
        key = (s.agents, expected_tasks(s), s.scenario.duration)
        if key in seen:
            continue
        seen.add(key)
        reason = budget(agents=s.agents, tasks=key[1], duration=s.scenario.duration)
        if reason:
            raise ScenarioError(sc.path, "dispatch.planner_params",
                                f"planner {name!r}: {reason}; {FORCE_HINT}")
