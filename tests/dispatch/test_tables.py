"""The CLI's tables at 80 columns: no cell cut short with an ellipsis, every allocator's name in
full, no line wider than the terminal."""

from __future__ import annotations

import io
import itertools

import pytest

from dispatch.output.printed import aggregate, print_tables

ALLOCATORS = [
    "hungarian",
    "magnnet",
    "magnnet_edge",
    "magnnet_match",
    "auction",
    "greedy",
    "fcfs",
    "random",
]


def _summary(alloc: str, n: int, seed: int, space: str = "voxel") -> dict:
    k = ALLOCATORS.index(alloc)
    return {
        "scenario": "paper_dynamic",
        "allocator": alloc,
        "planner": "astar",
        "n_agents": n,
        "seed": seed,
        "space": space,
        "n_tasks": 12345,
        "total_cost": 123456.7 + k * 1000,
        "conflict_free_rate": 0.5 + 0.05 * k,
        "alloc_seconds": 123.456,
        "tasks_completed": 12000,
        "tasks_unfinished": 345,
        "makespan": 86400.0,
        "decisions": 9876,
        "rounds": 20000,
        "messages": 99999,
        "conflicts": 77,
        "cost_seconds": 100.0,
        "decide_seconds": 23.456,
        "first_decision_cost": 1234.5,
        "first_decision_seconds": 0.0123,
        "realized_travel": 123456.7,
        "wait_time_mean": 123.4,
        "tasks_expired": 100,
        "tasks_rejected": 200,
        "tasks_unreachable": 0,
        "tasks_cut_off": 45,
        "tasks_failed": 0,
        "sim_time": 86400.0,
        "comm_delay": 0.0,
        "agent_seconds": 1.0,
        "distance": 123456789.0,
        "empty_distance": 23456789.0,
        "occupied_distance": 100000000.0,
        "failures": 0,
        "tasks_reassigned": 0,
        "tasks_transferred": 0,
        "tasks_assigned": 12100,
    }


def _render(summaries, **kw) -> str:
    from rich.console import Console

    buf = io.StringIO()
    console = Console(file=buf, width=80, force_terminal=False, color_system=None)
    print_tables(summaries, console, **kw)
    return buf.getvalue()


SWEEP = [
    _summary(a, n, s) for a, n, s in itertools.product(ALLOCATORS, [4, 8, 12, 20, 100], [0, 1, 2])
]


@pytest.mark.parametrize("kind", ["static", "dynamic", "road", "one voxel", "one road"])
def test_tables_fit_80_columns(kind):
    if kind == "road":
        runs = [dict(s, space="road") for s in SWEEP]
    elif kind.startswith("one"):
        runs = [dict(SWEEP[0], space=kind.split()[1])]
    else:
        runs = SWEEP
    text = _render(runs, dynamic=kind == "dynamic")
    assert "…" not in text and "..." not in text, text
    assert max(len(line) for line in text.splitlines()) <= 80
    if not kind.startswith("one"):
        for a in ALLOCATORS:
            assert f" {a} " in f" {text} ".replace("\n", " "), (a, text)
        assert "12345" in text  # the widest numbers are whole
    else:
        assert "12345 released" in text and "Table" not in text.split("\n")[0]


@pytest.mark.parametrize("kind", ["static", "road"])
def test_titles_are_paragraphs_of_the_terminal_width_without_trailing_spaces(kind):
    """A table's title is printed above it as a paragraph of the terminal's width (rich would
    wrap it to the table's, 48 columns for Table III, and pad its lines with spaces)."""
    runs = [dict(s, space="road") for s in SWEEP] if kind == "road" else SWEEP
    lines = _render(runs).splitlines()
    starts = [i for i, line in enumerate(lines)
              if line.startswith(("Table I", "Trips,", "Shared rides,", "Energy,"))]
    assert len(starts) == (1 if kind == "road" else 2), lines
    for i in starts:
        title = lines[i:next(j for j in range(i, len(lines))
                             if lines[j].split()[:1] == ["allocator"])]
        assert all(line == line.rstrip() for line in title), title
        assert len(title) >= 2 and max(len(line) for line in title) > 70, title


def test_static_and_dynamic_tables_say_what_they_measure():
    static = _render(SWEEP)
    dynamic = _render(SWEEP, dynamic=True)
    assert "Table I: total travel cost" in static and "gap" in static
    assert "Table I (dynamic): per task" in dynamic and "gap" not in dynamic
    assert "served" in dynamic and "wait" in dynamic and "ms/decision" in dynamic


def test_dynamic_aggregate_by_hand():
    runs = [
        dict(
            _summary("greedy", 4, s),
            n_tasks=10,
            tasks_completed=5 + 5 * s,
            total_cost=20.0 * (s + 1),
            tasks_assigned=10,
            alloc_seconds=0.1 * (s + 1),
            decisions=10,
        )
        for s in (0, 1)
    ]
    a = aggregate(runs)[("greedy", 4)]
    assert a["served_share"] == pytest.approx(0.75)  # 5/10 and 10/10
    assert a["cost_per_assignment"] == pytest.approx(3.0)  # 2 and 4 s
    assert a["decision_ms"] == pytest.approx(15.0)  # 10 and 20 ms


def _variant_runs() -> list[dict]:
    """Two batch windows (a run key) of one scenario, 0 and 30 s: Hungarian costs 100 in one
    and 80 in the other, greedy 10 % more than Hungarian in both."""
    out = []
    for window, ref in ((0.0, 100.0), (30.0, 80.0)):
        for alloc, factor in (("hungarian", 1.0), ("greedy", 1.1)):
            for seed in (0, 1):
                out.append({**_summary("hungarian", 8, seed), "scenario": "chicago",
                            "batch_window": window, "allocator": alloc,
                            "total_cost": ref * factor * (1 + seed)})
    return out


def test_gap_is_paired_within_a_batch_window():
    """The reference is the Hungarian run of the same scenario, batch window, planner, N and
    seed: Hungarian is 0 % from itself and greedy +10 % at both windows (keyed without the
    window, one window's Hungarian would be the other's reference: -20 % / +25 %)."""
    agg = aggregate(_variant_runs())
    assert set(agg) == {("hungarian imm", 8), ("hungarian 30s", 8), ("greedy imm", 8),
                        ("greedy 30s", 8)}
    for label in ("hungarian imm", "hungarian 30s"):
        assert agg[(label, 8)]["gap"] == pytest.approx(0.0)
    for label in ("greedy imm", "greedy 30s"):
        assert agg[(label, 8)]["gap"] == pytest.approx(0.1)
    text = _render(_variant_runs())
    assert "+10.0%" in text and "-20" not in text and "+25" not in text


def test_tables_and_analysis_share_one_gap_and_order():
    """The CLI's tables and analysis.metrics compute the same paired gaps and the same
    allocator order (one definition: paired.compare)."""
    pd = pytest.importorskip("pandas")
    from analysis import metrics as M
    from dispatch.output import printed as tables
    from paired import compare
    runs = _variant_runs()
    assert list(M.paired_gaps(pd.DataFrame(runs))) == pytest.approx(compare.paired_gaps(runs))
    assert tables.allocator_order is compare.allocator_order is M.allocator_order
    am = M.allocator_metrics(pd.DataFrame(runs)).set_index(["batch_window", "allocator"])
    assert len(am) == 4
    agg = aggregate(runs)
    for (window, alloc), row in am.iterrows():
        label = f"{alloc} {compare.window_label(window)}"
        assert row["gap_mean"] == pytest.approx(agg[(label, 8)]["gap"])


def test_trip_table_shows_cut_off_trips_and_fits_with_variant_labels():
    """The trip table has a column of the trips the run's end cut off (summary
    ``tasks_cut_off``; served + rejected + cut off + failed add up to the trips), named so,
    and fits 80 columns uncut with the longest labels (a swept batch window)."""
    rows = []
    for a, n, s in itertools.product(["local_hungarian", "magnnet_match", "fcfs"],
                                     [100, 1000], [0, 1]):
        for window in (0.0, 30.0):
            rows.append({**_summary("hungarian", n, s, "road"), "allocator": a,
                         "batch_window": window, "n_tasks": 1000, "tasks_completed": 900,
                         "tasks_rejected": 40, "tasks_expired": 20, "tasks_unreachable": 0,
                         "tasks_cut_off": 38, "tasks_failed": 2})
    text = _render(rows)
    assert "…" not in text and max(map(len, text.splitlines())) <= 80
    line = next(ln for ln in text.splitlines() if ln.split()[:2] == ["local_hungarian", "30s"])
    assert line.split()[4:7] == ["90.0%", "6.0%", "3.8%"], line
    assert " cut " in text and "cut off (still waiting or aboard when the run ended)" in " ".join(
        text.split()) and "canc" not in text


def test_shared_ride_table_with_variants():
    """Pooled road runs get the shared-ride table too, rows ordered and labelled as the trip
    table's (allocator, then batch window)."""
    rows = [{**_summary("hungarian", 10, s, "road"), "allocator": a, "batch_window": w,
             "shared_rate": 0.3, "occupancy": 1.4, "delay_mean": 60.0, "detour_ratio": 1.2}
            for a in ("fcfs", "hungarian") for w in (0.0, 30.0)
            for s in (0, 1)]
    text = _render(rows)
    shared = text[text.index("Shared rides"):]
    labels = [ln.split()[:2] for ln in shared.splitlines() if ln.split()[:1] in (["fcfs"],
                                                                              ["hungarian"])]
    assert labels == [["hungarian", "imm"], ["hungarian", "30s"], ["fcfs", "imm"],
                      ["fcfs", "30s"]]


def test_tables_and_analysis_share_one_set_of_per_task_figures():
    """The CLI's tables and analysis.metrics read each run's per-task figures from one
    definition (paired.per_task): the same means, a zero or missing denominator giving NaN
    in both (not a division error, not 0)."""
    import math

    pd = pytest.importorskip("pandas")
    from analysis import metrics as M
    from paired.per_task import PER_TASK, per_task

    runs = []
    for seed, (done, assigned, decisions) in enumerate(((12000, 400, 9876), (11000, 0, 0),
                                                        (0, None, 5))):
        s = {**_summary("greedy", 8, seed), "tasks_completed": done, "wait_time_mean": 30.0 + seed,
             "tasks_assigned": assigned, "decisions": decisions}
        runs.append(s)
    got = [per_task(s) for s in runs]
    assert got[0] == {"served_share": 12000 / 12345, "wait_mean": 30.0,
                      "cost_per_assignment": runs[0]["total_cost"] / 400,
                      "decision_ms": 1000 * 123.456 / 9876}
    assert math.isnan(got[1]["cost_per_assignment"]) and math.isnan(got[1]["decision_ms"])
    assert got[2]["served_share"] == 0.0 and math.isnan(got[2]["cost_per_assignment"])
    dm = M.dynamic_metrics(pd.DataFrame(runs)).iloc[0]
    agg = aggregate(runs)[("greedy", 8)]
    for name, key in zip(PER_TASK, ("served_share", "wait", "cost_per_assignment",
                                    "decision_ms")):
        values = [g[name] for g in got]
        mean = sum(values) / len(values)  # NaN where a run's figure is NaN
        assert dm[f"{name}_mean"] == pytest.approx(
            sum(v for v in values if not math.isnan(v)) / sum(not math.isnan(v) for v in values))
        if name == "wait_mean":
            assert agg[key] == pytest.approx(mean)
        else:  # the CLI's mean over seeds keeps a NaN (a run without the figure)
            assert (math.isnan(agg[key]) and math.isnan(mean)) or agg[key] == pytest.approx(mean)


ENERGY = {"kwh_drawn": 2400.0, "kwh_charged": 900.0, "charges": 37, "strandings": 1,
          "soc_min": 0.123, "soc_end_mean": 0.456, "queue_seconds": 7200.0,
          "kwh_auxiliary": 300.0}


def test_one_road_run_says_cut_off_trips_and_its_energy():
    """One run's summary counts the trips the run's end cut off on their own (not as
    cancelled) and, with energy, prints its energy line: kWh drawn and charged, charges,
    queueing, lowest and end state of charge, strandings."""
    s = {**_summary("hungarian", 1200, 0, "road"), **ENERGY}
    text = " ".join(_render([s]).split())
    assert "12000 served (97.2 %), 45 cut off by the end of the run (still waiting or aboard)" \
        in text and "cancel" not in text
    # the driving part and the auxiliary load's apart (the kWh per km of driving is the first
    # over the km); a summary written before the auxiliary column: no split
    assert ("energy 2,400.0 kWh drawn (2.00 kWh per vehicle; 2,100.0 kWh driving, 300.0 kWh "
            "the auxiliary load), 900.0 kWh charged in 37 charges, 2.0 h queued; state of "
            "charge lowest 12.3%, mean at the end 45.6%; 1 vehicle stranded") in text
    old = {k: v for k, v in s.items() if k != "kwh_auxiliary"}
    assert "energy 2,400.0 kWh drawn (2.00 kWh per vehicle), 900.0 kWh charged" in " ".join(
        _render([old]).split())
    plain = _render([_summary("hungarian", 1200, 0, "road")])
    assert "energy" not in plain and "kWh" not in plain


def test_electric_runs_get_an_energy_table_that_fits_80_columns():
    """Several electric runs: the energy table, per vehicle and means over the seeds (by
    hand), rows as the trip table's, within 80 columns."""
    rows = [{**_summary("hungarian", n, seed, "road"), **ENERGY, "allocator": a,
             "charges": 30 + 10 * seed, "kwh_drawn": 2400.0 + 600.0 * seed}
            for a in ("local_hungarian", "fcfs") for n in (800, 1200) for seed in (0, 1)]
    text = _render(rows)
    assert "…" not in text and max(map(len, text.splitlines())) <= 80
    energy = text[text.index("Energy, mean over 2 seed(s)"):]
    line = next(ln for ln in energy.splitlines() if ln.split()[:2] == ["local_hungarian", "800"])
    # (2400 + 3000) / 2 / 800 kWh per vehicle, 900 / 800 charged, (30 + 40) / 2 charges,
    # 2 h queued, 12.3 % lowest, 45.6 % at the end, 1 stranded
    assert line.split()[2:] == ["3.38", "1.12", "35", "2.0", "12.3", "45.6", "1"], line
    assert "Energy" not in _render([_summary("fcfs", 8, s, "road") for s in (0, 1)])


def test_one_run_says_walks_promises_and_shifts_only_where_used():
    """The demand-responsive features each get a line of one run's summary where the run
    used them: metres walked (meeting points), promises kept and broken (prebooking),
    vehicle-hours on duty (shifts: fewer than the whole fleet all run)."""
    base = _summary("hungarian", 1200, 0, "road")
    full = base["n_agents"] * base["sim_time"] / 3600
    plain = " ".join(_render([{**base, "vehicle_hours": full, "meeting_points": 0,
                               "promises": 0}]).split())
    assert "walking" not in plain and "promises" not in plain and "shifts" not in plain
    s = {**base, "walk_mean": 215.4, "meeting_points": 5510, "meeting_cut": 6176,
         "promises": 207, "promises_broken": 1, "vehicle_hours": full / 2,
         "riders_per_vehicle_hour": 2.5, "shift_overruns": 3}
    text = " ".join(_render([s]).split())
    assert ("walking 215 m walked per ride (to board plus from alighting); 5510 candidate "
            "points, 6176 left out by tasks.meeting_points") in text
    assert "promises 207 booked rides promised, 1 broken" in text
    assert f"shifts {full / 2:.1f} vehicle-hours on duty, 2.50 riders per vehicle-hour, " \
           "3 home late" in text
