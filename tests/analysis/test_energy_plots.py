"""The electric fleet in the analysis: charging states in the fleet states (from the events),
the SOC quantiles, and the report's energy pictures from a small run's Parquet files."""

from __future__ import annotations

import pandas as pd
import pytest

from analysis.energy_plots import soc_quantiles
from analysis.timeline import fleet_states


def test_charging_states_from_events():
    ev = pd.DataFrame({
        "run_id": "r", "t": [0.0, 10.0, 30.0, 50.0, 50.0, 90.0],
        "event": ["depart", "queue", "charge_start", "charge_end", "idle", "assign"],
        "agent_id": 0, "task_id": [-1, -1, -1, -1, -1, 3]})
    st = fleet_states(ev, pd.DataFrame({"run_id": ["r"], "agent_id": [0]}), end=100.0)
    assert st[["state", "start", "end"]].values.tolist() == [
        ["to_charger", 0.0, 10.0], ["queueing", 10.0, 30.0], ["charging", 30.0, 50.0],
        ["idle", 50.0, 90.0], ["to_pickup", 90.0, 100.0]]


def test_soc_quantiles():
    soc = pd.DataFrame({"run_id": "r", "k": "a", "t": [0.0] * 11,
                        "soc": [i / 10 for i in range(11)]})
    q = soc_quantiles(soc, ["k"]).iloc[0]
    assert (q["p10"], q["median"], q["p90"]) == pytest.approx((0.1, 0.5, 0.9))


def test_report_draws_the_energy_pictures(tmp_path):
    from analysis.report import write_report
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    (tmp_path / "st.csv").write_text("station_id,node,plugs,kw\nA,0,1,20\nB,99,2,20\n")
    p = tmp_path / "ev.toml"
    p.write_text('name = "ev"\nseed = 1\nduration = 9000.0\n[world]\nnetwork = "manhattan"\n'
                 'blocks = [10, 10]\nblock = 200.0\nspeed = 10.0\n[fleet]\nagents = 6\n'
                 '[fleet.energy]\nbattery_kwh = 2.0\nwh_per_km = 150.0\nsoc0 = 0.6\n'
                 'sample = 600.0\n[chargers]\nfile = "st.csv"\n[charging.threshold]\n'
                 'low = 0.3\nhigh = 0.9\n[tasks]\nsource = "poisson"\nrate = 0.01\ncount = 60\n'
                 'max_wait = 600.0\n[dispatch]\nallocator = "hungarian"\n', encoding="utf-8")
    [spec] = load_scenario(p).runs()
    run_one(spec, tmp_path / "runs")
    files = write_report(tmp_path / "runs", tmp_path / "rep")
    names = {f.name for f in files}
    assert {"soc.png", "stations.png", "soc.csv"} <= names
    q = pd.read_csv(tmp_path / "rep" / "soc.csv")
    assert q["t"].iloc[0] == 0.0 and q["median"].iloc[0] == pytest.approx(0.6)
    assert "stations.png" in (tmp_path / "rep" / "report.md").read_text()


def test_spread_keeps_order_spacing_and_bounds_by_brute_force():
    """Label positions: the targets' order, at least ``gap`` apart, inside [lo, hi] where
    they fit, and each on its target when no neighbour is within the gap."""
    import numpy as np

    from analysis.energy_plots import spread

    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(1, 20))
        targets = rng.uniform(0, 100, n)
        gap = float(rng.uniform(0.5, 8))
        p = spread(targets, gap, 0.0, 100.0)
        order = np.argsort(targets, kind="stable")
        assert (np.diff(p[order]) >= gap - 1e-9).all()
        if gap * (n - 1) <= 100:
            assert p.min() >= -1e-9 and p.max() <= 100 + 1e-9
        alone = [i for i in range(n) if all(abs(targets[i] - targets[j]) > 2 * n * gap
                                            for j in range(n) if j != i)]
        for i in alone:
            assert p[i] == pytest.approx(targets[i])


def test_queue_scale_starts_at_one_vehicle():
    from analysis.energy_plots import queue_scale

    assert queue_scale([pd.DataFrame({"mean_queue": [0.0, 0.0003]})]) == 1.0
    assert queue_scale([pd.DataFrame({"mean_queue": [0.2]}),
                        pd.DataFrame({"mean_queue": [2.5]})]) == 2.5


def _ev_scenario(d, name: str, energy: bool = True):
    d.mkdir(parents=True, exist_ok=True)
    (d / "st.csv").write_text("station_id,node,plugs,kw\nA,0,1,20\nB,99,2,20\nC,98,1,20\n")
    ev = ('[fleet.energy]\nbattery_kwh = 2.0\nwh_per_km = 150.0\nsoc0 = 0.6\nsample = 600.0\n'
          '[chargers]\nfile = "st.csv"\n[charging.threshold]\nlow = 0.3\nhigh = 0.9\n'
          if energy else "")
    p = d / f"{name}.toml"
    p.write_text(f'name = "{name}"\nseed = 1\nduration = 9000.0\n[world]\nnetwork = '
                 '"manhattan"\nblocks = [10, 10]\nblock = 200.0\nspeed = 10.0\n[fleet]\n'
                 f'agents = 6\n{ev}[tasks]\nsource = "poisson"\nrate = 0.01\ncount = 60\n'
                 'max_wait = 600.0\n[dispatch]\nallocator = "hungarian"\n[sweep]\n'
                 'allocator = ["hungarian", "greedy"]\n', encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def two_scenarios(tmp_path_factory):
    """An electric scenario (two allocators) and a plain one, run into one folder."""
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    d = tmp_path_factory.mktemp("two")
    for name, energy in (("ev", True), ("plain", False)):
        for spec in load_scenario(_ev_scenario(d / name, name, energy)).runs():
            run_one(spec, d / "runs")
    return d / "runs"


def _figures(monkeypatch):
    """Capture the figures the report draws (name -> matplotlib Figure)."""
    import analysis.energy_plots as EP
    import analysis.taxi_plots as TP

    got = {}

    def keep(save):
        def inner(fig, path):
            got[path.name] = fig
            return save(fig, path)
        return inner

    monkeypatch.setattr(EP, "_save", keep(EP._save))
    monkeypatch.setattr(TP, "_save", keep(TP._save))
    return got


def test_report_of_two_scenarios_draws_a_panel_each_with_words(two_scenarios, tmp_path,
                                                               monkeypatch):
    """map.png has a row per scenario; soc.png's legend names the series in words and its
    title only the scenario with charge data; the stations panel names its run."""
    from analysis.report import write_report

    figs = _figures(monkeypatch)
    write_report(two_scenarios, tmp_path)
    rows = [ax for ax in figs["map.png"].axes if ax.get_visible() and ax.get_title()]
    titles = " ".join(ax.get_title() for ax in rows)
    assert "ev\n" in titles and "plain\n" in titles
    soc = figs["soc.png"]
    assert "plain" not in soc._suptitle.get_text() and "ev" in soc._suptitle.get_text()
    legend = [t.get_text() for t in soc.axes[0].get_legend().get_texts()]
    assert legend[:2] == ["hungarian", "greedy"] and "median vehicle" in legend
    assert not any("dijkstra" in t or "stay" in t for t in legend)
    st = figs["stations.png"]
    assert [ax.get_title() for ax in st.axes if ax.get_title()] == ["ev: hungarian, N = 6, seed 1"]
    labels = [t.get_text() for t in st.axes[0].texts]
    assert sorted(t.split()[0] for t in labels) == ["A", "B", "C"]


def test_taxi_csv_energy_columns_by_hand(two_scenarios, tmp_path):
    """taxi.csv's energy columns: per-vehicle means and the lowest / end state of charge from
    the vehicles table, charges and strandings from the events; NaN for the plain scenario;
    report.md prints them as a table under the electric fleet's heading."""
    import math

    from analysis.io import open_results
    from analysis.report import write_report

    write_report(two_scenarios, tmp_path)
    taxi = pd.read_csv(tmp_path / "taxi.csv")
    res = open_results(two_scenarios)
    v, ev = res.table("vehicles"), res.table("events")
    for r in taxi.itertuples():
        ids = set(res.summary.loc[(res.summary["scenario"] == r.scenario)
                                  & (res.summary["allocator"] == r.allocator), "run_id"])
        mine, e = v.loc[v["run_id"].isin(ids)], ev.loc[ev["run_id"].isin(ids)]
        if r.scenario == "plain":
            assert math.isnan(r.kwh_drawn_per_vehicle) and math.isnan(r.charges)
            continue
        assert r.kwh_drawn_per_vehicle == pytest.approx(mine["kwh_drawn"].mean())
        assert r.kwh_charged_per_vehicle == pytest.approx(mine["kwh_charged"].mean())
        assert r.soc_min == pytest.approx(mine["soc_min"].min())
        assert r.soc_end_mean == pytest.approx(mine["soc_end"].mean())
        assert r.queue_seconds_per_vehicle == pytest.approx(mine["queue_seconds"].mean())
        assert r.charges == (e["event"] == "charge_start").sum()
        assert r.strandings == (e["event"] == "stranded").sum()
    text = (tmp_path / "report.md").read_text()
    energy = text[text.index("## Electric fleet"):]
    assert "| kwh_drawn_per_vehicle |" in energy and "| plain |" not in energy
