"""Scenario errors a user fixes in one try: one line naming the scenario file and the key path,
with the closest known key, section or value where one is close, and a key's error before any
file the scenario names is read."""

from __future__ import annotations

import pytest

import dispatch.scenario.load as load
from dispatch.errors import ScenarioError
from dispatch.scenario.keys import KEYS
from dispatch.scenario.load import load_scenario


def error_of(tmp_path, text: str, name: str = "s.toml") -> str:
    """The one-line message of loading a scenario file of ``text``."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    return msg


def test_misspelt_key_suggests_the_closest(tmp_path):
    msg = error_of(tmp_path, "[tasks]\nmax_wiat = 30.0\n")
    assert "tasks.max_wiat: unknown key (did you mean 'max_wait'?)" in msg


def test_misspelt_section_suggests_the_closest(tmp_path):
    msg = error_of(tmp_path, "[dispach]\nallocator = 'greedy'\n")
    assert "dispach: unknown key (did you mean 'dispatch'?)" in msg


def test_misspelt_choice_suggests_the_closest(tmp_path):
    msg = error_of(tmp_path, "[tasks]\nsource = 'trac'\n")
    assert "tasks.source: must be one of" in msg and "(did you mean 'trace'?)" in msg


def test_far_off_key_has_no_suggestion(tmp_path):
    msg = error_of(tmp_path, "[comms]\nzzzzzz = 1\n")
    assert "comms.zzzzzz: unknown key (known keys here: latency, loss, range)" in msg


def test_key_typo_reported_before_the_trace_is_read(tmp_path, monkeypatch):
    (tmp_path / "broken.csv").write_bytes(b"junk\x00\x01")

    def read_trace(*args, **kwargs):
        raise AssertionError("the trace was read before the key typo was reported")

    monkeypatch.setattr(load, "_read_trace", read_trace)
    msg = error_of(tmp_path, "[tasks]\nsource = 'trace'\ntrace = 'broken.csv'\nmax_snap = 5.0\n"
                             "max_wiat = 3.0\n")
    assert "tasks.max_wiat: unknown key (did you mean 'max_wait'?)" in msg
    # a [tasks] typo comes before [fleet]'s start file is read too
    msg = error_of(tmp_path, "[fleet]\nstart = 'broken.csv'\n[tasks]\nsourse = 'static'\n")
    assert "tasks.sourse: unknown key (did you mean 'source'?)" in msg
    # and so does a typo in a later section
    msg = error_of(tmp_path, "[tasks]\nsource = 'trace'\ntrace = 'broken.csv'\n"
                             "[dispatch]\nbatch_windw = 5.0\n")
    assert "dispatch.batch_windw: unknown key (did you mean 'batch_window'?)" in msg


def test_missing_trace_names_the_key_and_the_scenario(tmp_path):
    msg = error_of(tmp_path, "[tasks]\nsource = 'trace'\ntrace = 'my_trips.csv'\n")
    assert msg == f"{tmp_path / 's.toml'}: tasks.trace: my_trips.csv cannot be read: " \
                  "file not found"


def test_missing_start_file_names_the_key_and_the_scenario(tmp_path):
    msg = error_of(tmp_path, "[fleet]\nstart = 'where.csv'\n")
    assert msg.endswith("s.toml: fleet.start: where.csv cannot be read: file not found")


def test_toml_syntax_error_gives_line_and_column(tmp_path):
    msg = error_of(tmp_path, "name = 'a'\nseed = = 3\n")
    assert msg == f"{tmp_path / 's.toml'}: line 2, column 8: TOML syntax: Invalid value"


def test_fleet_known_keys_list_every_accepted_key(tmp_path):
    msg = error_of(tmp_path, "[fleet]\nagentz = 3\n")
    known = msg.split("known keys here: ")[1].rstrip(")").split(", ")
    assert set(KEYS["fleet"]) <= set(known)
    assert {"sizing", "sizing_params", "energy", "breaks", "shift_grace"} <= set(known)


def test_misspelt_network_key_suggests_network(tmp_path):
    """A misspelt ``network`` leaves a table that looks like a voxel world's: the hint must
    still come from both kinds' keys."""
    msg = error_of(tmp_path, "[world]\nnetwrok = 'manhattan_osm'\n")
    assert "world.netwrok: unknown key (did you mean 'network'?)" in msg


def test_misspelt_shipped_network_suggests_the_closest(tmp_path):
    """The network is read when the run starts: the error then names the key and the closest
    shipped network."""
    from dispatch.config.scenario import RunSpec
    from dispatch.run.runner import run_one

    path = tmp_path / "s.toml"
    path.write_text("[world]\nnetwork = 'manhatan_osm'\n", encoding="utf-8")
    sc = load_scenario(path)
    with pytest.raises(ScenarioError) as info:
        run_one(RunSpec(sc, "fcfs", "dijkstra", 1, 0))
    msg = str(info.value)
    assert msg.startswith(f"{path}: world.network: ") and "\n" not in msg
    assert "(did you mean 'manhattan_osm'?)" in msg
