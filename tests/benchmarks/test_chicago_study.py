"""benchmarks/chicago_study.py: the derived scenario, the 80-column table and the findings
paragraph, against hand-made numbers (the study itself is run by hand, not here)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pandas as pd
import pytest

from dispatch.scenario.load import load_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def study():
    spec = importlib.util.spec_from_file_location("chicago_study",
                                                  ROOT / "benchmarks" / "chicago_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_derived_scenario(study, tmp_path):
    a = study.parse_args(["--hours", "3", "--trips-per-day", "1000", "--agents", "20", "40"])
    path = tmp_path / "s.toml"
    path.write_text(study.derived_text(a, ["fcfs", "greedy"], ["stay", "demand"]))
    sc = load_scenario(path)
    assert sc.duration == 3 * 3600
    assert sc.tasks.trips_per_day == 1000
    runs = sc.runs()
    assert len(runs) == 2 * 2 * 2 * 2 * 3  # N x allocator x window x repositioner x seed
    assert {r.scenario.name for r in runs} == {"chicago_study"}
    assert {r.batch_window for r in runs} == {0.0, 30.0}
    assert {r.seed for r in runs} == {0, 1, 2}
    assert {(r.allocator, r.agents, r.reposition) for r in runs} == {
        (al, n, rp) for al in ("fcfs", "greedy") for n in (20, 40) for rp in ("stay", "demand")}
    full = study.parse_args([])
    assert "duration = 93600.0" in study.derived_text(full, ["fcfs"], ["stay"])


def _table():
    rows = []
    for alloc, base in (("fcfs", 300.0), ("hungarian", 240.0)):
        for window, dw in (("imm", 0.0), ("30s", 30.0)):
            for rep, dr in (("stay", 0.0), ("demand", -100.0)):
                label = f"{alloc} {window}" + (" + demand" if rep == "demand" else "")
                rows.append({"label": label + " and a very long tail", "allocator": alloc,
                             "N": 200, "window": window, "reposition": rep, "runs": 1,
                             "served": 0.8, "rejected": 0.2 - (0.05 if window == "30s" else 0),
                             "wait_mean": base + dw + dr, "wait_p90": 2 * base,
                             "utilization": 0.5, "empty": 0.1 + (0.05 if rep == "demand" else 0),
                             "wall_s": 12.3})
    return pd.DataFrame(rows)


def test_table_fits_80_columns(study):
    text = study.text_table(_table())
    assert max(len(line) for line in text.splitlines()) <= 80
    assert len(text.splitlines()) == 2 + 8


def test_findings_by_hand(study):
    para = study.findings(_table())
    # best: hungarian imm + demand, 240 - 100 = 140 s; best other allocator: fcfs imm + demand
    # 200 s, 60 s (30 %) more; worst: fcfs 30s 330 s
    assert "lowest mean wait hungarian imm + demand and a very long tail (140 s" in para
    assert "60 s (30 %) below the best other allocator" in para
    assert "highest fcfs 30s and a very long tail (330 s)" in para
    # batching: +30 s in all 4 pairs, rejection -5 points in all 4
    assert "mean wait lower in 0 of 4 pairs (allocator, N, repositioner), change +30 s" in para
    assert "rejection rate lower in 4 of 4, -5.0 points" in para
    # repositioning: -100 s in all 4 pairs, empty share +5 points
    assert "mean wait lower in 4 of 4 pairs (allocator, N, window), change -100 s" in para
    assert "empty share of the km +5.0 points" in para


def test_rerun_with_other_lists_resumes_the_runs_it_shares(study, tmp_path):
    """Calling the study again with other --allocators / --repositioners / --agents writes
    another derived text, but a run both calls make is the same run (run_digest), under the
    same scenario names: the sweep skips it and adds only the missing ones."""
    from dispatch.run.resume import run_digest

    def specs(args, allocs, reps, name):
        a = study.parse_args(["--hours", "1", *args])
        path = tmp_path / name
        path.write_text(study.derived_text(a, allocs, reps))
        return {s.run_id: s for s in load_scenario(path).runs()}

    first = specs(["--agents", "500", "1000"], ["fcfs", "greedy", "hungarian"], ["stay"], "a")
    second = specs(["--agents", "1000"], ["hungarian", "greedy"], ["demand", "stay"], "b")
    shared = sorted(set(first) & set(second))
    assert len(shared) == 2 * 2 * 1 * 1 * 3  # hungarian, greedy x 2 windows x N = 1000 x stay
    # x 3 seeds
    assert {first[r].batch_window for r in shared} == {0.0, 30.0}
    for r in shared:
        assert run_digest(first[r]) == run_digest(second[r])
    assert len({run_digest(s) for s in second.values()}) == len(second)


def test_comm_range_sets_the_radio_range_and_makes_other_runs(study, tmp_path):
    """``--comm-range 2000`` gives the derived scenario ``[comms] range = 2000``; without it
    the range stays unlimited; the runs of the two are different runs (other digests)."""
    from dispatch.run.resume import run_digest

    def load(args, name):
        a = study.parse_args(["--hours", "1", "--agents", "500", *args])
        path = tmp_path / name
        path.write_text(study.derived_text(a, ["auction"], ["stay"]))
        return load_scenario(path)

    ranged, free = load(["--comm-range", "2000"], "r.toml"), load([], "f.toml")
    assert ranged.comms.range == 2000.0
    assert free.comms.range is None
    digests = {run_digest(s) for s in free.runs()}
    assert not digests & {run_digest(s) for s in ranged.runs()}
    for bad in ("-5", "inf", "nan"):
        with pytest.raises(SystemExit):
            study.parse_args(["--comm-range", bad])


def test_table_shows_conflicts(study):
    """The terminal table has the conflicts (tasks), the Markdown table also the conflict-free
    share; '-' where a run folder has none (older tables)."""
    t = _table().assign(conflicts=[0, 8712, 3, 0, 1, 2, 3, 4],
                        conflict_free=[1.0, 0.5, 0.875, 1, 1, 1, 1, 1])
    text = study.text_table(t)
    assert max(len(line) for line in text.splitlines()) <= 80
    head, _, first, second, *_ = text.splitlines()
    assert "confl." in head and "conflict-free" not in head
    assert first.split()[-2:] == ["0", "12.3"] and second.split()[-2:] == ["8712", "12.3"]
    md = study.markdown_table(t).splitlines()
    assert "| conflict-free |" in md[0]
    assert "| 8712 | 50.0% | 12.3 |" in md[3]
    assert "| - | - | 12.3 |" in study.markdown_table(_table()).splitlines()[2]


def test_three_seeds_intervals_and_cut_off(study):
    """Three seeds by default; the table shows the cut-off share (served + rejected + cut off
    add up) and 95 % intervals over seeds (terminal: served and wait; study.md: served,
    rejected, cut off and wait), still within 80 columns."""
    assert study.parse_args([]).seeds == [0, 1, 2]
    t = _table().assign(served=0.75, rejected=0.2, cut_off=0.05, served_ci=0.012,
                        rejected_ci=0.01, cut_off_ci=0.004, wait_mean_ci=12.4)
    text = study.text_table(t)
    assert max(len(line) for line in text.splitlines()) <= 80
    head, _, first, *_ = text.splitlines()
    assert "cut%" in head and "served%" in head
    assert first.split()[-8:-4] == ["75.0±1.2", "20.0", "5.0", "300±12"], first
    md = study.markdown_table(t).splitlines()
    assert "| cut% |" in md[0] and "| p90 |" in md[0]
    assert "| 75.0% ± 1.2 | 20.0% ± 1.0 | 5.0% ± 0.4 | 300 ± 12 |" in md[2]
