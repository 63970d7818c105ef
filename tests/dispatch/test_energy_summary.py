"""The summary's energy columns (dispatch.output.energy): what the vehicles table and the
event stream of the same run say, and NaN / 0 for a run without energy."""

from __future__ import annotations

import math

import pytest

from dispatch.output.energy import ENERGY_COLUMNS
from tests.dispatch.test_energy import grid, random_run, run


@pytest.mark.parametrize("seed", [1, 2])
def test_energy_columns_add_up_the_vehicles_and_count_the_events(tmp_path, seed):
    s, t = random_run(tmp_path, seed)
    v, ev = t["vehicles"], t["events"]
    assert s["kwh_drawn"] == pytest.approx(v.kwh_drawn.sum(), abs=1e-9)
    assert s["kwh_charged"] == pytest.approx(v.kwh_charged.sum(), abs=1e-9)
    assert s["queue_seconds"] == pytest.approx(v.queue_seconds.sum(), abs=1e-9)
    assert s["soc_min"] == v.soc_min.min()
    assert s["soc_end_mean"] == pytest.approx(v.soc_end.mean(), abs=1e-12)
    assert s["charges"] == (ev.event == "charge_start").sum() > 0
    assert s["strandings"] == (ev.event == "stranded").sum()


def test_a_stranding_is_counted(tmp_path):
    # test_energy's stranding by hand: one vehicle runs empty on its way to the pickup
    s, t = run(grid(tmp_path, "battery_kwh = 0.1\nwh_per_km = 150.0\nidle_kwh_per_hour = 7.2\n"
                              "reserve = 0.0", [(0.0, 2, 8)], extra="[faults]\ntow = 100.0\n"))
    assert s["strandings"] == 1 and s["soc_min"] == 0.0 and s["charges"] == 0


def test_a_run_without_energy_has_nan_figures_and_zero_counts(tmp_path):
    p = tmp_path / "plain.toml"
    (tmp_path / "trips.csv").write_text("t,origin_node,dest_node\n0.0,2,8\n")
    p.write_text('name = "plain"\nseed = 1\n[world]\nnetwork = "manhattan"\nblocks = [6, 2]\n'
                 'block = 200.0\nspeed = 10.0\n[fleet]\nagents = 1\n[tasks]\nsource = "trace"\n'
                 'trace = "trips.csv"\n[dispatch]\nallocator = "fcfs"\n', encoding="utf-8")
    s, _ = run(p)
    assert set(ENERGY_COLUMNS) <= s.keys()
    assert s["charges"] == 0 and s["strandings"] == 0
    assert all(math.isnan(s[k]) for k in ENERGY_COLUMNS if k not in ("charges", "strandings"))
