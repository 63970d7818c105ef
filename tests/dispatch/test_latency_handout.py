"""A decision that deliberates (``[comms] latency``) hands its pairs out as they are at the
hand-out (:mod:`dispatch.decide.deliberation`).

On a 6 x 5 Manhattan grid of 100 m blocks driven at 10 m/s (10 s a block; node ``k`` at
column ``k % 6``, row ``k // 6``), with the auction allocator, whose decision of one vehicle
and one request takes 3 message hops:

* a vehicle 30 s from a pickup whose ``max_wait`` is 31 s is not sent once a 3 s
  deliberation has made it late: the request expires unserved (without latency, or with a
  ``max_wait`` of 33 s, it rides, picked up at the hand-out plus the 30 s drive);
* a request inserted into a vehicle that drives on during the deliberation is handed out to
  it, re-planned from where the vehicle got to, in one decision: before, such a pair was
  dropped as stale and the decision came back every deliberation until the vehicle was free.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

DRIVE = 30.0  # seconds from node 0 to node 3


def _run(path: Path) -> tuple[dict, dict]:
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def _one_ride(directory: Path, *, max_wait: float, latency: float, allocator: str = "auction"
              ) -> Path:
    """One vehicle at node 0; one request at 0 s from node 3 to node 9 with ``max_wait``."""
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "max_wait"],
              [(0.0, 3, 9, max_wait)])
    write_csv(directory / "fleet.csv", ["vehicle_id", "x", "y"], [(0, 0.0, 0.0)])
    return road_scenario(directory, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"', allocator=allocator, duration=600.0,
                         extra=f"\n[comms]\nlatency = {latency!r}\n")


def test_a_pair_late_after_deliberating_is_not_handed_out(tmp_path):
    _, tables = _run(_one_ride(tmp_path, max_wait=31.0, latency=1.0))
    [d] = tables["decisions"].itertuples()
    assert d.hops == 3 and d.comm_delay == pytest.approx(3.0)
    assert d.n_assigned == 0  # the pair was dropped at the hand-out, 3 s late
    [t] = tables["tasks"].itertuples()
    assert t.state == "expired" and t.agent_id == -1
    events = set(tables["events"].event)
    assert "depart" not in events and "pickup" not in events


@pytest.mark.parametrize(("max_wait", "latency", "allocator", "pickup"), [
    (33.0, 1.0, "auction", 3.0 + DRIVE),  # the deliberation's 3 s and the drive: just in time
    (31.0, 0.0, "auction", DRIVE),  # no deliberation
    (31.0, 1.0, "hungarian", DRIVE),  # a centralized decision takes no hops
])
def test_a_pair_in_time_at_the_hand_out_rides_from_it(tmp_path, max_wait, latency, allocator,
                                                      pickup):
    _, tables = _run(_one_ride(tmp_path, max_wait=max_wait, latency=latency,
                               allocator=allocator))
    [t] = tables["tasks"].itertuples()
    assert t.state == "completed" and t.agent_id == 0
    assert t.assigned_at == pytest.approx(pickup - DRIVE)
    assert t.picked_up_at == pytest.approx(pickup)
    assert t.picked_up_at <= t.released_at + t.max_wait + 1e-9


def test_an_insertion_into_a_driving_vehicle_is_handed_out_in_one_decision(tmp_path):
    """Vehicle 0 (2 seats, node 0) is handed A (0 s, node 0 to node 5) at 0.15 s and drives
    through node 2 at 20.15 s; B (node 2 to node 4) is released at 20 s, when vehicle 1 stands
    at node 29, 70 s from it. The decision at 20 s inserts B into vehicle 0's plan; at its
    hand-out, 0.15 s later, vehicle 0 has driven on to node 2 and takes B there and then (the
    stale pair used to be dropped: 203 decisions, B handed out at 50.3 s once A was off)."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 0, 5), (20.0, 2, 4)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "x", "y"],
              [(0, 0.0, 0.0), (1, 500.0, 400.0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"\ncapacity = 2', allocator="auction",
                         duration=600.0, extra="\n[comms]\nlatency = 0.05\n")
    summary, tables = _run(path)
    tasks = tables["tasks"].set_index("task_id")
    assert (tasks.state == "completed").all()
    assert tasks.loc[1].agent_id == 0
    decisions = tables["decisions"]
    assert len(decisions) == summary["decisions"] == 2
    handed = decisions.t.iloc[1] + decisions.comm_delay.iloc[1]
    assert tasks.loc[1].assigned_at == pytest.approx(handed)
    assert handed == pytest.approx(20.15)
    assert tasks.loc[1].picked_up_at == pytest.approx(handed)  # (it stands at node 2 then)
    assert tasks.loc[1].completed_at == pytest.approx(handed + 20.0)
    assert tasks.loc[0].completed_at == pytest.approx(50.15)  # (A's ride as planned)
    inserts = tables["events"].query("event == 'insert' and task_id == 1")
    assert list(inserts.agent_id) == [0] and inserts.t.iloc[0] == pytest.approx(handed)
