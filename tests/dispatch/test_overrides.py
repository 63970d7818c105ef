"""Command-line overrides of scenario keys (``--set``, ``--capacity``, ``--batch-window``):
checked exactly like the file, recorded in the scenario text stored with the results."""

from __future__ import annotations

import tomllib

import pyarrow.parquet as pq
import pytest

from dispatch.errors import ScenarioError
from dispatch.run import cli
from dispatch.run.parser import parser
from dispatch.run.prepare import checked_specs, overrides
from dispatch.scenario.load import load_scenario
from dispatch.scenario.overrides import apply_overrides, parse_set

#: a small road scenario whose fleet may carry several riders
POOLED = ('name = "p"\nduration = 1000.0  # the horizon\n[world]\nnetwork = "manhattan"\n'
          'blocks = [3, 2]\nblock = 100.0\nspeed = 10.0\n[fleet]\nagents = 2\n'
          '[tasks]\nsource = "trace"\ntrace = "trips.csv"\nmax_delay = 600.0\n'
          '[dispatch]\nallocator = "hungarian"\nplanner = "dijkstra"\n'
          'objective = "added_time"\n[sweep]\nseed = [\n  0,\n  1,\n]\n')


@pytest.fixture
def pooled(tmp_path):
    (tmp_path / "trips.csv").write_text("t,origin_node,dest_node\n0,0,2\n50,3,5\n")
    path = tmp_path / "p.toml"
    path.write_text(POOLED)
    return path


def _error(argv, capsys) -> str:
    assert cli.main(argv) == 2
    return capsys.readouterr().err


def test_bad_key_is_refused_like_in_the_file(pooled, capsys):
    err = _error(["validate", str(pooled), "--set", "fleet.capacty=4"], capsys)
    assert "fleet.capacty: unknown key" in err and str(pooled) in err
    # the same key written in the file: the same message
    written = pooled.with_name("w.toml")
    written.write_text(POOLED.replace("agents = 2\n", "agents = 2\ncapacty = 4\n"))
    with pytest.raises(ScenarioError) as info:
        load_scenario(written)
    assert str(info.value).split(": ", 1)[1] == err.split(": ", 2)[2].strip()


def test_bad_value_names_the_key(pooled, capsys):
    assert "fleet.capacity: must be >= 1, got 0" in _error(
        ["validate", str(pooled), "--set", "fleet.capacity=0"], capsys)
    assert "fleet.capacity: must be an integer, got 'four'" in _error(
        ["validate", str(pooled), "--set", "fleet.capacity=four"], capsys)
    assert "dispatch.batch_window: must be >= 0" in _error(
        ["validate", str(pooled), "--batch-window", "-1"], capsys)
    assert "--set: must be SECTION.KEY=VALUE" in _error(
        ["validate", str(pooled), "--set", "capacity"], capsys)
    assert "fleet.agents: is not a table" in _error(
        ["validate", str(pooled), "--set", "fleet.agents.x=1"], capsys)


def test_set_equals_option_equals_file(pooled):
    by_set = load_scenario(pooled, overrides=[(*parse_set("fleet.capacity=4", pooled), "--set")])
    by_option = load_scenario(pooled, overrides=overrides(parser().parse_args(
        ["run", str(pooled), "--capacity", "4"])))
    written = pooled.with_name("w.toml")
    written.write_text(POOLED.replace("agents = 2\n", "agents = 2\ncapacity = 4\n"))
    in_file = load_scenario(written)
    assert by_set.fleet == by_option.fleet == in_file.fleet
    assert in_file.fleet.capacity == 4
    for sc in (by_set, by_option):
        assert tomllib.loads(sc.text) == tomllib.loads(in_file.text)
    assert "capacity = 4  # dispatch --set" in by_set.text
    assert "capacity = 4  # dispatch --capacity" in by_option.text


def test_overrides_edit_the_text_in_place():
    text = ('name = "x"\n[fleet]\nagents = 2  # two\n[sweep]\nseed = [\n  0,\n  1,\n]\n'
            'agents = [1]\n')
    doc = tomllib.loads(text)
    new, got = apply_overrides(text, doc, [("sweep.seed", "[5]", "--set"),
                                           ("fleet.agents", "3", "--set"),
                                           ("tasks.max_wait", "60.0", "--set"),
                                           ("seed", "7", "--set")], None)
    assert got == tomllib.loads(new) == {"name": "x", "seed": 7, "fleet": {"agents": 3},
                                         "sweep": {"seed": [5], "agents": [1]},
                                         "tasks": {"max_wait": 60.0}}
    assert new.count("# dispatch --set") == 4
    # a key the file writes as an inline table cannot be replaced line by line: refused
    inline = 'fleet = {agents = 2}\n'
    with pytest.raises(ScenarioError, match="fleet.agents: cannot be set"):
        apply_overrides(inline, tomllib.loads(inline), [("fleet.agents", "3", "--set")], None)


def test_bare_word_is_a_string(pooled):
    assert parse_set("dispatch.allocator=greedy", pooled) == ("dispatch.allocator", '"greedy"')
    assert parse_set("dispatch.batch_window = 30", pooled) == ("dispatch.batch_window", "30")


def test_batch_window_replaces_the_sweep(pooled):
    text = POOLED + "batch_window = [0.0, 30.0]\n"
    pooled.write_text(text)
    args = parser().parse_args(["validate", str(pooled), "--batch-window", "10"])
    _, specs = checked_specs(args)
    assert sorted({s.scenario.dispatch.batch_window for s in specs}) == [10.0]
    assert len(specs) == 2  # the two seeds


def test_run_records_overrides(pooled, capsys):
    out = pooled.parent / "out"
    assert cli.main(["run", str(pooled), "--out", str(out), "--duration", "20", "--capacity",
                     "3", "--set", "sweep.seed=[4]", "--set", "tasks.max_delay=300"]) == 0
    capsys.readouterr()
    files = sorted((out / "summary").rglob("part-0.parquet"))
    assert len(files) == 1 and "seed=4" in str(files[0])
    text = pq.read_schema(files[0]).metadata[b"dispatch.scenario"].decode()
    for line in ("duration = 20.0  # dispatch run --duration",
                 "capacity = 3  # dispatch --capacity", "seed = [4]  # dispatch --set",
                 "max_delay = 300  # dispatch --set"):
        assert line in text
    doc = tomllib.loads(text)
    assert doc["fleet"]["capacity"] == 3 and doc["tasks"]["max_delay"] == 300
