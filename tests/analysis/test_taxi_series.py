"""A taxi report over runs that differ by batch window (scenario variants) and repositioner,
not only by allocator: every series keeps its own row and its own line.

The run is tests/analysis/test_taxi_metrics.py's tiny road (4 trips, 2 taxis), swept over
``batch_window = [0, 30]`` and ``reposition = ["stay", "demand"]``: four series of one fcfs
run each, every one with the same 4 requests.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from analysis import metrics as M
from analysis import taxi_plots as TP
from analysis.io import open_results
from analysis.report import write_report
from dispatch.scenario import load_scenario
from tests.analysis.helpers import run_tiny_road

LABELS = ["fcfs imm", "fcfs imm + demand", "fcfs 30s", "fcfs 30s + demand"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = run_tiny_road(tmp_path_factory.mktemp("tiny_swept"), "tiny",
                        '[sweep]\nbatch_window = [0.0, 30.0]\nreposition = ["stay", "demand"]\n')
    return open_results(out), out


def test_variant_names():
    assert TP.variant_name("chicago_taxi-immediate") == "imm"
    assert TP.variant_name("chicago_taxi-batch30s") == "30s"
    assert TP.variant_name("manhattan") == "manhattan"
    assert TP.scenario_title(["c-batch30s", "c-immediate"]) == "c (imm, 30s)"
    assert TP.scenario_title(["a", "b"]) == "a, b"


def test_taxi_table_has_a_row_per_series(swept):
    res, _ = swept
    s = res.summary
    assert len(s) == 4
    taxi = M.taxi_metrics(s, res.table("tasks"), res.table("vehicles"), res.table("events"))
    keys = list(zip(taxi["scenario"], taxi["reposition"]))
    assert keys == [("tiny-immediate", "stay"), ("tiny-immediate", "demand"),
                    ("tiny-batch30s", "stay"), ("tiny-batch30s", "demand")]
    assert list(taxi["runs"]) == [1, 1, 1, 1]
    assert list(taxi["requests"]) == [4, 4, 4, 4]  # each series its own 4 trips, not pooled
    # the immediate run without repositioning is test_taxi_metrics' hand-computed run
    first = taxi.iloc[0]
    assert (first["rides"], first["rejections"]) == (3, 1)
    assert first["wait_average"] == pytest.approx(10)


def test_report_series_and_legend_labels(swept, tmp_path):
    res, _ = swept
    write_report(res, tmp_path)
    taxi = pd.read_csv(tmp_path / "taxi.csv")
    assert len(taxi) == 4
    assert set(zip(taxi["scenario"], taxi["reposition"])) == {
        (f"tiny-{v}", r) for v in ("immediate", "batch30s") for r in ("stay", "demand")}
    text = (tmp_path / "report.md").read_text()
    table = [ln for ln in text.splitlines() if ln.startswith("| fcfs")]
    assert len(table) == 4 and all("tiny-" in ln for ln in table)
    hc = pd.read_csv(tmp_path / "hourly_customers.csv")
    hf = pd.read_csv(tmp_path / "hourly_fleet.csv")
    for df in (hc, hf):  # what hourly.png and fleet_state.png draw: one line / panel each
        assert [label for _, label, _ in TP.series(df)] == LABELS
    assert hc.groupby(["scenario", "reposition"])["requests"].sum().tolist() == [4] * 4
    trips = M.with_series(M.trip_table(res.table("tasks")), res.summary)
    assert [label for _, label, _ in TP.series(trips)] == LABELS  # wait_by_allocator.png


def test_series_labels_name_only_what_differs():
    df = pd.DataFrame({"allocator": ["greedy", "fcfs", "fcfs", "greedy"],
                       "n_agents": [5, 5, 10, 10], "scenario": ["s"] * 4,
                       "planner": ["dijkstra"] * 4, "reposition": [None] * 4})
    assert [lab for _, lab, _ in TP.series(df)] == ["greedy N=5", "greedy N=10", "fcfs N=5",
                                                    "fcfs N=10"]


TINY = ('name = "tiny"\nduration = 1000.0\n[world]\nnetwork = "manhattan"\nblocks = [3, 2]\n'
        'block = 100.0\nspeed = 10.0\n[fleet]\nstart = "fleet.csv"\n[tasks]\nsource = "trace"\n'
        'trace = "trips.csv"\n[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\n')


@pytest.fixture(scope="module")
def two_texts(tmp_path_factory):
    """One folder, runs of two scenario texts (as chicago_study.py called twice with other
    lists): fcfs (one run) and greedy + demand (two seeds, so two runs of one series)."""
    from dispatch.runner import sweep

    d = tmp_path_factory.mktemp("two_texts")
    (d / "trips.csv").write_text("t,origin_node,dest_node,max_wait\n0,0,2,\n1,3,5,\n"
                                 "2,4,3,5\n30,1,0,\n")
    (d / "fleet.csv").write_text("vehicle_id,node\n0,0\n1,5\n")
    (d / "a.toml").write_text(TINY + '[sweep]\nallocator = ["fcfs"]\nreposition = ["stay"]\n')
    (d / "b.toml").write_text(TINY + '[sweep]\nallocator = ["greedy"]\n'
                              'reposition = ["demand"]\nseed = [0, 1]\n')
    out = d / "out"
    for name in ("a.toml", "b.toml"):
        assert all(o.status == "done" for o in sweep(load_scenario(d / name).runs(), out,
                                                      workers=1))
    return out


def test_hourly_plot_draws_one_runs_counts_per_series(two_texts, tmp_path, monkeypatch):
    """hourly.png of a folder holding runs of two scenario texts: the bars are one run's
    requests (4, the trace), each series' line its mean per run (3 served of 4 in every run
    here), not the sum over the runs or the series of the folder."""
    from analysis import taxi_plots

    res = open_results(two_texts)
    assert len(res.summary) == 3
    figures = {}
    real = taxi_plots._save

    def keep(fig, path):
        figures[Path(path).name] = fig
        return real(fig, path)

    monkeypatch.setattr(taxi_plots, "_save", keep)
    write_report(res, tmp_path)
    hc = pd.read_csv(tmp_path / "hourly_customers.csv")
    per_series = hc.set_index("allocator")
    assert per_series.loc["fcfs", "runs"] == 1 and per_series.loc["greedy", "runs"] == 2
    assert per_series.loc["greedy", "requests"] == 8  # the CSV sums the series' two runs
    top = figures["hourly.png"].axes[0]
    bars = [b.get_height() for b in top.patches]
    assert bars == [4.0]  # one run's requests (the trace's 4), once
    lines = {ln.get_label(): ln.get_ydata() for ln in top.get_lines()}
    assert sorted(lines) == ["fcfs", "greedy + demand"]
    assert list(lines["fcfs"]) == [3.0] and list(lines["greedy + demand"]) == [3.0]
    assert (tmp_path / "hourly.png").stat().st_size > 10_000


def test_hourly_plot_of_series_with_different_demand_draws_each_its_own():
    """Series that saw different requests (other scenario texts, other demand) each get
    their own dotted requests line, not the first series' bars."""
    from analysis import taxi_plots

    hc = pd.DataFrame({"allocator": ["fcfs", "fcfs"], "n_agents": [2, 2],
                       "scenario": ["low", "high"], "planner": ["dijkstra"] * 2,
                       "reposition": ["stay"] * 2, "hour": [0, 0], "t_h": [0.0, 0.0],
                       "runs": [1, 2], "requests": [800, 3200], "rides": [700, 3000],
                       "rejectionRate": [0.1, 0.05], "wait_median": [60.0, 60.0],
                       "wait_p90": [120.0, 120.0]})
    got = {label: (g["requests"].tolist(), g["rides"].tolist())
           for label, g in taxi_plots.per_run(hc)}
    assert got == {"fcfs low": ([800.0], [700.0]), "fcfs high": ([1600.0], [1500.0])}
    assert not taxi_plots._same_demand(taxi_plots.per_run(hc))
