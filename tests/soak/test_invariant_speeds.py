"""The soak's ``reachable`` check reads how fast a vehicle may go from the run itself: on a
road network the fastest edge of the network the run wrote beside its tables (not a default
street speed), and in a voxel world, where an event names the cell a vehicle stands in or is
stepping out of, a step's time counts from the first event at that cell."""

from __future__ import annotations

import json
import tomllib

import pandas as pd
import pytest

from dispatch.run.cli import main
from soak import invariants

#: a line of six nodes 1 km apart: its first two edges (each way) at 30 m/s, the others 8 m/s
FAST, SLOW = 30.0, 8.0


def _line_network(folder) -> None:
    nodes = [{"id": i, "x": 1000.0 * i, "y": 0.0} for i in range(6)]
    links = [{"source": a, "target": b, "length": 1000.0, "speed": FAST if i < 2 else SLOW}
             for i in range(5) for a, b in ((i, i + 1), (i + 1, i))]
    (folder / "line.json").write_text(json.dumps(
        {"directed": True, "graph": {}, "nodes": nodes, "links": links}))
    (folder / "trips.csv").write_text("t,origin_node,dest_node\n10,2,0\n200,0,2\n400,5,0\n")
    (folder / "fleet.csv").write_text("vehicle_id,node\n0,0\n")
    (folder / "s.toml").write_text(
        'name = "fast_edges"\nseed = 1\nduration = 900.0\n[world]\nnetwork = "line.json"\n'
        '[fleet]\nstart = "fleet.csv"\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n')


def test_road_speed_is_the_networks_fastest_edge(tmp_path):
    _line_network(tmp_path)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(out)]) == 0
    doc = tomllib.loads((tmp_path / "s.toml").read_text())
    tables = invariants.read_tables(out)
    assert invariants._top_speed(doc, tables, tables["vehicles"]) == {0: pytest.approx(FAST)}
    # the first drive covers the two fast edges (2 km in 66.7 s): clean with the network's
    # own speeds, flagged at the old default of 10 m/s (what a network without its edges
    # file falls back to)
    ev = tables["events"]
    pickup = ev[(ev.event == "pickup") & (ev.task_id == 0)].t.iloc[0]
    assert pickup - 10.0 < 2000.0 / 10.0
    assert invariants.check(doc, tables) == []
    without = {k: v for k, v in tables.items() if k != "_edges"}
    assert {n for n, _ in invariants.check(doc, without)} == {"reachable"}
    # and a vehicle faster than the fastest edge is still caught: the same pickup 2 km at
    # 40 m/s
    early = ev.copy()
    early.loc[(early.event == "pickup") & (early.task_id == 0), "t"] = 10.0 + 2000.0 / 40.0
    broken = invariants.check(doc, dict(tables, events=early))
    assert [n for n, _ in broken] == ["reachable"] and "at most 30 m/s" in broken[0][1]


def test_road_speed_counts_a_congestion_factor_below_one():
    doc = {"world": {"network": "x.json", "congestion": [0.5] + [1.5] * 23}}
    edges = pd.DataFrame({"u": [0, 1], "v": [1, 0], "seconds": [100.0, 50.0],
                          "metres": [1000.0, 1000.0]})
    vehicles = pd.DataFrame({"agent_id": [3], "speed": [1.0]})
    assert invariants._top_speed(doc, {"_edges": edges}, vehicles) == {3: 40.0}


def _voxel_events(rows) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["t", "event", "agent_id", "task_id", "x", "y", "z"])


def _voxel_reachable(rows) -> list[str]:
    doc = {"world": {"size": [12.0, 12.0, 10.0], "cell": 2.0}}
    vehicles = pd.DataFrame({"agent_id": [1], "speed": [5.0]})
    ev = _voxel_events(rows)
    return list(invariants._reachable(doc, {}, {}, None, ev, vehicles))


def test_voxel_step_counts_from_the_first_event_at_its_cell():
    # idle at 76.86 s, handed a task at 77.18 s mid-step (the event names the cell it leaves)
    # and in the next cell (2 m on) at 77.26 s: the step took 0.4 s at 5 m/s, legal
    rows = [(76.857777, "idle", 1, -1, 11.0, 7.0, 1.0),
            (77.177800, "depart", 1, 115, 11.0, 7.0, 1.0),
            (77.257777, "move", 1, 115, 9.0, 7.0, 1.0),
            (77.657777, "move", 1, 115, 9.0, 5.0, 1.0)]
    assert _voxel_reachable(rows) == []
    # the same next cell only 0.2 s after it first stood in the last one: too fast
    rows[0] = (77.057777, "idle", 1, -1, 11.0, 7.0, 1.0)
    assert len(_voxel_reachable(rows)) == 1
    # and a second step faster than its speed (2 m in 0.3 s) is caught after a first
    rows = [(0.0, "idle", 1, -1, 1.0, 1.0, 1.0), (0.4, "move", 1, 0, 3.0, 1.0, 1.0),
            (0.7, "move", 1, 0, 5.0, 1.0, 1.0)]
    assert len(_voxel_reachable(rows)) == 1
