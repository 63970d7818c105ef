"""benchmarks/lookahead.py: what each series runs (no simulation)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def la():
    spec = importlib.util.spec_from_file_location("lookahead", ROOT / "benchmarks" / "lookahead.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_series_runs_what_its_name_says(la):
    sc = la.scenario_for(ROOT / "scenarios" / "chicago_taxi.toml", 30.0, 1.0)
    for series in la.SERIES:
        spec = la.spec_of(series, sc, 500, 0, "v.npz", None, "vd.npz", "day.pt")
        params = dict(spec.scenario.dispatch.allocator_params)
        assert spec.allocator == ("magnnet" if series.startswith("magnnet") else "hungarian")
        assert spec.scenario.dispatch.batch_window == 30.0
        if "value(d)" in series:
            assert params["value"] == "vd.npz"
        elif "value" in series:
            assert params["value"] == "v.npz"
        else:
            assert "value" not in params
        assert (spec.scenario.reposition.policy == "demand") == ("demand" in series)
        assert (spec.scenario.comms.range == 2000.0) == series.endswith("@2km")
        assert (params.get("checkpoint") == "day.pt") == series.startswith("magnnet-day")
