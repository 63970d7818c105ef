"""Vehicle breakdowns and communication blackouts: nothing lost, nothing served twice.

Random scenarios with faults in both spaces (a sample here, 500 more under ``-m slow``): every
trip ends in exactly one terminal state, none is served twice, a failed vehicle never moves
while failed, distances add up, re-assigned trips have one task row and several assignments.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.conftest import write_scenario

TERMINAL = {"completed": "complete", "expired": "expire", "rejected": "reject",
            "unreachable": "unreachable", "cut_off": "cut_off", "failed": "failed"}
MOVING = ("depart", "move", "pickup", "dropoff")


def road_text(rng, faults: str) -> str:
    cols, rows = (int(x) for x in rng.integers(3, 7, size=2))
    source = rng.choice(["static", "poisson", "periodic"])
    tasks = {"static": f'source = "static"\ncount = {int(rng.integers(3, 15))}',
             "poisson": f'source = "poisson"\nrate = {float(rng.uniform(0.02, 0.2)):.3f}\n'
                        f'count = {int(rng.integers(5, 30))}',
             "periodic": f'source = "periodic"\ninterval = {float(rng.uniform(5, 30)):.1f}\n'
                         f'count = {int(rng.integers(5, 30))}'}[source]
    if rng.random() < 0.5:
        tasks += f"\nmax_wait = {float(rng.uniform(60, 600)):.0f}"
    alloc = rng.choice(["fcfs", "hungarian", "greedy", "auction"])
    return (f'name = "faulty"\nseed = {int(rng.integers(0, 1000))}\nduration = 20000.0\n\n'
            f'[world]\nnetwork = "manhattan"\nblocks = [{cols}, {rows}]\nblock = 100.0\n'
            f'speed = 10.0\n\n[fleet]\nagents = {int(rng.integers(1, 6))}\n\n[tasks]\n{tasks}\n'
            f'service_time = {float(rng.choice([0.0, 5.0]))}\n\n'
            f'[dispatch]\nallocator = "{alloc}"\nplanner = "dijkstra"\n'
            f'batch_window = {float(rng.choice([0.0, 0.0, 10.0]))}\n\n[faults]\n{faults}\n')


def random_faults(rng) -> str:
    lines = [f"rate = {float(rng.uniform(0.5, 6.0)):.2f}",
             f"repair = {rng.choice(['30.0', '300.0', 'inf'])}",
             f'on_board = "{rng.choice(["transfer", "fail"])}"']
    if rng.random() < 0.3:
        lines.append("blackout = [[0.0, 200.0]]")
    return "\n".join(lines)


def check(r) -> dict:
    t = {n: tb.to_pandas() for n, tb in r.tables.items()}
    tasks, ev, veh, s = t["tasks"], t["events"], t["vehicles"], r.summary
    released = ev[ev.event == "release"]
    assert tasks.task_id.is_unique and sorted(tasks.task_id) == sorted(released.task_id)
    term = ev[ev.event.isin(TERMINAL.values())]
    assert term.task_id.is_unique and set(term.task_id) == set(tasks.task_id)
    for row in tasks.itertuples():
        assert term.set_index("task_id").event[row.task_id] == TERMINAL[row.state]
    # never served twice: one drop-off / completion per trip, by the vehicle of its row
    done = ev[ev.event == "complete"]
    assert done.task_id.is_unique
    comp = tasks[tasks.state == "completed"]
    assert (comp.picked_up_at <= comp.completed_at).all()
    assert (comp.released_at <= comp.picked_up_at).all()
    # a failed vehicle does not move while failed
    for agent, g in ev[ev.agent_id >= 0].sort_values("t", kind="stable").groupby("agent_id"):
        down = False
        for e in g.itertuples():
            if e.event == "breakdown":
                assert not down
                down = True
            elif e.event == "repair":
                assert down
                down = False
            elif e.event in MOVING:
                assert not down, (agent, e)
    # distances add up; failures counted
    assert np.allclose(veh.distance, veh.empty_distance + veh.occupied_distance)
    assert s["failures"] == veh.failures.sum() == (ev.event == "breakdown").sum()
    reopened = ev[ev.event == "reopen"]
    assert s["tasks_reassigned"] == reopened.task_id.nunique() == (tasks.reassigned > 0).sum()
    assert tasks.reassigned.sum() == len(reopened)
    # a re-assigned trip has one task row and one won assignment per time it was handed out
    won = t["assignments"][t["assignments"].won]
    handed = won.groupby("task_id").size()
    for row in tasks[tasks.reassigned > 0].itertuples():
        assert handed.get(row.task_id, 0) >= 1
    for state in TERMINAL:
        assert s[f"tasks_{state}"] == (tasks.state == state).sum()
    return {"faults": int(s["failures"]), "reassigned": int(s["tasks_reassigned"]),
            "transferred": int(s["tasks_transferred"]), "failed": int(s["tasks_failed"])}


def run_random(tmp_path: Path, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    path = tmp_path / f"f{seed}.toml"
    path.write_text(road_text(rng, random_faults(rng)))
    [spec] = load_scenario(path).runs()
    return check(run_one(spec))


def run_random_voxel(tmp_path: Path, seed: int) -> dict:
    """A tiny voxel world (tests/conftest.py) with breakdowns, every source but traces, with
    or without reservations."""
    rng = np.random.default_rng(seed)
    source = str(rng.choice(["static", "poisson", "periodic"]))
    tasks = {"source": source, "count": int(rng.integers(3, 15)),
             "service_time": float(rng.choice([0.0, 1.0]))}
    if source == "poisson":
        tasks["rate"] = float(rng.uniform(0.2, 1.0))
    if source == "periodic":
        tasks["interval"] = float(rng.uniform(1.0, 4.0))
    if rng.random() < 0.3:
        tasks["ttl"] = 30.0
    planner = str(rng.choice(["astar", "astar", "reservation"]))
    faults = (f"rate = {float(rng.uniform(100.0, 400.0)):.1f}\n"  # tiny runs: tens of seconds
              f"repair = {rng.choice(['3.0', '10.0', 'inf'])}\n"
              f'on_board = "{rng.choice(["transfer", "fail"])}"')
    path = write_scenario(tmp_path, f"v{seed}.toml", seed=int(rng.integers(0, 1000)),
                          fleet={"agents": int(rng.integers(1, 6))}, tasks=tasks,
                          dispatch={"allocator": str(rng.choice(["hungarian", "greedy",
                                                                   "auction"])),
                                    "planner": planner},
                          duration=2000.0, extra=f"[faults]\n{faults}\n")
    [spec] = load_scenario(path).runs()
    return check(run_one(spec))


def test_random_voxel_scenarios_with_breakdowns(tmp_path):
    totals = pd.DataFrame([run_random_voxel(tmp_path, seed) for seed in range(15)]).sum()
    assert totals["faults"] > 10


def test_random_road_scenarios_with_breakdowns(tmp_path):
    totals = pd.DataFrame([run_random(tmp_path, seed) for seed in range(40)]).sum()
    assert totals["faults"] > 20 and totals["reassigned"] > 5  # the sample exercises faults
    assert totals["transferred"] + totals["failed"] > 0


@pytest.mark.slow
def test_500_random_road_and_200_voxel_scenarios_with_breakdowns(tmp_path):
    road = pd.DataFrame([run_random(tmp_path, seed) for seed in range(1000, 1500)]).sum()
    voxel = pd.DataFrame([run_random_voxel(tmp_path, s) for s in range(1000, 1200)]).sum()
    for name, totals in (("road", road), ("voxel", voxel)):  # the closing note's counts
        print(f"\nfaults, {name}: " + ", ".join(f"{k} {int(v)}" for k, v in totals.items()))
    assert road["faults"] > 200 and voxel["faults"] > 100


def two_taxis(tmp_path: Path, *, trip: str, failure: str, on_board: str = "transfer"):
    """A 10 x 10 grid (100 m blocks, 10 m/s), taxi 0 on node 0 and taxi 1 on node 99, one
    trip (``t,origin_node,dest_node``) and one scheduled breakdown (``t,vehicle_id,duration``);
    the run, checked."""
    (tmp_path / "trips.csv").write_text(f"t,origin_node,dest_node\n{trip}\n")
    (tmp_path / "fleet.csv").write_text("vehicle_id,node\n0,0\n1,99\n")
    (tmp_path / "fail.csv").write_text(f"t,vehicle_id,duration\n{failure}\n")
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nduration = 5000.0\n[world]\nnetwork = "manhattan"\n'
                    'blocks = [10, 10]\nblock = 100.0\nspeed = 10.0\n[fleet]\n'
                    'start = "fleet.csv"\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                    f'[dispatch]\nallocator = "fcfs"\n[faults]\nfile = "fail.csv"\n'
                    f'on_board = "{on_board}"\n')
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    check(r)
    return r


@pytest.mark.parametrize("on_board", ["transfer", "fail"])
def test_a_breakdown_with_the_passenger_on_board(tmp_path, on_board):
    """One taxi, one long trip, a breakdown half-way to the drop-off: the passenger is
    transferred to the second taxi (picked up where the first stopped) or the trip fails."""
    r = two_taxis(tmp_path, trip="0,0,9", failure="40,0,inf", on_board=on_board)
    task = r.tables["tasks"].to_pandas().iloc[0]
    veh = r.tables["vehicles"].to_pandas().set_index("agent_id")
    assert veh.loc[0, "failures"] == 1
    assert veh.loc[0, "occupied_distance"] == pytest.approx(400.0)  # 40 s at 10 m/s
    assert task.picked_up_at == 0.0 and (task.x, task.y) == (0.0, 0.0)  # the requested pickup
    if on_board == "fail":
        assert task.state == "failed" and task.closed_at == 40.0
        assert veh.loc[1, "tasks_completed"] == 0
    else:
        assert task.state == "completed" and task.transfers == 1 and task.agent_id == 1
        # taxi 1 drives from node 99 to the node taxi 0 was at (400 m along row 0), then on
        assert veh.loc[1, "empty_distance"] == pytest.approx(900 + 900 - 400)
        assert veh.loc[1, "occupied_distance"] == pytest.approx(500.0)
        assert task.completed_at == pytest.approx(40 + 140 + 50)


def test_a_trip_not_yet_picked_up_is_reassigned_and_repaired_vehicles_return(tmp_path):
    r = two_taxis(tmp_path, trip="0,9,0", failure="20,0,100")
    ev = r.tables["events"].to_pandas()
    task = r.tables["tasks"].to_pandas().iloc[0]
    assert task.reassigned == 1 and task.transfers == 0 and task.state == "completed"
    # at t = 20 taxi 0 stands 200 m along the row, closer than taxi 1 (900 m), yet failed
    assigns = ev[ev.event == "assign"]
    assert list(assigns.agent_id) == [0, 1] and list(assigns.t) == [0.0, 20.0]
    assert list(ev[ev.agent_id == 0].event)[-2:] == ["repair", "idle"]
    veh = r.tables["vehicles"].to_pandas().set_index("agent_id")
    assert veh.loc[0, "down_seconds"] == pytest.approx(100.0)
    assert veh.loc[0, "empty_distance"] == pytest.approx(200.0)


def decentralized_allocators() -> list[str]:
    from dispatch.api.registry import available, load

    return [n for n in available("allocator") if getattr(load("allocator", n),
                                                         "decentralized", False)]


@pytest.mark.parametrize("allocator", decentralized_allocators())
def test_blackout_and_loss_still_assign_every_task(make_scenario, allocator):
    """During a blackout decentralized allocators hear only themselves; with 30 % message
    loss on top, every task is still assigned and completed."""
    path = make_scenario(fleet={"agents": 6}, tasks={"source": "periodic", "interval": 3.0,
                                                     "count": 12},
                         dispatch={"allocator": allocator},
                         extra="[comms]\nrange = 8.0\nloss = 0.3\n\n[faults]\n"
                               "blackout = [[0.0, 20.0]]\n")
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    tasks = r.tables["tasks"].to_pandas()
    assert (tasks.state == "completed").all()
    dec = r.tables["decisions"].to_pandas()
    early = dec[dec.t < 20.0]
    assert len(early) and (early.comm_components == early.n_idle).all()  # nobody linked


def test_voxel_breakdowns(make_scenario):
    path = make_scenario(fleet={"agents": 4}, tasks={"source": "poisson", "rate": 0.3,
                                                     "count": 20},
                         extra="[faults]\nrate = 30.0\nrepair = 5.0\n")
    [spec] = load_scenario(path).runs()
    out = check(run_one(spec))
    assert out["faults"] > 0


@pytest.mark.parametrize("faults, key", [
    ("rate = -1.0", "faults.rate"),
    ("repair = 0.0", "faults.repair"),
    ('on_board = "eject"', "faults.on_board"),
    ("blackout = [[5.0, 1.0]]", "faults.blackout"),
    ("blackout_region = [0.0, 0.0, 1.0, 1.0]", "faults.blackout_region"),
    ('file = "nope.csv"', "faults.file: nope.csv cannot be read: file not found"),
])
def test_bad_fault_settings_are_named(make_scenario, faults, key):
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")):
        load_scenario(make_scenario(extra=f"[faults]\n{faults}\n"))


@pytest.mark.parametrize("seed, on_board", [(s, o) for s in range(4)
                                             for o in ("transfer", "fail")])
def test_breakdowns_with_reservations_keep_vehicles_apart(tmp_path, seed, on_board):
    """Reservation-based execution (the crowded scenario's world): a broken-down vehicle holds
    its cell hard, releases the rest of its route, never moves while failed; nobody ever
    shares a cell; every task still ends once."""
    from dispatch.space.world import world_for
    from tests.dispatch.test_reservations import Recorded, check_run

    path = write_scenario(tmp_path, world={"size": [10, 10, 3]},
                          obstacles={"count": 8, "min_size": [1, 1, 3], "max_size": [3, 3, 3]},
                          fleet={"agents": 8, "uav_max_start_altitude": 2.0},
                          tasks={"source": "poisson", "rate": 0.5, "count": 20,
                                 "service_time": 2.0},
                          dispatch={"planner": "reservation"}, seed=seed, duration=400.0,
                          extra=f'[faults]\nrate = 40.0\nrepair = 8.0\non_board = "{on_board}"\n')
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    out = check(r)
    t = {n: tb.to_pandas() for n, tb in r.tables.items()}
    check_run(Recorded(world_for(spec.scenario.world, spec.seed).grid, t))
    assert out["faults"] > 0


def test_same_seed_same_faults(tmp_path):
    rng = np.random.default_rng(5)
    path = tmp_path / "s.toml"
    path.write_text(road_text(rng, "rate = 3.0\nrepair = 60.0"))
    [spec] = load_scenario(path).runs()
    a, b = run_one(spec), run_one(spec)
    cols = ["t", "event", "agent_id", "task_id"]
    assert a.tables["events"].select(cols).equals(b.tables["events"].select(cols))
    assert math.isclose(a.summary["distance"], b.summary["distance"])
