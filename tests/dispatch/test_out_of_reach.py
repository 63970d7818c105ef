"""``[dispatch] out_of_reach``: a request no vehicle reaches in time at its first offer is
rejected at once ("reject", the default) or stays open until its deadline ("wait"), when a
vehicle that frees up near it may still take it.

Checked on a line of intersections with answers computed by hand, for single seats and for
the insertion of shared rides, both allocators that decide every request of a batch
(``hungarian``) and one at a time (``fcfs``): the waiting request is served by the vehicle
that frees up, or expires at its deadline when none does; the default is unchanged."""

from __future__ import annotations

from pathlib import Path

import pytest

from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_reassign import LINE
from tests.dispatch.test_trips import road_scenario, write_csv


def _run(tmp_path: Path, mode: str | None, max_wait: float, allocator: str = "hungarian",
         capacity: int = 1, company: bool = False):
    """V0 starts at node 8, V1 at node 0 (a line of 20 s edges). t = 0: trip A 8 -> 9 (V0
    takes it: at its node, drops off at node 9 at t = 20). t = 1: trip B 9 -> 5: V1 is idle but
    9 edges (180 s) away, past B's ``max_wait``; at t = 20 V0 is free at node 9, 0 s from B's
    pickup. ``company``: trip C 0 -> 1 released with B (V1 takes it), so B's first offer is a
    decision of two requests, not one."""
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [[0, 8], [1, 0]])
    trips = [[0.0, 8, 9], [1.0, 9, 5]] + ([[1.0, 0, 1]] if company else [])
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], trips)
    extra = "" if mode is None else f'out_of_reach = "{mode}"'
    name = f"reach_{mode}_{int(max_wait)}_{allocator}_{capacity}_{company}"
    path = road_scenario(tmp_path, network=LINE,
                         fleet=f'start = "fleet.csv"\ncapacity = {capacity}',
                         tasks=f'source = "trace"\ntrace = "trips.csv"\nmax_wait = {max_wait!r}',
                         allocator=allocator, extra=extra, name=name)
    sc = load_scenario(path)
    assert sc.dispatch.out_of_reach == (mode or "reject")
    res = run_one(sc.runs()[0], tmp_path / name)
    return res.tables["tasks"].to_pandas().set_index("task_id"), res.summary


@pytest.mark.parametrize("allocator", ["hungarian", "fcfs"])
@pytest.mark.parametrize("capacity", [1, 2])
@pytest.mark.parametrize("company", [False, True])
def test_a_waiting_request_is_served_by_the_vehicle_that_frees_up(tmp_path, allocator, capacity,
                                                                  company):
    tasks, summary = _run(tmp_path, "wait", 60.0, allocator, capacity, company)
    # by hand: B (task 1) waits from t = 1; V0 drops A off at node 9 at t = 20 and takes B
    # there at once (wait 19 s), then 4 edges to node 5 (t = 100)
    assert tasks.loc[1, "state"] == "completed" and tasks.loc[1, "agent_id"] == 0
    assert tasks.loc[1, "picked_up_at"] == pytest.approx(20.0)
    assert tasks.loc[1, "completed_at"] == pytest.approx(100.0)
    if company:  # C: V1 at its pickup at once, one edge (t = 21)
        assert tasks.loc[2, "agent_id"] == 1 and tasks.loc[2, "completed_at"] == pytest.approx(21.0)
    assert summary["tasks_completed"] == 2 + company


@pytest.mark.parametrize("mode", [None, "reject"])
@pytest.mark.parametrize("company", [False, True])
def test_by_default_a_request_out_of_reach_is_rejected_at_once(tmp_path, mode, company):
    tasks, summary = _run(tmp_path, mode, 60.0, company=company)
    assert tasks.loc[1, "state"] == "rejected"
    assert tasks.loc[1, "closed_at"] == pytest.approx(1.0)
    assert summary["tasks_completed"] == 1 + company


def test_a_waiting_request_no_vehicle_reaches_by_its_deadline_expires(tmp_path):
    tasks, summary = _run(tmp_path, "wait", 10.0)  # deadline t = 11, V0 free at t = 20
    assert tasks.loc[1, "state"] == "expired"
    assert tasks.loc[1, "closed_at"] == pytest.approx(11.0)
    assert tasks.loc[0, "state"] == "completed" and summary["tasks_completed"] == 1
