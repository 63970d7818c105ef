"""The exact vehicle cut (dispatch.decide.nearest): a one-request decision of an allocator that
declares ``nearest_cut`` costs the idle vehicles nearest first and stops where none left can be
cheaper, and takes the vehicle the whole column takes, at the same cost."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from dispatch.api import registry
from dispatch.api.problem import AgentView, AgentViews, AllocationProblem, TaskView
from dispatch.decide import nearest, one_request, pipeline
from dispatch.plan.idle_places import MOVING, NOT_IDLE, IdlePlaces
from dispatch.run.runner import execute
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import RoadNetwork
from tests.dispatch.test_determinism import read_run
from tests.dispatch.test_one_request import assert_same_tables

ROOT = Path(__file__).resolve().parents[2]
#: the shipped scenarios on road networks
ROAD = sorted(p.name for p in (ROOT / "scenarios").glob("*.toml")
              if "\nnetwork =" in p.read_text())


@cache
def cut_allocators() -> tuple:
    """An instance of every registered allocator that declares it may be cut."""
    out = []
    for name in sorted(registry.available("allocator")):
        cls = registry.load("allocator", name)
        if cls.nearest_cut:
            out.append(cls())
    return tuple(out)


def test_declarations():
    """fcfs and hungarian may be cut; hungarian with a learned value (adjusted costs), greedy
    (every requester's bid is recorded) and a subclass that answers itself may not."""
    names = {a.name for a in cut_allocators()}
    assert {"fcfs", "hungarian"} <= names
    assert "greedy" not in names and "rtv" not in names
    from allocators.hungarian import HungarianAllocator

    class Own(HungarianAllocator):
        def allocate(self, problem):
            return super().allocate(problem)

    assert not Own.nearest_cut and HungarianAllocator.nearest_cut
    assert all(a.one_by_minimum for a in cut_allocators())


def random_network(rng) -> RoadNetwork:
    """Nodes scattered on a few km (some on one point), each linked both ways to its nearest
    few, edges driven at speeds from walking to motorway, times rounded up to whole seconds
    (many ties)."""
    n = int(rng.integers(2, 60))
    xy = rng.uniform(0, rng.uniform(100, 5000), (n, 2))
    if n > 3:
        xy[1] = xy[0]  # two nodes on one point
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    k = min(n - 1, int(rng.integers(1, 5)))
    near = np.argsort(d, axis=1)[:, 1:k + 1]
    u = np.repeat(np.arange(n), k)
    v = near.reshape(-1)
    u, v = np.concatenate((u, v, np.arange(n - 1))), np.concatenate((v, u, np.arange(1, n)))
    metres = d[u, v]
    seconds = np.ceil(metres / rng.uniform(1, 35, u.size)) + 1.0
    return RoadNetwork.from_edges("random", xy, list(range(n)), u, v, seconds=seconds,
                                  metres=metres)


def column_problem(cost: np.ndarray, ids: np.ndarray) -> AllocationProblem:
    agents = AgentViews.of([AgentView(int(i), "car", 0, 1.0) for i in ids])
    tasks = (TaskView(7, "trip", 0, 0.0),)
    n = len(ids)
    return AllocationProblem.made(0.0, agents, tasks, np.array(cost, order="C"),
                                  np.ones((n, n), bool), np.random.default_rng(0), max_rounds=1,
                                  loss=0.0, latency=0.0, cell_size=1.0,
                                  agent_pos=np.zeros((n, 3)), task_pos=np.zeros((1, 3)))


@pytest.mark.parametrize("seed", range(300))
def test_top_speed_bounds_every_drive(seed):
    """No drive between two nodes is shorter than their straight line, less the slack, over
    the top speed; the top speed is no faster than the fastest edge's."""
    net = random_network(np.random.default_rng(seed))
    t = dijkstra(net.time)
    d = np.hypot(*(net.xy[:, None, :] - net.xy[None, :, :]).transpose(2, 0, 1))
    assert net.top_speed is not None
    assert (d / net.top_speed * (1 - nearest.SLACK) <= t).all()
    for speed, slack in net.speed_slacks:
        assert 0 < speed < net.top_speed and slack >= 0
        assert (nearest.seconds(d, ((speed, slack),)) <= t).all()
    speeds = ((net.top_speed, 0.0), *net.speed_slacks)
    assert (nearest.seconds(d, speeds) <= t).all()


@pytest.mark.parametrize("seed", range(400))
def test_cut_chooses_what_the_full_column_chooses(seed, monkeypatch):
    """Random networks and fleets (idle vehicles standing, some driving, some busy; several on
    one node), a request's deadline and a cost above the drive (a plan's service and trip),
    some vehicles ruled out (a battery, a shift): every allocator that declares it may be cut
    answers the vehicles the cut costed as it answers the whole column, the one-request path
    too; every vehicle the cut skipped costs more than the least cost (or is late), and none
    is costed twice."""
    rng = np.random.default_rng(seed)
    monkeypatch.setattr(nearest, "BATCH", int(rng.choice([1, 4, 16])))
    net = random_network(rng)
    n_fleet = int(rng.integers(1, 80))
    node = rng.integers(0, net.n, n_fleet)
    state = rng.choice([NOT_IDLE, MOVING, 0], n_fleet, p=[0.3, 0.1, 0.6])
    places = IdlePlaces(net.xy, n_fleet)
    for s in range(n_fleet):
        places.put(s, places.cell_of_node[node[s]] if state[s] == 0 else int(state[s]))
    task = int(rng.integers(0, net.n))
    to_task = dijkstra(net.time.T, indices=task)  # seconds from every node to the task
    drive = to_task[node] + np.where(state == MOVING, rng.uniform(0, 30, n_fleet), 0.0)
    extra = float(rng.choice([0.0, rng.uniform(0, 300)]))  # the added time's trip, or none
    late = math.inf if rng.random() < 0.3 else float(rng.uniform(0, 1.5 * drive.max() + 1))
    value = np.where(drive <= late, drive + extra, np.inf)
    value[rng.random(n_fleet) < 0.1] = np.inf  # ruled out by another limit
    idle = np.flatnonzero(state != NOT_IDLE)  # the decision's candidates, ascending
    costed: list[int] = []

    def cost(slots):
        assert (np.diff(slots) > 0).all()
        costed.extend(slots.tolist())
        return float(value[slots].min())

    best = math.inf
    moving = np.array(sorted(places.moving), np.int64)
    if moving.size:
        best = cost(moving)
    x, y = net.xy[task]
    speeds = ((net.top_speed, 0.0), *net.speed_slacks)

    def bound(slots):
        return nearest.seconds(np.hypot(*(net.xy[node[slots]] - (x, y)).T), speeds)

    best = nearest.visit(places.rings(x, y), bound, cost, speeds=speeds, best=best,
                         late=nearest.cap(late, 0.0))
    assert len(costed) == len(set(costed)) and set(costed) <= set(idle.tolist())
    skipped = np.setdiff1d(idle, costed)
    assert (value[skipped] > best).all() or not math.isfinite(best)
    assert best == (value[idle].min() if idle.size else math.inf)
    sub = np.array(sorted(costed), np.int64)
    for allocator in cut_allocators():
        whole = allocator.allocate(column_problem(value[idle, None], idle))
        if not math.isfinite(best):
            assert whole.pairs == (), allocator.name
            continue
        part = allocator.allocate(column_problem(value[sub, None], sub))
        assert part.pairs == whole.pairs, allocator.name
    if math.isfinite(best):
        problem = column_problem(value[sub, None], sub)
        d = pipeline.Decision(0.0, sub, problem.agents, [SimpleNamespace(id=7)],
                              problem.tasks, value[sub, None], None, {}, {}, problem.comm, 0.0,
                              lambda c: problem, n_idle=idle.size)
        got = one_request.decided(d)
        assert got.allocation.pairs == whole.pairs
        assert got.problem.n_agents == idle.size


@pytest.mark.parametrize("seed", range(50))
def test_rings_yield_every_vehicle_once_and_bound_the_rest(seed):
    """Ring by ring every standing idle vehicle comes once; each vehicle of a later ring is at
    least ``beyond`` away from the point."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 1000, (int(rng.integers(1, 200)), 2))
    n = int(rng.integers(1, 300))
    places = IdlePlaces(xy, n)
    at = rng.integers(0, len(xy), n)
    for s in range(n):
        places.put(s, places.cell_of_node[at[s]] if rng.random() < 0.7 else NOT_IDLE)
    for s in range(0, n, 3):  # some go busy again, some come back
        places.put(s, NOT_IDLE if rng.random() < 0.5 else places.cell_of_node[at[s]])
    want = sorted(s for s in range(n) if places.key[s] >= 0)
    assert sorted(places.standing()) == want
    x, y = rng.uniform(-200, 1200, 2)
    seen, beyond_before = [], 0.0
    for ring, beyond in places.rings(x, y):
        dist = np.hypot(*(xy[at[ring]] - (x, y)).T) if ring else np.zeros(0)
        assert (dist >= beyond_before - 1e-9).all()
        seen.extend(ring)
        beyond_before = beyond
    assert sorted(seen) == want


def run_tables(name: str, out: Path, full: bool, monkeypatch, allocator) -> tuple:
    """The tables of the first run of scenario ``name`` (its first 20 simulated minutes;
    ``allocator``: that one instead of the file's), with the cut or the whole column, and the
    vehicles whose costs were computed. Each cut decision checks the fleet's index against
    the fleet's arrays."""
    monkeypatch.setattr(nearest, "FULL", full)
    monkeypatch.setattr(nearest, "MIN_CANDIDATES", 0)
    costed = [0]
    real_search = nearest.search

    def checked(pipe, now):
        fleet = pipe.fleet
        standing = np.flatnonzero(fleet.idle_mask & ~fleet.driving)
        assert sorted(fleet.places.standing()) == standing.tolist()
        assert sorted(fleet.places.moving) == np.flatnonzero(
            fleet.idle_mask & fleet.driving).tolist()
        for s in standing.tolist():
            assert fleet.places.key[s] == fleet.places.cell_of_node[fleet.node[s]]
        return real_search(pipe, now)

    monkeypatch.setattr(nearest, "search", checked)
    real_call = pipeline.PlannerCosts.__call__

    def whole(self, agents, tasks):
        costed[0] += len(agents) * (len(tasks) == 1)
        return real_call(self, agents, tasks)

    monkeypatch.setattr(pipeline.PlannerCosts, "__call__", whole)
    scenario = load_scenario(ROOT / "scenarios" / name, ignore_limits=True,
                             overrides=[("duration", "1200.0", "test")])
    execute(scenario.runs(allocator=allocator)[:1], out)
    return read_run(out), costed[0]


@pytest.mark.parametrize("allocator", [None, "fcfs", "hungarian"])
@pytest.mark.parametrize("name", ROAD)
def test_same_results_as_the_whole_column(tmp_path, monkeypatch, name, allocator):
    """Every shipped road scenario (its own allocator, fcfs and hungarian; its first 20
    simulated minutes) gives the same tables with the cut as with the whole column."""
    whole, _ = run_tables(name, tmp_path / "whole", True, monkeypatch, allocator)
    cut, _ = run_tables(name, tmp_path / "cut", False, monkeypatch, allocator)
    assert_same_tables(whole, cut)


def test_the_cut_costs_fewer_vehicles(tmp_path, monkeypatch):
    """On an immediate fcfs run most of the idle vehicles are never costed."""
    _, n_whole = run_tables("manhattan.toml", tmp_path / "whole", True, monkeypatch, "fcfs")
    _, n_cut = run_tables("manhattan.toml", tmp_path / "cut", False, monkeypatch, "fcfs")
    assert 0 < n_cut < n_whole / 3
