"""The trips a trace's reading leaves out (``tasks.max_snap``) are said once per trace and count
in a process, as a warning only when a large share of the file is left out (the trace and the
network probably do not match), else at INFO level: the shipped Manhattan day, which leaves
out by design the 9 % of its trips that end across a river, loads without a warning, however
often it is loaded (a bench loads it three times)."""

from __future__ import annotations

import logging

import pytest

from dispatch.scenario import notes
from dispatch.scenario.load import load_scenario
from dispatch.scenario.notes import DROPPED_WARN_SHARE
from tests.conftest import ROOT

NYC = ROOT / "dispatch" / "data" / "nyc_manhattan" / "nyc_taxi_2014-12-21_20k.csv"
JFK = "40.6413,-73.7781"  # far from every Manhattan intersection


@pytest.fixture(autouse=True)
def _fresh(monkeypatch):
    monkeypatch.setattr(notes, "SAID", set())


def _said(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if "trips left out" in r.getMessage()]


def test_the_shipped_day_says_its_left_out_trips_once_and_without_a_warning(caplog):
    caplog.set_level(logging.INFO, logger="dispatch.scenario.load")
    for _ in range(3):
        load_scenario(ROOT / "scenarios" / "nyc_manhattan.toml")
    [record] = _said(caplog)
    assert record.levelno == logging.INFO
    assert "1812 of 19979 trips left out" in record.getMessage()
    assert 1812 / 19979 < DROPPED_WARN_SHARE


def test_a_trace_mostly_off_the_network_warns_once(tmp_path, caplog):
    rows = NYC.read_text(encoding="utf-8").splitlines()
    header, kept = rows[0], rows[1:7]
    far = [f"{100 + i},{JFK},{JFK},2014-12-21 00:10:00,1" for i in range(4)]
    (tmp_path / "trips.csv").write_text("\n".join([header, *kept, *far]) + "\n",
                                        encoding="utf-8")
    path = tmp_path / "mine.toml"
    path.write_text('[world]\nnetwork = "manhattan_osm"\n[fleet]\nagents = 2\n'
                    '[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                    'start = "2014-12-21T00:00"\nmax_snap = 250.0\n', encoding="utf-8")
    caplog.set_level(logging.INFO, logger="dispatch.scenario.load")
    sc = load_scenario(path)
    load_scenario(path)
    assert len(sc.tasks.trips) == 6
    [record] = _said(caplog)
    assert record.levelno == logging.WARNING
    assert "trips.csv: 4 of 10 trips left out" in record.getMessage()
    assert "tasks.max_snap = 250 m" in record.getMessage()
