"""The tables ``dispatch run`` and ``dispatch sweep`` print, from the runs' summaries.

* static voxel scenarios: the MAGNNET paper's Table I (total travel cost, gap to Hungarian) and
  Table III (conflict-free success rate, allocation time of the first decision);
* dynamic voxel scenarios (tasks released over time): the same two tables **per task**
  (served share, mean wait, mean planned cost per assignment; conflict-free rate, milliseconds
  per decision), because planned costs summed over a run are not comparable between allocators
  that drive different trajectories and serve different numbers of tasks;
* road-network runs: the trip table (served, rejected, cut off by the run's end, wait, empty
  km, km driven), with a row of 95 % interval half-widths over the seeds under each row of
  several seeds; electric runs add the energy table (:mod:`dispatch.output.energy`);
* a single run: its own summary, one ``key: value`` line each.

Every table is one row per (allocator, N), grouped by N, with short numeric cells: it fits an
80-column terminal without cutting a cell (a test renders them at width 80). Where the runs
hold several batch windows (``[sweep] batch_window``, a run key), a row is an allocator and a
window (``fcfs imm``, ``fcfs 30s``).
"""

from __future__ import annotations

import math
from collections import defaultdict
from statistics import fmean

from dispatch.config.runkeys import key_names

# One allocator order, one paired gap, one label of a batch window, one set of per-task figures
# for the CLI's tables and the analysis package, and one interval of a mean (a shared package
# outside both, standard library only; see their docstrings).
from dispatch.output.energy import ENERGY_FIGURES, electric, energy_line
from paired.compare import allocator_order, paired_gaps, window_label
from paired.per_task import per_task, ratio
from paired.stats import mean_ci


def _mean(rows: list[dict], key: str) -> float:
    vals = [float(r[key]) for r in rows if r.get(key) is not None and not math.isnan(r[key])]
    return fmean(vals) if vals else math.nan


def _f(v: float, digits: int = 1, scale: float = 1.0, unit: str = "") -> str:
    return "-" if v is None or math.isnan(v) else f"{v * scale:.{digits}f}{unit}"


def _label(s: dict, windows: bool) -> str:
    """A table row's name: the allocator, and its batch window when the runs hold several
    (``fcfs imm``, ``fcfs 30s``)."""
    return f"{s['allocator']} {window_label(_window(s))}" if windows else s["allocator"]


def _window(s: dict) -> float:
    """A run's batch window (0 for a summary without one)."""
    w = s.get("batch_window")
    return 0.0 if w is None or math.isnan(float(w)) else float(w)


def _windows(summaries: list[dict]) -> bool:
    """Whether the runs hold several batch windows (rows then name theirs)."""
    return len({_window(s) for s in summaries}) > 1


def aggregate(summaries: list[dict], reference: str = "hungarian") -> dict[tuple[str, int], dict]:
    """Per (row, n_agents), a row being the allocator (and its batch window where the runs
    hold several): mean over seeds of the total cost, the paired gap to ``reference``
    (:func:`paired.compare.paired_gaps`: the same value of every other run key, see
    :data:`dispatch.config.runkeys.RUN_KEYS`), the conflict-free rate, the allocation seconds, and
    the per-task figures of dynamic runs (served share, wait, cost per assignment, ms per
    decision); ``runs``."""
    windows = _windows(summaries)
    gaps = paired_gaps(summaries, reference, run_keys=key_names())
    groups: dict[tuple[str, int], list[tuple[dict, float]]] = defaultdict(list)
    for s, g in zip(summaries, gaps, strict=True):
        groups[(_label(s, windows), s["n_agents"])].append((s, g))
    out = {}
    for key, pairs in groups.items():
        rows = [s for s, _ in pairs]
        figures = [per_task(r) for r in rows]
        gs = [g for _, g in pairs if not math.isnan(g)]
        out[key] = {
            "allocator": rows[0]["allocator"],
            "batch_window": _window(rows[0]),
            "runs": len(rows),
            "total_cost": _mean(rows, "total_cost"),
            "gap": fmean(gs) if gs else math.nan,
            "conflict_free_rate": _mean(rows, "conflict_free_rate"),
            "alloc_seconds": _mean(rows, "alloc_seconds"),
            "first_decision_seconds": _mean(rows, "first_decision_seconds"),
            "tasks_completed": _mean(rows, "tasks_completed"),
            "n_tasks": _mean(rows, "n_tasks"),
            "served_share": fmean(f["served_share"] for f in figures),
            "wait": _mean(figures, "wait_mean"),
            "cost_per_assignment": fmean(f["cost_per_assignment"] for f in figures),
            "decision_ms": fmean(f["decision_ms"] for f in figures),
        }
    return out


def _new_table(title: str, columns: list[str], collapse: bool = False):
    from rich import box
    from rich.table import Table

    # collapse: one space between columns (the box's own divider), for the widest tables
    # (no edge: a box's top and bottom edges are lines of spaces)
    t = Table(title=title, box=box.SIMPLE_HEAD, padding=(0, 0) if collapse else (0, 1),
              pad_edge=False, show_edge=False, title_justify="left")
    for i, col in enumerate(columns):
        t.add_column(col, justify="left" if i == 0 else "right", no_wrap=i == 0)
    return t


def _show(console, t) -> None:
    """Print table ``t`` with its title above it as a paragraph of the console's width (rich
    wraps a title to the table's width, 48 columns for a narrow table, and pads its lines with
    spaces), then the table."""
    import textwrap

    from rich.text import Text

    title, t.title = t.title, None
    if title:
        console.print(Text(textwrap.fill(str(title), width=max(console.width, 20)),
                           style="table.title"), soft_wrap=True)
    console.print(t)


def _grouped_rows(agg: dict):
    """(allocator, N, row) in N order, allocators in the paper's order; ``last`` marks the last
    row of an N (a section ends there)."""
    sizes = sorted({n for _, n in agg})
    alloc = {a: r.get("allocator", a) for (a, _), r in agg.items()}
    window = {a: r.get("batch_window", 0.0) for (a, _), r in agg.items()}
    rank = {a: i for i, a in enumerate(allocator_order(alloc.values()))}

    def order(label):
        return rank[alloc[label]], window[label], label

    labels = sorted({a for a, _ in agg}, key=order)
    for n in sizes:
        here = [a for a in labels if (a, n) in agg]
        for i, a in enumerate(here):
            yield a, n, agg[(a, n)], i == len(here) - 1


def render(summaries: list[dict], console=None, *, dynamic: bool = False) -> None:
    """Print Tables I and III (see the module docstring; ``dynamic``: the per-task tables)."""
    from rich.console import Console

    console = console or Console()
    agg = aggregate(summaries)
    runs = max((r["runs"] for r in agg.values()), default=0)
    if dynamic:
        t1 = _new_table(f"Table I (dynamic): per task, mean over {runs} seed(s); served = "
                        "completed / released; wait = release to pickup; cost = planned "
                        "seconds to the pickup per assignment",
                        ["allocator", "N", "tasks", "served", "wait s", "cost s"])
        t3 = _new_table("Table III (dynamic): conflict-free success rate and wall time per "
                        "decision (cost matrix + allocator)",
                        ["allocator", "N", "conflict-free", "ms/decision"])
        for a, n, r, last in _grouped_rows(agg):
            t1.add_row(a, str(n), _f(r["n_tasks"], 0), _f(r["served_share"], 1, 100, "%"),
                       _f(r["wait"]), _f(r["cost_per_assignment"], 2), end_section=last)
            t3.add_row(a, str(n), _f(r["conflict_free_rate"], 1, 100, "%"),
                       _f(r["decision_ms"], 2), end_section=last)
    else:
        t1 = _new_table(f"Table I: total travel cost (s, sum of the planned costs), mean over "
                        f"{runs} seed(s); gap to Hungarian paired by seed",
                        ["allocator", "N", "runs", "cost s", "gap"])
        t3 = _new_table("Table III: conflict-free success rate and allocation time of the "
                        "first decision (cost matrix + allocator)",
                        ["allocator", "N", "conflict-free", "time ms"])
        for a, n, r, last in _grouped_rows(agg):
            gap = ("" if r["allocator"] == "hungarian" or math.isnan(r["gap"])
                   # + 0.0 turns a rounding-level -0.0 (equal totals in another order) into 0
                   else f"{round(100 * r['gap'], 1) + 0.0:+.1f}%")
            t1.add_row(a, str(n), str(r["runs"]), _f(r["total_cost"]), gap, end_section=last)
            t3.add_row(a, str(n), _f(r["conflict_free_rate"], 1, 100, "%"),
                       _f(r["first_decision_seconds"], 1, 1000), end_section=last)
    _show(console, t1)
    _show(console, t3)


def render_trips(summaries: list[dict], console=None) -> None:
    """Print the trip table of road-network runs: per allocator and fleet size, the mean over
    seeds of trips released, the share served and rejected (at once, or expired waiting), the
    mean wait (release to pickup), the share of the fleet's kilometres driven empty, the
    kilometres driven and the wall seconds spent deciding. Runs with a repositioner other than
    ``stay`` get a table per repositioner (its name and the kilometres it drove in the title)."""
    by_repositioner: dict[str, list[dict]] = defaultdict(list)
    for s in summaries:
        by_repositioner[s.get("reposition", "stay")].append(s)
    for name in sorted(by_repositioner, key=lambda r: (r != "stay", r)):
        rows = by_repositioner[name]
        _render_trips(rows, console, None if set(by_repositioner) == {"stay"} else name)


def _ci(rows: list[dict], value) -> tuple[float, float]:
    """Mean over ``rows`` of ``value(row)`` and the half-width of its 95 % Student-t interval
    (NaN with fewer than two finite values)."""
    mean, half, _ = mean_ci(value(r) for r in rows)
    return mean, half


#: The trip table's figures: (column, digits, scale, unit, value of one run).
_TRIP_FIGURES = (
    ("trips", 0, 1.0, "", lambda r: r["n_tasks"]),
    ("served", 1, 100, "%", lambda r: per_task(r)["served_share"]),
    ("rej.", 1, 100, "%", lambda r: ratio(r["tasks_rejected"] + r["tasks_expired"]
                                           + r.get("tasks_unreachable", 0), r["n_tasks"])),
    # the summary's tasks_cut_off: trips the run's end cut off (still waiting or aboard)
    ("cut", 1, 100, "%", lambda r: ratio(r["tasks_cut_off"], r["n_tasks"])),
    ("wait", 1, 1.0, "", lambda r: r["wait_time_mean"]),
    ("empty", 0, 100, "%", lambda r: ratio(r["empty_distance"], r["distance"])),
    # thousands of km: a city day fits 80 columns
    ("k km", 1, 1e-6, "", lambda r: r["distance"]),
    ("dec. s", 2, 1.0, "", lambda r: r["alloc_seconds"]),
)


def _render_trips(summaries: list[dict], console, repositioner: str | None) -> None:
    from rich.console import Console

    console = console or Console()
    groups: dict[tuple[str, int], list[dict]] = defaultdict(list)
    windows = _windows(summaries)
    for s in summaries:
        groups[(_label(s, windows), s["n_agents"])].append(s)
    runs = max((len(g) for g in groups.values()), default=0)
    title = ("Trips, mean over {runs} seed(s): served, rejected (at once or expired) and cut "
             "off (still waiting or aboard when the run ended) share of the trips, wait from "
             "release to pickup (s), share of km driven empty, km driven (thousands), wall "
             "seconds deciding").format(runs=runs)
    if runs > 1:
        title += "; under a row of several seeds, ± the half-width of its 95 % interval"
    if repositioner is not None:
        km = fmean(s.get("reposition_distance", 0.0) for s in summaries) / 1000
        title = f"Repositioner {repositioner!r} ({km:.0f} km repositioning per run). " + title
    t = _new_table(title, ["allocator", "N", *(c for c, *_ in _TRIP_FIGURES)], collapse=True)
    agg = {}
    for key, rows in groups.items():
        agg[key] = {"allocator": rows[0]["allocator"], "batch_window": _window(rows[0]),
                    "runs": len(rows),
                    "figures": [(_ci(rows, value), digits, scale, unit)
                                for _, digits, scale, unit, value in _TRIP_FIGURES]}
    for a, n, r, last in _grouped_rows(agg):
        several = r["runs"] > 1
        t.add_row(a, str(n), *(_f(m, d, sc, u) for (m, _), d, sc, u in r["figures"]),
                  end_section=last and not several)
        if several:  # the interval under its mean, in the same columns (80 columns still)
            t.add_row("", "", *("" if math.isnan(h) else "±" + _f(h, d, sc, u)
                                for (_, h), d, sc, u in r["figures"]), style="dim",
                      end_section=last)
    _show(console, t)
    if any(_pooled(r) for r in summaries):
        _render_shared(groups, runs, console)
    if any(electric(r) for r in summaries):
        _render_energy(groups, runs, console)


def _pooled(s: dict) -> bool:
    """A run whose vehicles could carry more than one request (some ride was shared, or more
    passenger-metres than occupied metres)."""
    return bool(s.get("shared_rate", 0.0) == s.get("shared_rate", 0.0)
                and s.get("shared_rate", 0.0) > 0) or s.get("occupancy", 0.0) > 1.0


def _render_shared(groups: dict, runs: int, console) -> None:
    """The shared-ride table of pooled runs (MATSim DRT's occupancy)."""
    title = (f"Shared rides, mean over {runs} seed(s): occupancy (passenger-km / vehicle-km), "
             "share of completed rides shared, delay (drop-off - release - direct drive, s), "
             "detour (in-vehicle time / direct drive)")
    t = _new_table(title, ["allocator", "N", "occupancy", "shared", "delay", "detour"])
    agg = {key: {"allocator": rows[0]["allocator"], "batch_window": _window(rows[0]),
                 "occ": _mean(rows, "occupancy"), "shared": _mean(rows, "shared_rate"),
                 "delay": _mean(rows, "delay_mean"), "detour": _mean(rows, "detour_ratio")}
           for key, rows in groups.items()}
    for a, n, r, last in _grouped_rows(agg):
        t.add_row(a, str(n), _f(r["occ"], 2), _f(r["shared"], 1, 100, "%"), _f(r["delay"]),
                  _f(r["detour"], 2), end_section=last)
    _show(console, t)


def _render_energy(groups: dict, runs: int, console) -> None:
    """The energy table of electric runs (:data:`dispatch.output.energy.ENERGY_FIGURES`)."""
    title = (f"Energy, mean over {runs} seed(s): kWh drawn and charged per vehicle, charges "
             "(plug-ins), hours queued at stations, lowest state of charge of any vehicle "
             "and the fleet's mean at the end (%), vehicles stranded (battery empty)")
    t = _new_table(title, ["allocator", "N", *(c for c, *_ in ENERGY_FIGURES)], collapse=True)
    agg = {key: {"allocator": rows[0]["allocator"], "batch_window": _window(rows[0]),
                 "figures": [(_mean([{"v": value(r)} for r in rows if electric(r)], "v"), d, sc)
                             for _, d, sc, value in ENERGY_FIGURES]}
           for key, rows in groups.items()}
    for a, n, r, last in _grouped_rows(agg):
        t.add_row(a, str(n), *(_f(m, d, sc) for m, d, sc in r["figures"]), end_section=last)
    _show(console, t)


def render_one(s: dict, console=None, *, dynamic: bool = False) -> None:
    """Print one run's summary, one ``key: value`` line each (wrapped, never cut)."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    t = Table(title=f"One run of {s['scenario']}", box=None, show_header=False, padding=(0, 1),
              title_justify="left")
    t.add_column("key", no_wrap=True, style="bold")
    t.add_column("value", overflow="fold")
    n, done = s["n_tasks"], s["tasks_completed"]
    share = f" ({100 * done / n:.1f} %)" if n else ""
    road = s.get("space") == "road"
    window = f", batch window {_window(s):g} s" if _window(s) else ""
    t.add_row("run", f"{s['allocator']} / {s['planner']}, N = {s['n_agents']}, seed "
                     f"{s['seed']}, {s.get('space', 'voxel')}{window}")
    what = "trips" if road else "tasks"
    rejected = s["tasks_rejected"] + s["tasks_expired"] + s.get("tasks_unreachable", 0)
    # tasks_cut_off: the tasks the run's end cut off (a count of its own, not a rejection)
    t.add_row(what, f"{n} released, {done} served{share}, {s['tasks_cut_off']} cut off by "
                    f"the end of the run (still waiting or {'aboard' if road else 'under way'}"
                    f"); rejected {s['tasks_rejected']} at once, expired "
                    f"{s['tasks_expired']}, unreachable {s.get('tasks_unreachable', 0)} "
                    f"(rejections {rejected}); failed {s.get('tasks_failed', 0)}")
    if s.get("offers", 0):  # offers riders may decline (dispatch.api.acceptor)
        t.add_row("offers", f"{s['offers']} made, {s['tasks_declined']} riders declined; "
                            f"revenue {_f(s['revenue'])}")
    t.add_row("wait", f"{_f(s['wait_time_mean'])} s mean, release to pickup")
    per = per_task(s)["cost_per_assignment"]
    if road or dynamic:
        what = ("time added to the vehicle's plan" if s.get("objective") == "added_time"
                else "vehicle to pickup")
        t.add_row("planned cost", f"{_f(per, 2)} s per assignment ({what})")
    else:
        t.add_row("total cost", f"{_f(s['total_cost'])} s (Table I: sum of the planned costs)")
    if not road:
        t.add_row("conflict-free", f"{_f(s['conflict_free_rate'], 1, 100)} % of the tasks "
                                   "offered (Table III)")
    km = s.get("distance", math.nan) / 1000
    empty = ratio(s.get("empty_distance", math.nan), s.get("distance", math.nan))
    fleet = f"{_f(km, 1)} km driven"
    if road:
        fleet += f", {_f(empty, 1, 100)} % of it empty"
    t.add_row("fleet", fleet)
    if road and _pooled(s):
        t.add_row("shared rides", f"occupancy {_f(s['occupancy'], 2)} (passenger-km / "
                                  f"vehicle-km), {_f(s['shared_rate'], 1, 100)} % of rides "
                                  f"shared, delay {_f(s['delay_mean'])} s mean, detour ratio "
                                  f"{_f(s['detour_ratio'], 2)}")
    if s.get("meeting_points", 0):  # meeting points (dispatch.decide.meeting)
        t.add_row("walking", f"{_f(s['walk_mean'], 0)} m walked per ride (to board plus from "
                             f"alighting); {s['meeting_points']} candidate points, "
                             f"{s['meeting_cut']} left out by tasks.meeting_points")
    if s.get("riders"):  # [transit] (dispatch.decide.riders)
        t.add_row("riders", f"{s['riders_served']} of {s['riders']} served: door to door "
                            f"{_f(s['mode_share_fleet'], 1, 100)} %, fleet then train "
                            f"{_f(s['mode_share_fleet_train'], 1, 100)} %, train then fleet "
                            f"{_f(s['mode_share_train_fleet'], 1, 100)} %, train "
                            f"{_f(s['mode_share_train'], 1, 100)} %; "
                            f"{_f(s['vehicle_km_per_rider'], 2)} vehicle-km per rider served, "
                            f"door to door {_f(s['door_to_door_median'])} s median, "
                            f"{s['missed_connections']} missed connections")
    if s.get("promises", 0):  # prebooking (dispatch.decide.prebook)
        t.add_row("promises", f"{s['promises']} booked rides promised, "
                              f"{s['promises_broken']} broken")
    hours = s.get("vehicle_hours", math.nan)
    if hours < s["n_agents"] * s["sim_time"] / 3600 - 1e-9 or s.get("shift_overruns", 0):
        # shifts or sizing took vehicles off duty (dispatch.fleet.shifts)
        t.add_row("shifts", f"{_f(hours, 1)} vehicle-hours on duty, "
                            f"{_f(s['riders_per_vehicle_hour'], 2)} riders per vehicle-hour, "
                            f"{s.get('shift_overruns', 0)} home late")
    if road and s.get("reposition", "stay") != "stay":
        t.add_row("repositioning", f"{s['reposition']}: {s.get('repositions', 0)} drives, "
                                   f"{_f(s.get('reposition_distance', 0.0) / 1000, 1)} km")
    if electric(s):
        t.add_row("energy", energy_line(s))
    if s.get("reassignments"):
        t.add_row("reassigned", f"{s['reassignments']} times a vehicle on its way to a pickup "
                                "was given another task")
    t.add_row("deciding", f"{s['decisions']} decisions, {_f(s['alloc_seconds'], 3)} s wall "
                          f"(first: {_f(s['first_decision_seconds'], 1, 1000)} ms)")
    t.add_row("simulated", f"{_f(s['sim_time'])} s")
    _show(console, t)


def print_tables(summaries: list[dict], console=None, *, dynamic: bool = False) -> None:
    """What ``dispatch run`` / ``sweep`` print: one run's summary, or the tables of many
    (voxel and road runs apart)."""
    if len(summaries) == 1:
        render_one(summaries[0], console, dynamic=dynamic)
        return
    voxel = [s for s in summaries if s.get("space", "voxel") == "voxel"]
    roads = [s for s in summaries if s.get("space") == "road"]
    if voxel:
        render(voxel, console, dynamic=dynamic)
    if roads:
        render_trips(roads, console)

