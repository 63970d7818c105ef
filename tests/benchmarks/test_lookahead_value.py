"""benchmarks/lookahead_value.py: series names and the study table (no simulation)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def lv():
    spec = importlib.util.spec_from_file_location("lookahead_value",
                                                  ROOT / "benchmarks" / "lookahead_value.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_series_name_gives_its_allocator_objective_and_parameters(lv):
    got = lv.parse("rtv+value=v.npz@120+reward=600")
    assert got["allocator"] == "rtv" and got["objective"] is None and not got["demand"]
    assert got["params"] == {"value": "v.npz", "value_weight": 120.0, "value_reward": 600.0}
    got = lv.parse("hungarian/added_time+demand+dvalue=d.npz+dmix=0.3")
    assert got["objective"] == "added_time" and got["demand"]
    assert got["params"] == {} and got["demand_params"] == {"value": "d.npz", "value_mix": 0.3}
    got = lv.parse("hungarian/added_time+demand+d.max_moves=100+d.zone=1500+every=60+horizon=900")
    assert got["demand_params"] == {"max_moves": 100, "zone": 1500.0}
    assert isinstance(got["demand_params"]["max_moves"], int)
    assert got["reposition_every"] == 60.0 and got["reposition_horizon"] == 900.0
    assert "out_of_reach" not in got and lv.parse("hungarian+wait")["out_of_reach"] == "wait"
    with pytest.raises(SystemExit, match="unknown series part"):
        lv.parse("hungarian+bogus=1")
    with pytest.raises(SystemExit, match="unknown series part"):
        lv.parse("hungarian+demand+d.value_mix=1")  # the mix is dmix=


def test_the_table_gives_means_intervals_and_paired_differences(lv):
    # two seeds: a mean and its t half-width t(0.975, 1) * sd / sqrt(2) = 12.706 * |a - b| / 2
    rows = [{"series": s, "n_agents": "10", "seed": str(k), "served_share": str(v),
             "wait_mean": str(w), "vehicle_km": "100", "passenger_km": "50"}
            for s, k, v, w in (("a", 0, 0.80, 100.0), ("a", 1, 0.90, 110.0),
                               ("b", 0, 0.85, 90.0), ("b", 1, 0.93, 90.0))]
    text = lv.table(rows, ["a", "b"], [10], [0, 1])
    lines = text.splitlines()
    assert len(lines) == 4
    a, b = lines[2], lines[3]
    half = 12.7062 * 10.0 / 2  # served % of a: 80 and 90
    assert f"| 85.00 ± {half:.2f} |" in a and "| 105.0 ± 63.5 |" in a
    assert "| 100 ± 0 | 50 ± 0 |" in a and a.endswith("|  |")
    # b - a by seed: +5 and +3 points: mean +4, half-width 12.706 * 1.414 / 1.414 = 12.71
    assert b.endswith("| +4.00 ± 12.71 |")
    rows[2]["vehicle_km"] = ""  # a run that did not record it: a dash, not a number
    assert "| – | 50 ± 0 |" in lv.table(rows, ["a", "b"], [10], [0, 1]).splitlines()[3]
