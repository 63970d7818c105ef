"""One operator drives every stop: a vehicle that charges, is dispatched part-way through a
repositioning move, runs its battery empty with a rider on board (stranded: a breakdown) and is
towed, all through :class:`dispatch.plan.operator.Operator`'s process; the invariants checked from
the events (occupancy within capacity, energy balance, one terminal state per request)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from dispatch.run.runner import make_recorder
from dispatch.run.sim import Simulation
from dispatch.scenario.load import load_scenario

TERMINAL = {"complete", "expire", "reject", "unreachable", "cut_off", "failed"}
#: 10 x 2 intersections, 200 m blocks at 10 m/s: an edge is 20 s; node = row * 10 + column
GRID = 'network = "manhattan"\nblocks = [10, 2]\nblock = 200.0\nspeed = 10.0'
#: events the operator's own processes emit (the vehicle's plan process, a repair or a tow)
DRIVEN = {"queue", "charge_start", "charge_end", "pickup", "dropoff", "stranded", "breakdown",
          "repair"}


def scenario(d: Path) -> Path:
    # the vehicle stands at the station (node 1) with 0.1 kWh of 1 kWh; 150 Wh/km at 10 m/s
    # is 0.0015 kWh/s driving, plus 3.6 kWh/h (0.001 kWh/s) auxiliary, which the reserve rule
    # does not see. t = 60: charged from 0.04 to 0.35 kWh at 3.6 kW (310 s, to t = 370).
    # t = 400: sent toward the zone of the early requests (unreachable in 1 s: rejected, but
    # demand). t = 410: a trip from node 3 to node 19, 10 s into the move (on edge 1 -> 2):
    # the move is cut, pickup at 440; the drop-off leg (140 s) needs 0.35 kWh, it has ~0.22:
    # stranded with the rider on board (on_board = "fail"), towed to the station in 100 s,
    # charged again, and it serves a last trip at t = 1000
    (d / "fleet.csv").write_text("vehicle_id,node\n0,1\n")
    (d / "trips.csv").write_text("t,origin_node,dest_node,max_wait\n10,4,14,1\n20,13,14,1\n"
                                 "30,14,4,1\n410,3,19,600\n1000,2,0,600\n")
    (d / "st.csv").write_text("station_id,node,plugs,kw\nS,1,1,3.6\n")
    p = d / "one.toml"
    p.write_text(
        f'name = "one"\nseed = 1\nduration = 100000.0\n[world]\n{GRID}\n'
        '[fleet]\nstart = "fleet.csv"\ncapacity = 2\n[fleet.energy]\nbattery_kwh = 1.0\n'
        'wh_per_km = 150.0\nidle_kwh_per_hour = 3.6\nsoc0 = 0.1\nreserve = 0.0\n'
        '[tasks]\nsource = "trace"\ntrace = "trips.csv"\nmax_wait = 600.0\n'
        '[dispatch]\nallocator = "fcfs"\n'
        '[chargers]\nfile = "st.csv"\n[charging]\nstrategy = "threshold"\ninterval = 60.0\n'
        '[charging.threshold]\nlow = 0.2\nhigh = 0.35\n'
        '[reposition]\npolicy = "demand"\ninterval = 100.0\nhorizon = 1000.0\n'
        '[reposition.demand]\nzone = 600.0\n'
        '[faults]\ntow = 100.0\non_board = "fail"\n', encoding="utf-8")
    return p


def test_charge_reposition_cut_strand_and_tow_by_one_operator(tmp_path):
    [spec] = load_scenario(scenario(tmp_path)).runs()
    recorder = make_recorder(spec, tmp_path / "out")
    sim = Simulation(spec, recorder)
    by = []  # (event, the process that emitted it)

    def seen(e):
        p = sim.env.active_process
        by.append((e.kind, None if p is None else p._generator.__qualname__))

    sim.bus.subscribe(seen)
    summary = sim.run()
    recorder.finish()

    ev = pd.read_parquet(tmp_path / "out" / "events")
    tasks = pd.read_parquet(tmp_path / "out" / "tasks")
    veh = pd.read_parquet(tmp_path / "out" / "vehicles").iloc[0]
    mine = ev[ev.agent_id == 0]
    kinds = mine.event.tolist()

    # the story: a charge, a move cut by a dispatch, a pickup, a stranding, a tow
    story = ["charge_start", "charge_end", "reposition", "assign", "pickup", "stranded",
             "breakdown", "repair", "charge_start", "charge_end", "assign", "pickup", "dropoff"]
    at, k0 = [], 0
    for k in story:
        k0 = kinds.index(k, k0)
        at.append(k0)
    assert at == sorted(at)
    move = mine[mine.event == "reposition"].iloc[0]
    cut = mine[mine.event == "assign"].iloc[0]
    # dispatched part-way: no idle between the move and the assignment, which came before the
    # move's arrival (60 s from node 1 to node 4)
    between = kinds[kinds.index("reposition"):kinds.index("assign")]
    assert "idle" not in between and cut.t < move.t + 60.0
    assert summary["repositions"] >= 1 and 0 < summary["reposition_distance"] < 600.0
    stranded = mine[mine.event == "stranded"].iloc[0]
    repair = mine[mine.event == "repair"].iloc[0]
    assert repair.t == pytest.approx(stranded.t + 100.0) and repair.x == 200.0  # at node 1
    # one operator: every stop's events come from its processes (its repair is its
    # Breakdowns base's), no charging or repositioning process of their own
    owners = {q for k, q in by if k in DRIVEN}
    assert owners <= {"Operator.drive", "Breakdowns._repair"}, owners
    assert all(q.startswith(("Operator.", "Breakdowns.")) for k, q in by if k == "idle")

    # occupancy never above the capacity (a breakdown empties the vehicle)
    load, cap = 0, 2
    for k in kinds:
        load = {"pickup": load + 1, "dropoff": load - 1, "breakdown": 0}.get(k, load)
        assert 0 <= load <= cap
    assert load == 0
    # the rider on board when it stranded: failed
    trip = tasks[tasks.task_id == cut.task_id].iloc[0]
    assert trip.state == "failed" and summary["tasks_completed"] == 1
    # energy balance: start + charged - drawn = end, to 1e-9 kWh
    assert abs(0.1 + veh.kwh_charged - veh.kwh_drawn - veh.soc_end * 1.0) < 1e-9
    assert veh.kwh_charged > 0.3 and veh.soc_min >= 0.0
    # each request exactly one terminal state
    released = set(ev[ev.event == "release"].task_id)
    terminal = ev[ev.event.isin(TERMINAL)]
    assert terminal.task_id.is_unique and set(terminal.task_id) == released
    assert set(tasks.task_id) == released


@pytest.mark.parametrize("allocator", ["rtv", "hungarian"])
def test_pooled_decisions_cut_repositioning_moves(tmp_path, allocator):
    # a repositioning move is a stop of the plan that a decision does not keep: pooled
    # decisions (rtv's routes, insertions) see the vehicle's plan as empty and cut the move
    p = tmp_path / "pool.toml"
    p.write_text(
        'name = "pool"\nseed = 1\nduration = 20000.0\n[world]\nnetwork = "manhattan"\n'
        'blocks = [8, 8]\nblock = 200.0\nspeed = 10.0\n[fleet]\nagents = 6\ncapacity = 2\n'
        '[tasks]\nsource = "poisson"\nrate = 0.03\ncount = 120\nmax_wait = 300.0\n'
        f'max_delay = 600.0\n[dispatch]\nallocator = "{allocator}"\nbatch_window = 20.0\n'
        'objective = "added_time"\n[reposition]\npolicy = "demand"\ninterval = 60.0\n'
        'horizon = 1000.0\n[reposition.demand]\nzone = 600.0\n', encoding="utf-8")
    [spec] = load_scenario(p).runs()
    recorder = make_recorder(spec, tmp_path / "out")
    summary = Simulation(spec, recorder).run()
    recorder.finish()
    ev = pd.read_parquet(tmp_path / "out" / "events")
    cuts = 0
    for _, g in ev[ev.agent_id >= 0].groupby("agent_id"):
        moving, load = False, 0
        for k in g.event:
            if k == "reposition":
                assert load == 0  # only an idle vehicle repositions
                moving = True
            elif k == "idle":
                moving = False
            elif k == "assign":
                cuts += moving
                moving = False
            load = {"pickup": load + 1, "dropoff": load - 1}.get(k, load)
            assert 0 <= load <= 2
    assert summary["repositions"] > 0 and cuts > 0
    terminal = ev[ev.event.isin(TERMINAL)]
    assert terminal.task_id.is_unique
    assert set(terminal.task_id) == set(ev[ev.event == "release"].task_id)
