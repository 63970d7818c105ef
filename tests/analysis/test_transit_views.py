"""What the report and the replay show of a run with ``[transit]``: the mode split figure and
its riders table (door-to-door times by option recomputed from the legs and tasks tables equal
the summary's), and the replay's stations and riders off the fleet (a layer of their own, drawn
without a script error)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from analysis.io import open_results
from analysis.replay_data import choose_run, read_table, transit_of
from analysis.transit_plots import door_to_door, transit_section
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.analysis.test_replay_browser import Page, _write, browser  # noqa: F401 (fixture)

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def transit_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("transit_views")
    sc = load_scenario(ROOT / "scenarios" / "nyc_manhattan_transit.toml", overrides=[
        ("tasks.start", '"2014-12-21T17:00"', "--set"), ("tasks.count", "80", "--set"),
        ("fleet.agents", "30", "--set"), ("duration", "3600.0", "--set"),
        ("transit.mode_choice", '"train_first"', "--set")])
    [spec] = sc.runs()
    run_one(spec, out)
    return out


def test_door_to_door_by_option_equals_the_summary(transit_run, tmp_path):
    res = open_results(transit_run)
    s = res.summary
    legs, tasks = res.table("legs"), res.table("tasks")
    trips = door_to_door(legs, tasks)
    row = s.iloc[0]
    assert len(trips) == row["riders_served"]
    for mode in ("fleet", "fleet_train", "train_fleet", "train"):
        mine = trips.loc[trips["mode"] == mode, "seconds"]
        want = row[f"door_to_door_mean_{mode}"]
        assert (math.isnan(want) and mine.empty) or math.isclose(mine.mean(), want)
    files, items = transit_section(res, s, tmp_path)
    assert [f.name for f in files] == ["mode_split.png"] and files[0].stat().st_size > 0
    assert ("img", "mode_split.png") in items


def test_a_report_without_transit_has_no_transit_section(transit_run, tmp_path):
    res = open_results(transit_run)
    assert transit_section(res, res.summary.drop(columns=["riders"]), tmp_path) == ([], [])


def test_the_replay_data_of_riders_off_the_fleet(transit_run):
    run = choose_run(transit_run, None)
    legs = read_table(run, "legs")
    d = transit_of(legs, 0.0, 0.0, lambda v, t: np.asarray(v, t))
    off = legs.loc[legs["mode"] != "fleet"]
    assert len(d["t0"]) == len(off) and set(d["mode"]) <= {1, 2}
    assert (np.diff(d["t0"]) >= 0).all()
    named = set(off["from_stop_id"].dropna()) | set(off["to_stop_id"].dropna())
    assert set(d["sid"]) == named
    assert transit_of(legs.iloc[:0], 0.0, 0.0, None) is None


def test_the_replay_draws_riders_on_trains(transit_run, browser, tmp_path):  # noqa: F811
    legs = pq.read_table(next((transit_run / "legs").rglob("part-0.parquet"))).to_pandas()
    train = legs.loc[legs["mode"] == "train"].iloc[0]
    page = _write(transit_run, tmp_path / "replay.html")
    p = Page(browser, page, float((train["start"] + train["end"]) / 2))
    try:
        assert p.page.query_selector("input[data-layer='transit']") is not None
    finally:
        p.close()
