"""A taxi report over runs that differ by batch window (scenario variants) and repositioner,
not only by allocator: every series keeps its own row and its own line.

The run is tests/analysis/test_taxi_metrics.py's tiny road (4 trips, 2 taxis), swept over
``batch_window = [0, 30]`` and ``reposition = ["stay", "demand"]``: four series of one fcfs
run each, every one with the same 4 requests.
"""

from __future__ import annotations

import pandas as pd
import pytest

from analysis import metrics as M
from analysis import taxi_plots as TP
from analysis.io import open_results
from analysis.report import write_report
from dispatch.runner import execute
from dispatch.scenario import load_scenario

LABELS = ["fcfs imm", "fcfs imm + demand", "fcfs 30s", "fcfs 30s + demand"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiny_swept")
    (d / "trips.csv").write_text("t,origin_node,dest_node,max_wait\n0,0,2,\n1,3,5,\n"
                                 "2,4,3,5\n30,1,0,\n")
    (d / "fleet.csv").write_text("vehicle_id,node\n0,0\n1,5\n")
    path = d / "tiny.toml"
    path.write_text('name = "tiny"\nduration = 1000.0\n[world]\nnetwork = "manhattan"\n'
                    'blocks = [3, 2]\nblock = 100.0\nspeed = 10.0\n[fleet]\n'
                    'start = "fleet.csv"\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                    '[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\n'
                    '[sweep]\nbatch_window = [0.0, 30.0]\nreposition = ["stay", "demand"]\n')
    out = d / "out"
    execute(load_scenario(path).runs(), out)
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
