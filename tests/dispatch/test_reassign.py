"""Re-assignment before pickup (``[dispatch] reassign = true``): a decision also considers the
vehicles still driving to a pickup; a vehicle given another task (or none while its task goes
to someone else) gives its task up, which goes back to open, and re-routes from where it is.

Checked: a hand-built case on a line of intersections (answers computed by hand), the
life-cycle invariants on random runs (every task ends in exactly one terminal state, no request
is picked up twice, no vehicle holds two tasks, no task is held by two vehicles), the summary's
count against the events, and same seed same output."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

TERMINAL_EVENTS = {"complete", "expire", "reject", "unreachable", "cut_off", "failed"}
#: two rows of 10 intersections, 200 m apart, 10 m/s: 20 s per edge (row 0 is the line)
LINE = 'network = "manhattan"\nblocks = [10, 2]\nblock = 200.0\nspeed = 10.0'


def _line_run(tmp_path: Path, reassign: bool):
    """V0 starts at node 0, V1 at node 8. t = 0: trip A 8 -> 9 (V1 takes it: at its node,
    drops off at t = 20). t = 1: trip B 9 -> 5: only V0 is idle, 9 edges away (180 s), and
    drives to it. At t = 20 V1 is idle at node 9, 0 s from B's pickup; V0 is 19 s into its
    first edge (1 s from node 1, then 8 edges: 161 s from node 9)."""
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [[0, 0], [1, 8]])
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [[0.0, 8, 9],
                                                                          [1.0, 9, 5]])
    path = road_scenario(tmp_path, network=LINE, fleet='start = "fleet.csv"',
                         tasks='source = "trace"\ntrace = "trips.csv"',
                         extra=f"reassign = {'true' if reassign else 'false'}",
                         name=f"line_{reassign}")
    return run_one(load_scenario(path).runs()[0], tmp_path / f"out_{reassign}")


def test_a_closer_vehicle_that_becomes_free_takes_the_request(tmp_path):
    res = _line_run(tmp_path, reassign=True)
    tasks = res.tables["tasks"].to_pandas().set_index("task_id")
    ev = res.tables["events"].to_pandas()
    # by hand: B (task 1) is picked up by V1 at t = 20 (wait 19 s), dropped at node 5 after
    # 4 edges (t = 100); V0 gave it up at t = 20, 19 s (190 m) along its first edge
    assert tasks.loc[1, "agent_id"] == 1
    assert tasks.loc[1, "picked_up_at"] == pytest.approx(20.0)
    assert tasks.loc[1, "completed_at"] == pytest.approx(100.0)
    assert tasks.loc[1, "cost"] == pytest.approx(0.0)
    re = ev[ev.event == "reassign"]
    assert list(zip(re.t, re.agent_id, re.task_id)) == [(pytest.approx(20.0), 0, 1)]
    assert re.x.iloc[0] == pytest.approx(190.0) and re.y.iloc[0] == pytest.approx(0.0)
    after = ev[(ev.t == 20.0) & (ev.index > re.index[0])]
    assert ("assign", 1, 1) in set(zip(after.event, after.agent_id, after.task_id))
    assert ("idle", 0, -1) in set(zip(after.event, after.agent_id, after.task_id))
    veh = res.tables["vehicles"].to_pandas().set_index("agent_id")
    assert veh.loc[0, "empty_distance"] == pytest.approx(190.0)
    assert veh.loc[0, "distance"] == pytest.approx(190.0)
    assert veh.loc[0, "busy_seconds"] == pytest.approx(19.0)
    assert veh.loc[1, "distance"] == pytest.approx(200.0 + 800.0)
    assert res.summary["reassignments"] == 1
    assert res.summary["wait_time_mean"] == pytest.approx((0.0 + 19.0) / 2)


def test_without_reassign_the_first_vehicle_drives_all_the_way(tmp_path):
    res = _line_run(tmp_path, reassign=False)
    tasks = res.tables["tasks"].to_pandas().set_index("task_id")
    assert tasks.loc[1, "agent_id"] == 0
    assert tasks.loc[1, "picked_up_at"] == pytest.approx(181.0)  # 1 + 9 edges x 20 s
    assert res.summary["reassignments"] == 0
    assert "reassign" not in set(res.tables["events"].to_pandas().event)


def _check_invariants(res) -> None:
    ev = res.tables["events"].to_pandas()
    tasks = res.tables["tasks"].to_pandas()
    # every released task ends in exactly one terminal state
    released = set(ev.task_id[ev.event == "release"])
    assert released == set(tasks.task_id)
    term = ev[ev.event.isin(TERMINAL_EVENTS)]
    assert term.task_id.value_counts().max() == 1
    assert set(term.task_id) == released
    # no request is picked up twice (no faults here: no transfers)
    assert ev[ev.event == "pickup"].task_id.value_counts().max() <= 1
    # replay: no vehicle holds two tasks, no task is held by two vehicles
    holds: dict[int, int] = {}  # vehicle -> task
    held_by: dict[int, int] = {}  # task -> vehicle
    for kind, a, t in zip(ev.event, ev.agent_id, ev.task_id):
        if kind == "assign":
            assert a not in holds, f"vehicle {a} given task {t} while holding {holds.get(a)}"
            assert t not in held_by, f"task {t} given to {a} while held by {held_by.get(t)}"
            holds[a], held_by[t] = t, a
        elif kind == "reassign":
            assert holds.get(a) == t
            del holds[a], held_by[t]
        elif kind in ("complete", "cut_off", "failed") and t in held_by:
            del holds[held_by.pop(t)]
    # a task given up is never picked up by the vehicle that gave it up (unless re-assigned)
    picked = {t: a for t, a in zip(ev.task_id[ev.event == "pickup"],
                                   ev.agent_id[ev.event == "pickup"])}
    done = tasks[tasks.state == "completed"].set_index("task_id")
    for t, a in picked.items():
        if t in done.index:
            assert done.loc[t, "agent_id"] == a
    assert res.summary["reassignments"] == int((ev.event == "reassign").sum())


@pytest.mark.parametrize("allocator,batch", [("fcfs", 0.0), ("hungarian", 30.0),
                                             ("greedy", 10.0)])
def test_invariants_on_random_runs(tmp_path, allocator, batch):
    path = road_scenario(tmp_path, allocator=allocator, duration=3000.0,
                         fleet="agents = 6",
                         tasks='source = "poisson"\nrate = 0.05\ncount = 120\nmax_wait = 400.0',
                         extra=f"reassign = true\nbatch_window = {batch!r}",
                         name=f"rnd_{allocator}")
    res = run_one(load_scenario(path).runs()[0], tmp_path / "out")
    _check_invariants(res)
    assert res.summary["reassignments"] > 0  # the case happens in these runs
    again = run_one(load_scenario(path).runs()[0], tmp_path / "again")
    for name in ("tasks", "events", "vehicles"):
        assert res.tables[name].to_pandas().equals(again.tables[name].to_pandas()), name
    for k, v in res.summary.items():
        if k.endswith("seconds") or k == "alloc_seconds":
            continue
        w = again.summary[k]
        assert (isinstance(v, float) and math.isnan(v) and math.isnan(w)) or v == w, k


def test_reassign_with_faults_keeps_the_invariants(tmp_path):
    path = road_scenario(tmp_path, allocator="fcfs", duration=3000.0, fleet="agents = 6",
                         tasks='source = "poisson"\nrate = 0.05\ncount = 80\nmax_wait = 400.0',
                         extra="reassign = true\n\n[faults]\nrate = 2.0\nrepair = 60.0",
                         name="rnd_faults")
    res = run_one(load_scenario(path).runs()[0], tmp_path / "out")
    ev = res.tables["events"].to_pandas()
    term = ev[ev.event.isin(TERMINAL_EVENTS)]
    assert term.task_id.value_counts().max() == 1
    assert set(term.task_id) == set(ev.task_id[ev.event == "release"])


def test_reassign_needs_a_road_network(make_scenario):
    with pytest.raises(ScenarioError, match="reassign"):
        load_scenario(make_scenario(dispatch={"reassign": True}))


def test_reassign_must_be_a_boolean(tmp_path):
    path = road_scenario(tmp_path, tasks='source = "static"\ncount = 3', extra='reassign = 1')
    with pytest.raises(ScenarioError, match="reassign.*true or false"):
        load_scenario(path)


def test_events_table_lists_reassign():
    from dispatch.events import KINDS

    assert "reassign" in KINDS
    assert pd.Series(["reassign"]).isin(KINDS).all()
