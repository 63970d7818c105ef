"""Shared rides end to end: random pooled runs on a Manhattan grid (capacity 1-6, with and
without ``max_delay``, faults on and off, every allocator) checked for the invariants of a stop
list from the events alone; a hand-computed shared ride; breakdowns with passengers on board;
clear errors for what pooling does not support."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

ALLOCATORS = ("hungarian", "greedy", "fcfs", "auction", "local_hungarian", "random", "magnnet")
EPS = 1e-6


def _trace(directory: Path, rng: np.random.Generator, n: int, max_pax: int) -> None:
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(8.0))
        o, d = rng.choice(30, size=2, replace=False)
        pax = int(rng.integers(1, max_pax + 1))
        delay = "" if rng.random() < 0.5 else round(float(rng.uniform(30, 400)), 1)
        rows.append((round(t, 3), int(o), int(d), pax, delay))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "passengers",
                                        "max_delay"], rows)


def _run(directory: Path, *, allocator: str, capacity: int, max_delay: float | None,
         faults: bool, objective: str, seed: int, service: float = 0.0):
    _trace(directory, np.random.default_rng(seed), 18, max(1, min(capacity, 3)))
    tasks = f'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0\nservice_time = {service}'
    if max_delay is not None:
        tasks += f"\nmax_delay = {max_delay}"
    extra = f'objective = "{objective}"'
    if faults:
        extra += '\n\n[faults]\nrate = 2.0\nrepair = 120.0\non_board = "transfer"'
    path = road_scenario(directory, tasks=tasks, fleet=f"agents = 3\ncapacity = {capacity}",
                         allocator=allocator, extra=extra, duration=1e5)
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def check_invariants(summary: dict, tables: dict) -> None:
    """The stop-list invariants, read from the events and the tasks table only."""
    tasks = tables["tasks"].set_index("task_id")
    ev = tables["events"]
    cap = tables["vehicles"].set_index("agent_id")["capacity"]
    # every request in exactly one terminal state, one terminal event each
    terminal = {"complete", "expire", "reject", "unreachable", "cut_off", "failed"}
    ends = ev[ev.event.isin(terminal)].groupby("task_id").size()
    assert (ends.reindex(tasks.index, fill_value=0) == 1).all()
    assert tasks.state.isin(["completed", "expired", "rejected", "unreachable", "cut_off",
                             "failed"]).all()
    # occupancy from the events never exceeds the capacity; a drop-off follows a pickup of
    # the same request by the same vehicle (a breakdown empties the vehicle)
    on_board: dict[int, dict[int, int]] = defaultdict(dict)
    rides: dict[int, int] = {}
    for e in ev.itertuples(index=False):
        a, k = int(e.agent_id), int(e.task_id)
        if e.event == "pickup":
            on_board[a][k] = int(tasks.passengers[k])
            assert sum(on_board[a].values()) <= cap[a], (a, on_board[a])
            rides[k] = a
        elif e.event == "dropoff":
            assert rides.get(k) == a and k in on_board[a], (e, rides.get(k))
            del on_board[a][k]
        elif e.event == "breakdown":
            on_board[a].clear()
    # every completed request within its limits (none transferred: a breakdown owes a ride)
    drop = ev[ev.event == "dropoff"].groupby("task_id").t.max()
    done = tasks[(tasks.state == "completed") & (tasks.transfers == 0)]
    wait = done.picked_up_at - done.released_at
    assert (wait[done.max_wait.notna()] <= done.max_wait[done.max_wait.notna()] + EPS).all()
    limited = done[done.max_delay.notna() & done.dropoff_x.notna()]
    late = drop[limited.index] - limited.released_at - limited.direct_time - limited.max_delay
    assert (late <= EPS).all(), late[late > EPS]
    # passenger-metres: between the occupied metres and capacity times them; occupancy
    veh = tables["vehicles"]
    assert (veh.passenger_distance >= veh.occupied_distance - EPS).all()
    assert (veh.passenger_distance <= veh.capacity * veh.occupied_distance + EPS).all()
    assert np.isclose(veh.distance, veh.empty_distance + veh.occupied_distance).all()
    if summary["distance"] > 0:
        assert summary["occupancy"] == pytest.approx(
            veh.passenger_distance.sum() / veh.distance.sum())


CASES = [(alloc, cap, delay, faults, obj, seed)
         for seed, (alloc, cap, delay, faults, obj) in enumerate(
             (ALLOCATORS[i % 7], 1 + i % 6, (None, 150.0)[i // 7 % 2], bool(i // 3 % 2),
              ("pickup_time", "added_time")[i // 5 % 2]) for i in range(210))]


@pytest.mark.parametrize("allocator", ALLOCATORS)
def test_invariants_on_random_pooled_runs(tmp_path, allocator):
    """30 random runs per allocator (210 in all): capacities 1-6, with and without
    max_delay, faults on and off, both objectives."""
    mine = [c for c in CASES if c[0] == allocator]
    shared = 0
    for k, (alloc, cap, delay, faults, obj, seed) in enumerate(mine):
        d = tmp_path / f"run{k}"
        d.mkdir()
        summary, tables = _run(d, allocator=alloc, capacity=cap, max_delay=delay,
                               faults=faults, objective=obj, seed=seed,
                               service=5.0 if k % 4 == 0 else 0.0)
        check_invariants(summary, tables)
        shared += int(tables["tasks"].shared.sum())
    assert shared > 0  # the runs do share rides


def test_a_shared_ride_by_hand(tmp_path):
    """One 2-seat taxi on a line of 100 m blocks at 10 m/s: A rides 0 -> 4, B (released while
    the taxi drives to A) rides 1 -> 3. With added_time the taxi picks B up on the way:
    0 -(A)- 1 -(B)- 3 -(B off)- 4 -(A off). Passenger-metres: A 400 m, B 200 m."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 0, 4), (1.0, 1, 3)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                                         'max_wait = 100.0\nmax_delay = 100.0',
                         fleet='start = "fleet.csv"\ncapacity = 2',
                         network='network = "manhattan"\nblocks = [5, 2]\nblock = 100.0\n'
                                 'speed = 10.0', allocator="hungarian",
                         extra='objective = "added_time"')
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    tasks = r.tables["tasks"].to_pandas().set_index("task_id").sort_index()
    veh = r.tables["vehicles"].to_pandas().iloc[0]
    assert list(tasks.state) == ["completed", "completed"]
    assert tasks.shared.all()
    assert tasks.picked_up_at.tolist() == pytest.approx([0.0, 10.0])
    assert tasks.completed_at.tolist() == pytest.approx([40.0, 30.0])
    assert tasks.direct_time.tolist() == pytest.approx([40.0, 20.0])
    assert veh.distance == pytest.approx(400.0)
    assert veh.passenger_distance == pytest.approx(600.0)
    assert r.summary["occupancy"] == pytest.approx(1.5)
    assert r.summary["shared_rate"] == pytest.approx(1.0)
    # A: 40 - 0 - 40 = 0 s; B: released at 1, dropped at 30, direct 20: 9 s
    assert r.summary["delay_mean"] == pytest.approx(4.5)
    assert r.summary["detour_ratio"] == pytest.approx((40 / 40 + 20 / 20) / 2)
    ev = r.tables["events"].to_pandas()
    assert (ev.event == "insert").sum() == 1  # B went into A's plan


def test_a_request_larger_than_every_vehicle_is_rejected(tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node", "passengers"],
              [(0.0, 0, 4, 5), (1.0, 1, 3, 2)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet="agents = 2\ncapacity = 4")
    [spec] = load_scenario(path).runs()
    tasks = run_one(spec).tables["tasks"].to_pandas().set_index("task_id").sort_index()
    assert list(tasks.state) == ["rejected", "completed"]
    assert list(tasks.passengers) == [5, 2]


def test_breakdown_with_passengers_on_board(tmp_path):
    """A 4-seat taxi carrying two requests breaks down: with transfers both are picked up
    again by the other taxi and completed; without, both end failed. None is lost."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 0, 29), (5.0, 0, 28)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0), (1, 25)])
    write_csv(tmp_path / "fail.csv", ["t", "vehicle_id", "duration"], [(40.0, 0, "inf")])
    for transfer, want in ((True, "completed"), (False, "failed")):
        path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                             fleet='start = "fleet.csv"\ncapacity = 4',
                             extra=f'batch_window = 1.0\n\n[faults]\nfile = "fail.csv"\n'
                                   f'on_board = "{"transfer" if transfer else "fail"}"')
        [spec] = load_scenario(path).runs()
        r = run_one(spec)
        tasks = r.tables["tasks"].to_pandas().sort_values("task_id")
        ev = r.tables["events"].to_pandas()
        assert (ev.event == "breakdown").sum() == 1
        picked_by_0 = ev[(ev.event == "pickup") & (ev.agent_id == 0)].task_id.nunique()
        assert picked_by_0 == 2  # both were on board when it failed
        assert list(tasks.state) == [want, want]
        if transfer:
            assert (tasks.transfers == 1).all() and (tasks.agent_id == 1).all()
        check_invariants(r.summary, {n: t.to_pandas() for n, t in r.tables.items()})


@pytest.mark.parametrize("extra, key", [
    ("[fleet]\ncapacity = 2", "fleet.capacity"),
    ("[tasks]\nmax_delay = 60.0", "tasks.max_delay"),
])
def test_pooling_in_a_voxel_world_is_refused(tmp_path, extra, key):
    path = tmp_path / "v.toml"
    path.write_text(f'name = "v"\n{extra}\n', encoding="utf-8")
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    assert key in str(e.value) and "road network" in str(e.value)


def test_reassign_with_seats_is_refused(tmp_path):
    path = road_scenario(tmp_path, tasks='source = "static"\ncount = 3',
                         fleet="agents = 2\ncapacity = 3", extra="reassign = true")
    with pytest.raises(ScenarioError, match="dispatch.reassign"):
        load_scenario(path)


def test_start_file_capacity_column(tmp_path):
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node", "capacity"],
              [(0, 0, 4), (1, 5, ""), (2, 9, 1)])
    path = road_scenario(tmp_path, tasks='source = "static"\ncount = 3',
                         fleet='start = "fleet.csv"\ncapacity = 2')
    [spec] = load_scenario(path).runs()
    veh = run_one(spec).tables["vehicles"].to_pandas()
    assert list(veh.capacity) == [4, 2, 1]
    bad = write_csv(tmp_path / "bad.csv", ["vehicle_id", "node", "capacity"], [(0, 0, 0.5)])
    path = road_scenario(tmp_path, tasks='source = "static"\ncount = 3',
                         fleet=f'start = "{bad.name}"')
    with pytest.raises(ScenarioError, match="row 1.*capacity"):
        load_scenario(path)


def test_capacity_one_never_shares(tmp_path):
    summary, tables = _run(tmp_path, allocator="hungarian", capacity=1, max_delay=None,
                           faults=False, objective="pickup_time", seed=1)
    assert not tables["tasks"].shared.any()
    assert summary["occupancy"] <= 1.0 + 1e-12
    assert not (tables["events"].event == "insert").any()
    assert math.isclose(tables["vehicles"].passenger_distance.sum(),
                        tables["vehicles"].occupied_distance.sum())


def test_allocators_read_the_plans_read_only(tmp_path):
    """``problem.plans`` holds the stop list of each busy agent of a pooled decision, as the
    vehicle has it (kinds, requests, occupancies, planned times in order), and cannot be
    changed through it."""
    from allocators.hungarian import HungarianAllocator
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation

    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 0, 4), (1.0, 1, 3)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"\ncapacity = 2')
    [spec] = load_scenario(path).runs()
    seen = []

    class Spy(HungarianAllocator):
        def allocate(self, problem):
            seen.append({a: problem.plans[a] for a in problem.plans})
            with pytest.raises(TypeError):
                problem.plans[0] = ()  # type: ignore[index]
            return super().allocate(problem)

    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"), allocator=Spy())
    sim.run()
    assert seen[0] == {}  # the first request: the taxi is idle
    [(agent, stops)] = seen[1].items()
    assert agent == 0
    # A was picked up at once where the taxi stood: its drop-off is what is left
    assert [(s.kind, s.task_id, s.loc, s.passengers, s.occupancy) for s in stops] == [
        ("dropoff", 0, 4, -1, 0)]
    assert stops[0].eta == pytest.approx(40.0)


def _two_requests_one_taxi(tmp_path, route, capacity=2):
    """Two requests released together, one taxi, an allocator that gives it both along
    ``route`` (``Allocation.routes``); returns the run's tables or raises its error."""
    from dispatch.api.contracts import Allocator
    from dispatch.api.problem import Allocation
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation

    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(0.0, 1, 4), (0.0, 2, 3)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                                         'max_wait = 100.0\nmax_delay = 100.0',
                         fleet=f'start = "fleet.csv"\ncapacity = {capacity}',
                         network='network = "manhattan"\nblocks = [5, 2]\nblock = 100.0\n'
                                 'speed = 10.0')
    [spec] = load_scenario(path).runs()

    class Both(Allocator):
        name = "both"
        multi_request = True

        def allocate(self, problem):
            if not len(problem.tasks):
                return Allocation(pairs=())
            return Allocation(pairs=((0, 0), (0, 1)), routes={0: route})

    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"), allocator=Both())
    sim.run()
    sim.recorder.finish()
    import pyarrow.parquet as pq
    return {n: pq.read_table(next((tmp_path / "out" / n).rglob("part-0.parquet"))).to_pandas()
            for n in ("tasks", "events")}


def test_a_multi_request_route_is_driven(tmp_path):
    """0 -> pick A at 1 -> pick B at 2 -> drop B at 3 -> drop A at 4 (10 s a block)."""
    route = (("pickup", 0), ("pickup", 1), ("dropoff", 1), ("dropoff", 0))
    got = _two_requests_one_taxi(tmp_path, route)
    tasks = got["tasks"].set_index("task_id").sort_index()
    assert list(tasks.state) == ["completed", "completed"]
    assert list(tasks.agent_id) == [0, 0] and tasks.shared.all()
    assert tasks.picked_up_at.tolist() == pytest.approx([10.0, 20.0])
    assert tasks.completed_at.tolist() == pytest.approx([40.0, 30.0])
    assert tasks.cost.tolist() == pytest.approx([10.0, 20.0])  # seconds to the planned pickup


@pytest.mark.parametrize("route, capacity, why", [
    ((("dropoff", 0), ("pickup", 0), ("pickup", 1), ("dropoff", 1)), 2, "before its pickup"),
    ((("pickup", 0), ("pickup", 1), ("dropoff", 1)), 2, "missing"),
    ((("pickup", 0), ("pickup", 1), ("dropoff", 1), ("dropoff", 0)), 1, "capacity"),
    ((("pickup", 0), ("dropoff", 0), ("pickup", 1), ("dropoff", 1), ("pickup", 0)), 2,
     "once each"),
])
def test_a_bad_route_is_refused(tmp_path, route, capacity, why):
    from dispatch.errors import AllocationError

    with pytest.raises(AllocationError, match=why):
        _two_requests_one_taxi(tmp_path, route, capacity)
