"""``[transit]`` read from a scenario file (dispatch.scenario.transit): defaults written once,
misspelt keys and plugin names named with the closest known one, a bad feed one line naming
the key and the feed's file; and the mode choice plugins (``cheapest``, ``logit``) against
their closed forms."""

from __future__ import annotations

import dataclasses
import datetime as dt
import math

import numpy as np
import pytest

from dispatch.api import registry
from dispatch.api.mode_choice import Option, Weights
from dispatch.config.transit import TransitConfig
from dispatch.errors import ScenarioError
from dispatch.scenario.load import load_scenario

BASE = """
name = "transit_test"
duration = 600.0
[world]
network = "manhattan_osm"
[fleet]
agents = 2
[tasks]
source = "poisson"
rate = 0.01
[dispatch]
allocator = "fcfs"
planner = "dijkstra"
"""


def _load(tmp_path, extra: str, base: str = BASE):
    p = tmp_path / "s.toml"
    p.write_text(base + extra, encoding="utf-8")
    return load_scenario(p)


def test_no_transit_section_no_transit(tmp_path):
    assert _load(tmp_path, "").transit is None


def test_the_defaults_are_the_dataclass_fields(tmp_path):
    cfg = _load(tmp_path, "[transit]\nfeed = \"nyc_subway\"\n").transit
    defaults = TransitConfig()
    for f in dataclasses.fields(TransitConfig):
        if f.name != "feed_path":
            assert getattr(cfg, f.name) == getattr(defaults, f.name), f.name
    assert cfg.feed_path.name == "manhattan_subway.zip" and cfg.feed_path.is_file()


def test_every_key_read(tmp_path):
    cfg = _load(tmp_path, """[transit]
feed = "nyc_subway"
service_date = 2026-09-24
max_access_walk = 800
walk_speed = 1.2
transfer_walk = 250
min_change = 90
w_ivt = 1.0
w_wait = 2.5
w_walk = 1.5
w_transfer = 3
transfer_penalty = 600
mode_choice = "logit"
[transit.logit]
scale = 0.2
""").transit
    assert (cfg.service_date, cfg.max_access_walk, cfg.walk_speed, cfg.transfer_walk,
            cfg.min_change) == (dt.date(2026, 9, 24), 800.0, 1.2, 250.0, 90.0)
    assert (cfg.w_ivt, cfg.w_wait, cfg.w_walk, cfg.w_transfer, cfg.transfer_penalty) == \
        (1.0, 2.5, 1.5, 3.0, 600.0)
    assert cfg.mode_choice == "logit" and cfg.params == (("scale", 0.2),)
    assert _load(tmp_path, "[transit]\nservice_date = \"20260924\"\n").transit.service_date \
        == dt.date(2026, 9, 24)


@pytest.mark.parametrize("extra, message", [
    ("[transit]\nwalk_sped = 1.2\n",
     r"transit\.walk_sped: unknown key \(did you mean 'walk_speed'\?\)"),
    ("[transit]\nmode_choice = \"cheapst\"\n",
     r"transit\.mode_choice: unknown mode_choice 'cheapst' \(did you mean 'cheapest'\?\)"),
    ("[transit]\nmode_choice = \"logit\"\n[transit.logit]\nscale = -1\n",
     r"transit\.logit: scale must be a finite number > 0, got -1"),
    ("[transit]\n[transit.logit]\nscale = 0.2\n",
     r"transit\.logit: unknown key"),
    ("[transit]\nw_wait = -1\n", r"transit\.w_wait: must be >= 0"),
    ("[transit]\nservice_date = \"next tuesday\"\n",
     r"transit\.service_date: must be a date such as 2026-09-23"),
    ("[transit]\nfeed = \"nowhere.zip\"\n",
     r"transit\.feed: nowhere\.zip cannot be read: file not found"),
    ("[transit]\nservice_date = 2026-09-26\n",
     (r"transit\.feed: manhattan_subway\.zip:calendar\.txt: service_date: no service runs "
      r"on 2026-09-26")),
])
def test_a_bad_transit_section_is_one_line(tmp_path, extra, message):
    with pytest.raises(ScenarioError, match=message) as err:
        _load(tmp_path, extra)
    assert "\n" not in str(err.value) and "s.toml" in str(err.value)


def test_a_broken_user_feed_names_its_file(tmp_path):
    from tests.dispatch.gtfs_feeds import tiny_tables, write_feed

    tables = tiny_tables()
    tables["stop_times.txt"][3]["stop_id"] = "nope"
    write_feed(tmp_path / "myfeed", tables)
    with pytest.raises(ScenarioError, match=r"transit\.feed: stop_times\.txt: row 4: stop_id "
                                            r"'nope' names no stop of stops\.txt"):
        _load(tmp_path, "[transit]\nfeed = \"myfeed\"\nservice_date = 2026-03-11\n")


def test_transit_needs_a_road_network(tmp_path):
    base = "name = \"v\"\n[fleet]\nagents = 2\n[tasks]\nsource = \"static\"\ncount = 3\n"
    with pytest.raises(ScenarioError, match=r"transit\.feed: transit needs a road network"):
        _load(tmp_path, "[transit]\nfeed = \"nyc_subway\"\n", base)


# ------------------------------------------------------------------------------- mode choice

W = Weights(ivt=1.0, wait=2.0, walk=2.0, change=2.0, per_change=300.0)
OPTIONS = [Option("fleet", 2000.0, ivt=900.0, wait=300.0, walk=0.0),  # 1,500
           Option("fleet+train", 1900.0, ivt=700.0, wait=200.0, walk=60.0),  # 1,220
           Option("train+fleet", 2100.0, ivt=600.0, wait=120.0, walk=100.0, change=120.0,
                  changes=1),  # 1,580
           Option("train", 2400.0, ivt=800.0, wait=100.0, walk=500.0)]  # 2,000


def test_the_generalized_cost():
    assert [W.cost(o) for o in OPTIONS] == [1500.0, 1220.0, 1580.0, 2000.0]
    with pytest.raises(ValueError, match="option kind 'bus' is not one of"):
        Option("bus", 0.0, 0.0, 0.0, 0.0)


def test_cheapest_takes_the_least_cost_first_of_ties():
    choice = registry.load("mode_choice", "cheapest")()
    rng = np.random.default_rng(0)
    assert choice.choose(OPTIONS, W, rng) == 1
    assert choice.choose([OPTIONS[0], OPTIONS[0]], W, rng) == 0
    assert choice.choose(OPTIONS[2:], W, rng) == 0


def test_logit_follows_its_closed_form():
    """Probabilities ``exp(-scale c_i) / sum``, costs in minutes; 40,000 seeded draws land
    within 4 standard errors of them; the same seed gives the same choices."""
    logit = registry.load("mode_choice", "logit")(scale=0.1)
    c = np.array([1500.0, 1220.0, 1580.0, 2000.0]) / 60.0
    want = np.exp(-0.1 * c) / np.exp(-0.1 * c).sum()
    assert np.allclose(logit.probabilities(OPTIONS, W), want, rtol=1e-12)
    n = 40_000
    rng = np.random.default_rng(5)
    picks = np.array([logit.choose(OPTIONS, W, rng) for _ in range(n)])
    freq = np.bincount(picks, minlength=4) / n
    assert (np.abs(freq - want) < 4 * np.sqrt(want * (1 - want) / n)).all()
    again = np.random.default_rng(5)
    assert [logit.choose(OPTIONS, W, again) for _ in range(50)] == picks[:50].tolist()
    steep = registry.load("mode_choice", "logit")(scale=1e6)  # no overflow; the cheapest
    assert steep.choose(OPTIONS, W, np.random.default_rng(1)) == 1
    for bad in (0, -1, math.inf, True, "x"):
        with pytest.raises(ValueError, match="scale must be a finite number > 0"):
            registry.load("mode_choice", "logit")(scale=bad)


@pytest.mark.parametrize("name", ["cheapest", "logit"])
def test_the_shipped_mode_choices_pass_their_checks(name, capsys):
    from dispatch.checks.mode_choices import check_mode_choice
    from dispatch.run import cli

    assert check_mode_choice(registry.load("mode_choice", name)).ok
    assert cli.main(["check", name, "--kind", "mode_choice"]) == 0
    assert f"mode_choice {name!r}" in capsys.readouterr().out


def test_broken_mode_choices_are_caught():
    """An answer past the options, a bool for an index, a draw from the global random state:
    each fails its check."""
    import random

    from dispatch.api.mode_choice import ModeChoice
    from dispatch.checks.mode_choices import check_mode_choice

    class Past(ModeChoice):
        name = "past"

        def choose(self, options, weights, rng):
            return len(options)

    class Yes(ModeChoice):
        name = "yes"

        def choose(self, options, weights, rng):
            return True

    class Global(ModeChoice):
        name = "global"

        def choose(self, options, weights, rng):
            return random.randrange(len(options))

    def failed(cls):
        return {r.name for r in check_mode_choice(cls).failed()}

    assert failed(Past) == failed(Yes) == {"valid"}
    assert "rng" in failed(Global)


def test_train_first_takes_a_train_within_its_slack():
    """``train_first``: the cheapest option with a train where it costs at most ``slack``
    more than the cheapest of all, else the cheapest."""
    cls = registry.load("mode_choice", "train_first")
    w = Weights(1.0, 2.0, 2.0, 2.0, 300.0)
    fleet = Option("fleet", 0.0, ivt=600.0, wait=60.0, walk=0.0)  # cost 720
    feeder = Option("fleet+train", 0.0, ivt=900.0, wait=60.0, walk=60.0)  # 1140
    train = Option("train", 0.0, ivt=800.0, wait=100.0, walk=100.0, changes=1)  # 1500
    rng = np.random.default_rng(0)
    opts = [fleet, train, feeder]
    assert cls(slack=0).choose(opts, w, rng) == 0
    assert cls(slack=419).choose(opts, w, rng) == 0
    assert cls(slack=420).choose(opts, w, rng) == 2
    assert cls(slack=5000).choose(opts, w, rng) == 2
    assert cls().choose([fleet], w, rng) == 0 and cls().choose([train], w, rng) == 0
    with pytest.raises(ValueError, match="slack must be"):
        cls(slack=-1)
