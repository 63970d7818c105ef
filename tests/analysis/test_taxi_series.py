"""A taxi report over runs that differ by batch window (a run key) and repositioner, not only by
allocator: every series keeps its own row and its own line; a folder written the old way (each
window a scenario variant ``tiny-immediate`` / ``tiny-batch30s``, no ``batch_window=``
partition) reads the same.

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
from dispatch.scenario.load import load_scenario
from paired.compare import window_label
from tests.analysis.helpers import run_tiny_road

LABELS = ["fcfs imm", "fcfs imm + demand", "fcfs 30s", "fcfs 30s + demand"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = run_tiny_road(tmp_path_factory.mktemp("tiny_swept"), "tiny",
                        '[sweep]\nbatch_window = [0.0, 30.0]\nreposition = ["stay", "demand"]\n')
    return open_results(out), out


def test_window_labels_and_titles():
    assert window_label(0.0) == "imm"
    assert window_label(30) == "30s" and window_label(2.5) == "2.5s"
    assert TP.scenario_title(["c", "c"]) == "c"
    assert TP.scenario_title(["b", "a"]) == "a, b"


def test_batch_window_is_a_partition_and_a_column(swept):
    res, out = swept
    leaves = {p.relative_to(out / "summary").parts[:5]
              for p in (out / "summary").rglob("part-0.parquet")}
    assert leaves == {("scenario=tiny", "allocator=fcfs", "planner=dijkstra", f"reposition={r}",
                       f"batch_window={w}") for r in ("stay", "demand") for w in ("0", "30")}
    s = res.summary
    assert set(s["scenario"]) == {"tiny"}
    assert sorted(s["batch_window"]) == [0.0, 0.0, 30.0, 30.0]
    assert s["run_id"].nunique() == 4  # one id per window
    assert res.run_keys == ["scenario", "allocator", "planner", "reposition", "batch_window",
                            "n_agents", "seed"]
    tasks = res.table("tasks")
    assert set(tasks["batch_window"]) == {0.0, 30.0} and set(tasks["scenario"]) == {"tiny"}
    few = res.table("summary", columns=["total_cost"])  # a few columns: the keys come along
    assert sorted(few["batch_window"]) == [0.0, 0.0, 30.0, 30.0]


def _old_layout(new: Path, old: Path) -> None:
    """``new`` rewritten as versions before the batch window was a run key wrote it: each
    window a scenario of its own (``scenario=tiny-immediate`` / ``tiny-batch30s``), no
    ``batch_window=`` level, no ``batch_window`` column, no ``dispatch.run_keys``."""
    import pyarrow.parquet as pq

    for f in new.rglob("part-0.parquet"):
        parts = list(f.relative_to(new).parts)
        if parts[0] == "_runs":
            continue
        level = next(p for p in parts if p.startswith("batch_window="))
        w = float(level.partition("=")[2])
        parts.remove(level)
        parts[1] = f"scenario=tiny-{'immediate' if w == 0 else f'batch{w:g}s'}"
        t = pq.read_table(f)
        assert "batch_window" not in t.column_names
        meta = {k: v for k, v in t.schema.metadata.items() if k != b"dispatch.run_keys"}
        dest = old.joinpath(*parts)
        dest.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(t.replace_schema_metadata(meta), dest)


def test_an_older_folder_of_variants_reads_as_batch_windows(swept, tmp_path):
    """Runs written with ``-immediate`` / ``-batch30s`` scenario names read as scenario
    ``tiny`` with their window: the same taxi table as the new layout's, row for row, and
    every table's rows of a run carry the name and the window."""
    res, out = swept
    _old_layout(out, tmp_path / "old")
    old = open_results(tmp_path / "old")
    assert old.run_keys == ["scenario", "allocator", "planner", "reposition", "batch_window",
                            "n_agents", "seed"]  # the fallback: the files do not say
    s = old.summary
    assert set(s["scenario"]) == {"tiny"}
    assert sorted(s["batch_window"]) == [0.0, 0.0, 30.0, 30.0]
    cols = ["scenario", "batch_window", "reposition", "requests", "rides", "wait_average"]
    args = ("tasks", "vehicles", "events")
    new_taxi = M.taxi_metrics(res.summary, *(res.table(t) for t in args))[cols]
    old_taxi = M.taxi_metrics(s, *(old.table(t) for t in args))[cols]
    pd.testing.assert_frame_equal(old_taxi, new_taxi)
    few = old.table("summary", columns=["total_cost"])
    assert set(few["scenario"]) == {"tiny"}
    assert sorted(few["batch_window"]) == [0.0, 0.0, 30.0, 30.0]
    ev = old.table("events")
    assert set(ev["scenario"]) == {"tiny"} and set(ev["batch_window"]) == {0.0, 30.0}
    rid = s.loc[s["batch_window"] == 30.0, "run_id"].iloc[0]
    assert "batch_window" in old.metadata(rid, "summary")["dispatch.scenario"]
    assert len(old.run(rid)["tasks"]) == 4


def test_taxi_table_has_a_row_per_series(swept):
    res, _ = swept
    s = res.summary
    assert len(s) == 4
    taxi = M.taxi_metrics(s, res.table("tasks"), res.table("vehicles"), res.table("events"))
    keys = list(zip(taxi["scenario"], taxi["batch_window"], taxi["reposition"]))
    assert keys == [("tiny", 0.0, "stay"), ("tiny", 0.0, "demand"),
                    ("tiny", 30.0, "stay"), ("tiny", 30.0, "demand")]
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
    assert set(zip(taxi["batch_window"], taxi["reposition"])) == {
        (w, r) for w in (0.0, 30.0) for r in ("stay", "demand")}
    text = (tmp_path / "report.md").read_text()
    table = [ln for ln in text.splitlines() if ln.startswith("| fcfs")]
    assert len(table) == 4 and {ln.split("|")[4].strip() for ln in table} == {"imm", "30s"}
    hc = pd.read_csv(tmp_path / "hourly_customers.csv")
    hf = pd.read_csv(tmp_path / "hourly_fleet.csv")
    for df in (hc, hf):  # what hourly.png and fleet_state.png draw: one line / panel each
        assert [label for _, label, _ in TP.series(df)] == LABELS
    assert hc.groupby(["batch_window", "reposition"])["requests"].sum().tolist() == [4] * 4
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
    from dispatch.run.runner import sweep

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
    res = open_results(two_texts)
    assert len(res.summary) == 3
    figures = _capture(monkeypatch)
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


# ----------------------------------------------------------------------------- 40 series


def _forty():
    """40 series (5 allocators x N 500, 1000 x immediate / 30 s x stay / demand) of made-up
    hourly customers, fleet states and waits; greedy and fcfs identical under immediate
    dispatch (one request at a time: the same choice)."""
    import numpy as np

    allocs = ["fcfs", "greedy", "hungarian", "auction", "magnnet"]
    hc, hf, wt = [], [], []
    for a in allocs:
        for n in (500, 1000):
            for w in (0.0, 30.0):
                for rep in ("stay", "demand"):
                    like = "fcfs" if a == "greedy" and w == 0 else a
                    k = allocs.index(like) + (5 if n == 500 else 0) + (10 if w else 0)
                    rng = np.random.default_rng(k + (20 if rep == "demand" else 0))
                    keys = dict(allocator=a, n_agents=n, scenario="study", batch_window=w,
                                planner="dijkstra", reposition=rep)
                    for h in range(6):
                        hc.append({**keys, "hour": h, "t_h": float(h), "runs": 3,
                                   "requests": 300.0, "rides": 280.0 - k,
                                   "rejectionRate": 0.01 * k + rng.uniform(0, 0.01),
                                   "wait_median": 100.0 + k, "wait_p90": 200.0 + k})
                        hf.append({**keys, "hour": h, "t_h": float(h), "idle": n / 2 - k,
                                   "to_pickup": n / 4, "occupied": n / 4 + k,
                                   "repositioning": 0.0, "failed": 0.0})
                    wt += [{**keys, "wait": w} for w in rng.gamma(2.0, 60 + k, size=50)]
    return pd.DataFrame(hc), pd.DataFrame(hf), pd.DataFrame(wt)


def _capture(monkeypatch):
    from analysis import taxi_plots

    figures = {}
    real = taxi_plots._save

    def keep(fig, path):
        figures[Path(path).name] = fig
        return real(fig, path)

    monkeypatch.setattr(taxi_plots, "_save", keep)
    return figures


def test_forty_series_are_small_multiples_with_twins_marked(tmp_path, monkeypatch):
    """hourly.png and the wait ECDF of 40 series: one panel per N / window / repositioner
    (8), the 5 allocators coloured alike in each (no colour reused within a panel), the
    identical series (greedy = fcfs, immediate) marked; fleet_state.png says which panel
    repeats which."""
    from analysis import taxi_plots as TP

    figures = _capture(monkeypatch)
    hc, hf, wt = _forty()
    assert len(TP.series(hc)) == 40
    TP.hourly(hc, tmp_path / "hourly.png", bin_s=3600)
    fig = figures["hourly.png"]
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 8 * 3
    titles = sorted(ax.get_title() for ax in visible if ax.get_title())
    assert len(titles) == 8 and "N=500 imm (stay)" in titles and "N=1000 30s + demand" in titles
    for ax in visible[::3][:1]:
        colours = [tuple(ln.get_color()) if not isinstance(ln.get_color(), str)
                   else ln.get_color() for ln in ax.get_lines()]
        assert len(set(colours)) == 5  # five allocators, five colours
    notes = [t.get_text() for ax in visible for t in ax.texts]
    assert notes.count("identical: fcfs = greedy") == 4  # the immediate panels
    legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert {"hungarian", "magnnet", "auction", "greedy", "fcfs"} <= set(legend)

    TP.wait_by_group(wt, tmp_path / "wait.png")
    fig = figures["wait.png"]
    ecdf = [ax for ax in fig.get_axes() if ax.get_visible() and ax.get_title()
            and "N=" in ax.get_title()]
    assert len(ecdf) == 8
    labels = [t.get_text() for ax in ecdf for t in ax.get_legend().get_texts()]
    assert sum(lab.endswith("= greedy") for lab in labels) == 4
    box = [ax for ax in fig.get_axes() if "Per series" in ax.get_title(loc="right")][0]
    ticks = [t.get_text() for t in box.get_yticklabels()]
    assert len(ticks) == 40 and "fcfs N=500 imm  (= greedy N=500 imm)" in ticks

    TP.fleet_state(hf, tmp_path / "fleet.png", bin_s=3600)
    titles = [ax.get_title() for ax in figures["fleet.png"].axes if ax.get_visible()]
    assert len(titles) == 40 and "fcfs N=500 imm\n(= greedy N=500 imm)" in titles
    for name in ("hourly.png", "wait.png", "fleet.png"):
        assert (tmp_path / name).stat().st_size > 50_000


def test_series_filter(tmp_path, monkeypatch):
    from analysis import taxi_plots as TP

    figures = _capture(monkeypatch)
    hc, _, wt = _forty()
    groups = TP.series(hc)
    assert [g[1] for g in TP.select(groups, ["hungarian*"])] == [
        g[1] for g in groups if g[1].startswith("hungarian")]
    assert len(TP.select(groups, ["* 30s*", "fcfs*"])) == 20 + 4
    assert TP.select(groups, None) == groups
    with pytest.raises(ValueError, match="no series matches 'nosuch'"):
        TP.select(groups, ["nosuch"])
    TP.hourly(hc, tmp_path / "h.png", bin_s=3600, only=["hungarian N=500*", "fcfs N=500*"])
    top = figures["h.png"].axes[0]  # 8 series: one panel set, as before
    assert sorted(ln.get_label() for ln in top.get_lines()) == sorted(
        g[1] for g in TP.select(groups, ["hungarian N=500*", "fcfs N=500*"]))


def test_colours_never_reused():
    from analysis.plots import _colours

    for n in (5, 15, 40):
        assert len(set(_colours([f"s{i}" for i in range(n)]).values())) == n
