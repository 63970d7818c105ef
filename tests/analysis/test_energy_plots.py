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
    from dispatch.runner import run_one
    from dispatch.scenario import load_scenario

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
