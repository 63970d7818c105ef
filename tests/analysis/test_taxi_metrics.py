"""Every taxi metric on a run small enough to follow by hand.

The network is a 3 x 2 grid (``manhattan``, 100 m blocks, 10 m/s: 10 s per block):

    3 --- 4 --- 5        taxi 0 starts on node 0, taxi 1 on node 5; fcfs, no batching,
    |     |     |        no service time.
    0 --- 1 --- 2

trips (release, origin -> destination):
    T0  t = 0   0 -> 2   taxi 0 is there: wait 0, rides 20 s (200 m), free at t = 20 on node 2
    T1  t = 1   3 -> 5   taxi 1 drives 5 -> 4 -> 3 (20 s, 200 m empty): pickup t = 21, wait 20,
                         rides 20 s (200 m), free at t = 41 on node 5
    T2  t = 2   4 -> 3   max_wait 5 s, no taxi free before t = 7: expires (a rejection)
    T3  t = 30  1 -> 0   taxi 0 drives 2 -> 1 (10 s, 100 m empty): pickup t = 40, wait 10,
                         rides 10 s (100 m); the run ends at t = 50

So: 4 requests, 3 rides, 1 rejection; waits 0, 20, 10 s; in-vehicle 20, 20, 10 s, each the
direct free-flow time (detour ratio 1); 800 m driven, 300 m empty; each taxi is busy (to a
pickup or with a passenger) 40 of the 50 s.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analysis import metrics as M
from analysis.io import open_results
from analysis.network import direct_seconds, road_network
from analysis.timeline import FLEET_STATES, fleet_states, hourly_states
from tests.analysis.helpers import run_tiny_road


@pytest.fixture(scope="module")
def tiny_road(tmp_path_factory):
    return open_results(run_tiny_road(tmp_path_factory.mktemp("tiny_road"), "tiny_road"))


def _tables(res):
    return res.summary, res.table("tasks"), res.table("vehicles"), res.table("events")


def test_the_run_went_as_computed_by_hand(tiny_road):
    s, tasks, _, _ = _tables(tiny_road)
    t = tasks.set_index("task_id").sort_index()
    assert list(t["state"]) == ["completed", "completed", "expired", "completed"]
    assert list(t["picked_up_at"].fillna(-1)) == pytest.approx([0, 21, -1, 40])
    assert float(s["sim_time"].iloc[0]) == pytest.approx(50)


def test_customer_metrics_by_hand(tiny_road):
    s, tasks, vehicles, events = _tables(tiny_road)
    net = road_network(tiny_road.metadata(s["run_id"].iloc[0], "tasks"))
    direct = direct_seconds(tasks, net)
    m = M.taxi_metrics(s, tasks, vehicles, events, direct).iloc[0]
    assert (m["requests"], m["rides"], m["rejections"]) == (4, 3, 1)
    assert m["rejectionRate"] == pytest.approx(0.25)
    assert m["service_rate"] == pytest.approx(0.75)
    assert m["wait_average"] == pytest.approx(10)
    assert m["wait_median"] == pytest.approx(10)
    assert m["wait_p90"] == pytest.approx(18)  # linear between 10 and 20 at 0.9 of [0, 10, 20]
    assert m["wait_p95"] == pytest.approx(19)
    assert m["wait_max"] == pytest.approx(20)
    assert m["inVehicleTravelTime_mean"] == pytest.approx(50 / 3)
    assert m["directTravelTime_mean"] == pytest.approx(50 / 3)
    assert m["detour_ratio_mean"] == pytest.approx(1.0)
    assert m["assignment_delay_average"] == pytest.approx(0)  # assigned as released or freed
    assert m["approach_time_average"] == pytest.approx(10)  # 0, 20, 10


def test_vehicle_metrics_by_hand(tiny_road):
    s, tasks, vehicles, events = _tables(tiny_road)
    m = M.taxi_metrics(s, tasks, vehicles, events).iloc[0]
    assert m["vehicles"] == 2
    assert m["totalDistance"] == pytest.approx(800)
    assert m["totalEmptyDistance"] == pytest.approx(300)
    assert m["totalPassengerDistanceTraveled"] == pytest.approx(500)
    assert m["emptyRatio"] == pytest.approx(300 / 800)
    assert m["vkm_per_ride"] == pytest.approx(0.8 / 3)
    assert m["utilization"] == pytest.approx(80 / 100)
    # no network given: the run's own direct_time column (free-flow) gives the detour ratio
    assert m["detour_ratio_mean"] == pytest.approx(1.0)
    assert m["occupancy"] == pytest.approx(500 / 800)  # one-seat taxis: occupied / all km
    older = M.taxi_metrics(s, tasks.drop(columns=["direct_time"]), vehicles, events).iloc[0]
    assert np.isnan(older["detour_ratio_mean"])  # results written before it: no direct time


def test_fleet_states_by_hand(tiny_road):
    _, _, vehicles, events = _tables(tiny_road)
    st = fleet_states(events, vehicles, end=50.0)
    got = {a: [(r.state, r.start, r.end) for r in g.itertuples()]
           for a, g in st.groupby("agent_id")}
    assert got[0] == [("occupied", 0, 20), ("idle", 20, 30), ("to_pickup", 30, 40),
                      ("occupied", 40, 50)]
    assert got[1] == [("idle", 0, 1), ("to_pickup", 1, 21), ("occupied", 21, 41),
                      ("idle", 41, 50)]


def test_hourly_series_by_hand(tiny_road):
    s, tasks, vehicles, events = _tables(tiny_road)
    trips = M.trip_table(tasks, events)
    hc = M.hourly_customers(trips)
    assert len(hc) == 1 and hc["hour"].iloc[0] == 0
    assert (hc["requests"].iloc[0], hc["rides"].iloc[0], hc["rejections"].iloc[0]) == (4, 3, 1)
    states = fleet_states(events, vehicles, end=50.0)
    hf = M.hourly_fleet(states, s).iloc[0]
    # vehicle-seconds over the 50 s the run lasted: occupied 20 + 10 + 20, to a pickup
    # 10 + 20, idle 10 + 1 + 9; as mean vehicles (2 taxis): 1.0, 0.6, 0.4
    assert hf["occupied"] == pytest.approx(1.0)
    assert hf["to_pickup"] == pytest.approx(0.6)
    assert hf["idle"] == pytest.approx(0.4)
    assert hf["utilization"] == pytest.approx(0.8)


def _events(rows):
    return pd.DataFrame(rows, columns=["run_id", "t", "event", "agent_id", "task_id"])


def test_fleet_states_breakdown_and_repositioning():
    """A hand-written event stream: repositioning, an assignment, a breakdown on the way to the
    pickup, a repair; and hours split at the boundary."""
    ev = _events([("r", 100.0, "reposition", 0, -1), ("r", 400.0, "assign", 0, 7),
                  ("r", 3500.0, "breakdown", 0, 7), ("r", 3500.0, "reopen", 0, 7),
                  ("r", 3900.0, "repair", 0, -1), ("r", 3900.0, "idle", 0, -1)])
    vehicles = pd.DataFrame({"run_id": ["r"], "agent_id": [0]})
    st = fleet_states(ev, vehicles, end=4000.0)
    assert [(r.state, r.start, r.end) for r in st.itertuples()] == [
        ("idle", 0, 100), ("repositioning", 100, 400), ("to_pickup", 400, 3500),
        ("failed", 3500, 3900), ("idle", 3900, 4000)]
    h = hourly_states(st).set_index("hour")
    assert h.loc[0, "to_pickup"] == pytest.approx(3100)
    assert h.loc[0, "failed"] == pytest.approx(100)
    assert h.loc[1, "failed"] == pytest.approx(300)
    assert h.loc[1, "idle"] == pytest.approx(100)
    assert h[list(FLEET_STATES)].sum().sum() == pytest.approx(4000)
    summary = pd.DataFrame({"run_id": ["r"], "scenario": ["x"], "planner": ["p"],
                            "allocator": ["a"], "n_agents": [1]})
    hf = M.hourly_fleet(st, summary).set_index("hour")
    assert hf.loc[0, "utilization"] == pytest.approx(3100 / 3500)  # failed time is not available
    assert hf.loc[1, "utilization"] == pytest.approx(0)


def test_dynamic_metrics_are_per_task():
    s = pd.DataFrame({
        "scenario": "d", "planner": "p", "allocator": ["a", "a", "b"], "n_agents": 2,
        "seed": [0, 1, 0], "n_tasks": [10, 20, 10], "tasks_completed": [5, 20, 10],
        "wait_time_mean": [10.0, 20.0, 4.0], "total_cost": [50.0, 100.0, 30.0],
        "tasks_assigned": [5, 20, 10], "conflict_free_rate": [1.0, 0.5, 1.0],
        "alloc_seconds": [0.1, 0.2, 0.3], "decisions": [10, 20, 30]})
    d = M.dynamic_metrics(s).set_index("allocator")
    assert d.loc["a", "served_share_mean"] == pytest.approx(0.75)
    assert d.loc["a", "wait_mean_mean"] == pytest.approx(15)
    assert d.loc["a", "cost_per_assignment_mean"] == pytest.approx(7.5)  # (10 + 5) / 2
    assert d.loc["b", "cost_per_assignment_mean"] == pytest.approx(3)
    assert d.loc["a", "decision_ms_mean"] == pytest.approx(10)
