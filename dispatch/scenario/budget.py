"""Work bounds: what ``validate``, ``run`` and ``sweep`` refuse because it would not finish.

The size bounds of :class:`dispatch.config.scenario.Limits` (cells, vehicles, releases, ...) keep a
run in memory; these keep it in time. Each estimates the work of a run from the scenario
alone, before anything is built, and refuses past a bound with the estimate, the bound and
what to change (``--ignore-limits`` runs anyway), as the size bounds do:

* **task-decisions** (voxel worlds): every decision looks at every open task it considers (a
  distance field each, recomputed when the field cache cannot hold them all), so a run's work
  is about *decisions × open tasks considered*. Past
  :data:`~dispatch.decide.candidates.CUT_TASKS` (2,000) open tasks a decision considers only the
  candidates of :mod:`dispatch.decide.candidates` (each vehicle's nearest and the oldest: 132 for
  4 vehicles), so thousands of open tasks cost a bounded decision each. Static tasks: M
  decisions (one per completion) over up to M open tasks when the fleet is smaller than M,
  else one decision of N × M pairs. Generated tasks (periodic, Poisson) and traces: one
  decision per release (or per batch window), each over the tasks open at its instant, none
  served: all released so far, unless ``max_active`` caps them or ``ttl`` / ``max_wait``
  (a trace's per-trip ``max_wait``) makes them expire. The bound, 600,000 on a grid of up to
  75,000 cells (the paper's 50 × 50 × 30 m world: about 20 s on one core), shrinks in
  proportion for larger grids (the fields grow with the grid).
* **a planner's own work**: a planner plugin may override
  :meth:`~dispatch.api.contracts.Planner.budget`, returning a sentence when a run of that many
  vehicles and tasks over that many simulated seconds is past its own bound (``rrt_star``:
  tree iterations, and the ray tests its parameters cost: a tiny ``step`` keeps a tree within
  a rewiring radius of its goal, so each iteration tests every node; ``reservation``: the
  retries of blocked vehicles, ``agents × duration / retry_after``);
  :func:`check_planner_budget` calls it.

Road networks have no task-decision bound: a decision reads cached Dijkstra trees (a city
day of 100,000 trips takes about a minute), and their size bounds are the releases'.
"""

from __future__ import annotations

import numpy as np

from dispatch.api.space import space_class
from dispatch.decide.candidates import CUT_TASKS, considered, per_vehicle
from dispatch.errors import LIMITS_HINT, ScenarioError

#: Task-decisions (decisions × open tasks) of one run on a grid of :data:`REFERENCE_CELLS`.
TASK_DECISIONS = 600_000
#: The grid the bound is measured on (the paper's 50 × 50 × 30 one-metre cells).
REFERENCE_CELLS = 75_000
#: Open tasks the candidate cut scans (their positions, each vehicle's distances) in the time
#: a decision spends on one task it considers: a cut decision costs 1 task-decision per this
#: many open tasks on top of its candidates (about 1.5 µs a task against 33).
SCANNED_PER_TASK_DECISION = 20


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


def _releases(spec) -> tuple[np.ndarray, np.ndarray] | None:
    """``(times, lifetimes)`` of the releases of a generated or trace source within the run
    (nominal instants: ``k / rate``, ``k * interval``, a trace's ``t``; sorted), each with the
    seconds it stays open unserved (``ttl``, its ``max_wait``; inf without); None for other
    sources."""
    sc, t = spec.scenario, spec.scenario.tasks
    if t.source in ("periodic", "poisson"):
        gap = t.interval if t.source == "periodic" else 1.0 / t.rate
        n = int(sc.duration / gap)
        if t.count is not None:
            n = min(n, t.count)
        times = gap * np.arange(1, n + 1, dtype=float)
        waits = np.full(n, np.nan)
    elif t.trips is not None:
        times = np.asarray(t.trips.t, dtype=float)[: t.count]
        waits = np.asarray(t.trips.max_wait, dtype=float)[: t.count]
        keep = times <= sc.duration
        times, waits = times[keep], waits[keep]
    else:
        return None
    if t.max_wait is not None:
        waits = np.where(np.isnan(waits), t.max_wait, waits)
    lives = np.where(np.isnan(waits), np.inf, waits)
    if t.ttl is not None:
        lives = np.minimum(lives, t.ttl)
    return times, lives


def _cut_note(n: int) -> str:
    """How the candidate cut bounds a decision of ``n`` vehicles (for the messages)."""
    return (f"; past {CUT_TASKS:,} open tasks a decision considers each vehicle's "
            f"{per_vehicle(n):,} nearest and the oldest, at most {n * (per_vehicle(n) + 1):,}, "
            f"after a scan of all of them, {SCANNED_PER_TASK_DECISION} scanned counting as one")


def _scan(open_now: np.ndarray) -> float:
    """The task-decisions of the candidate cut's scans over ``open_now`` open tasks (one
    decision each; only the decisions the cut binds scan)."""
    return float(open_now[open_now > CUT_TASKS].sum()) / SCANNED_PER_TASK_DECISION


def task_decisions(spec) -> tuple[float, str]:
    """(the open tasks the decisions of one voxel run consider, summed; how it was counted):
    see the module doc. A decision over more than :data:`~dispatch.decide.candidates.CUT_TASKS`
    open tasks counts the candidates it keeps (:func:`dispatch.decide.candidates.considered`)."""
    sc, t = spec.scenario, spec.scenario.tasks
    n = spec.agents
    if t.source == "static":
        m = spec.n_static_tasks
        if n >= m:
            return float(n) * m, f"one decision of {n:,} vehicles x {m:,} tasks"
        how = (f"{m:,} static tasks on {n:,} vehicles: a decision per completion over up to "
               f"{m:,} open tasks")
        if m <= CUT_TASKS:
            return float(m) * m / 2, how
        left = np.arange(CUT_TASKS + 1, m + 1)  # the open tasks of the decisions past the cut
        work = CUT_TASKS**2 / 2 + float(considered(left, n).sum()) + _scan(left)
        return work, how + _cut_note(n)
    releases = _releases(spec)
    if releases is None or not len(releases[0]):
        return 0.0, ""
    times, lives = releases
    window = sc.dispatch.batch_window
    if window > 0:  # a decision per window while tasks come
        at = window * np.arange(1, int(min(len(times), sc.duration / window)) + 1)
    else:  # a decision per release
        at = times
    ends = np.sort(times + lives)
    open_now = (np.searchsorted(times, at, side="right")
                - np.searchsorted(ends, at, side="right"))
    why = "no max_active, ttl or max_wait: every release stays open until served"
    if np.isfinite(lives).any():
        why = "released and not yet expired by ttl or max_wait"
    if t.max_active is not None and t.max_active < open_now.max(initial=0):
        open_now = np.minimum(open_now, t.max_active)
        why = f"max_active = {t.max_active:,}"
    peak = int(open_now.max(initial=0))
    how = f"about {len(at):,} decisions over up to {peak:,} open tasks ({why})"
    if peak > CUT_TASKS:
        how += _cut_note(n)
    return float(considered(open_now, n).sum()) + _scan(open_now), how


def check_work(sc, specs, refuse) -> None:
    """Refuse (``refuse(key, what)``, a ScenarioError) a voxel run past :data:`TASK_DECISIONS`
    (scaled to its grid)."""
    cells = space_class(sc.world.space).work_cells(sc.world)
    if cells is None or not specs:  # no bound in this space (road networks)
        return
    bound = TASK_DECISIONS * REFERENCE_CELLS / max(cells, REFERENCE_CELLS)
    counted: dict = {}  # runs differing only in what the count does not read share it
    for s in specs:
        key = (s.agents, s.n_static_tasks, s.batch_window)
        if key not in counted:
            counted[key] = (*task_decisions(s), s.batch_window)
    work, how, window = max(counted.values(), key=lambda c: c[0])
    if work <= bound:
        return
    t = sc.tasks
    if t.source == "static":
        key = ("sweep.agents" if sc.sweep.agents and t.count is None else
               "tasks.count" if t.count is not None else "fleet.agents")
        fix = "fewer tasks (tasks.count) or vehicles"
    elif t.source == "trace":
        key = "tasks.trace"
        fix = "fewer trips (tasks.count), a max_wait or ttl, or a shorter duration"
    else:
        key = "tasks.max_active" if t.max_active is None else "tasks.rate"
        fix = "set tasks.max_active or tasks.ttl, or a lower rate or shorter duration"
    if t.source != "static" and not window > 0:
        fix += (", or a batch window (dispatch.batch_window: a decision per window, not per "
                "release)")
    grid = f" on a grid of {cells:,} cells" if cells > REFERENCE_CELLS else ""
    raise refuse(key, f"about {work:.3g} task-decisions ({how}){grid}: more than "
                      f"{bound:,.0f}, which take about 20 s; {fix}")


def check_planner_budget(sc, specs, planner, name: str) -> None:
    """Ask ``planner`` (built with the scenario's parameters) whether the runs of ``specs``
    that use it are within its own bound; raise ScenarioError (key
    ``dispatch.planner_params``) with its sentence when not."""
    seen = set()
    for s in specs:
        if s.planner != name:
            continue
        key = (s.agents, expected_tasks(s), s.scenario.duration)
        if key in seen:
            continue
        seen.add(key)
        reason = planner.budget(agents=s.agents, tasks=key[1], duration=s.scenario.duration)
        if reason:
            raise ScenarioError(sc.path, "dispatch.planner_params",
                                f"planner {name!r}: {reason}; {LIMITS_HINT}")


def periods(sc) -> list[tuple[str, float]]:
    """``(key, seconds)`` of each process a run of ``sc`` calls periodically: the repositioner,
    the charging strategy, the state-of-charge samples and the ``utilization`` sizer (a sizer
    of one's own sets its interval in code, checked positive by ``dispatch check``)."""
    out = []
    if sc.reposition.policy != "stay":
        out.append(("reposition.interval", sc.reposition.interval))
    if sc.charging is not None:
        out.append(("charging.interval", sc.charging.interval))
    if sc.fleet.energy is not None:
        out.append(("fleet.energy.sample", sc.fleet.energy.sample))
    interval = dict(sc.fleet.sizing_params).get("interval")
    if sc.fleet.sizing not in (None, "fixed") and isinstance(interval, (int, float)) \
            and not isinstance(interval, bool):
        out.append(("fleet.sizing_params.interval", float(interval)))
    return out


def check_periodic(sc, bound: int, refuse) -> None:
    """Refuse (``refuse(key, what)``) a period so short that its process would be called more
    than ``bound`` times over the run: a tiny period loops in (almost) no simulated time, so
    the run never ends."""
    for key, seconds in periods(sc):
        calls = sc.duration / seconds if seconds > 0 else float("inf")
        if not calls <= bound:
            raise refuse(key, f"{seconds:g} s: about {calls:.3g} calls in {sc.duration:g} s "
                              f"(more than {bound:,})")

