"""The shipped pooled recipes (scenarios/nyc_manhattan_pooled.toml, chicago_taxi_pooled.toml)
validate and run a short stretch of their day, sharing rides."""

from __future__ import annotations

from pathlib import Path

import pyarrow.dataset as ds
import pytest

from dispatch.run import cli
from dispatch.scenario.load import load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


@pytest.mark.parametrize("name, allocator", [("nyc_manhattan_pooled", "rtv"),
                                             ("chicago_taxi_pooled", "hungarian")])
def test_pooled_recipe_validates_and_runs(name, allocator, tmp_path, capsys):
    path = SCENARIOS / f"{name}.toml"
    sc = load_scenario(path)
    assert sc.name == name and sc.fleet.capacity == 4 and sc.dispatch.allocator == allocator
    assert sc.tasks.max_delay == 600.0 and sc.dispatch.batch_window == 30.0
    assert cli.main(["validate", str(path)]) == 0
    out = tmp_path / "out"
    assert cli.main(["run", str(path), "--duration", "900", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "shared rides" in printed
    summary = ds.dataset(out / "summary", partitioning="hive").to_table().to_pylist()
    assert len(summary) == 1 and summary[0]["sim_time"] == 900.0
    tasks = ds.dataset(out / "tasks", partitioning="hive").to_table()
    assert tasks.num_rows > 0 and "completed" in set(tasks.column("state").to_pylist())
