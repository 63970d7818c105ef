"""Execution with reservations (the ``reservation`` planner): no two vehicles ever share a cell.

The checks read the recorded tables only, not the planner's or the kernel's bookkeeping: each
vehicle's occupancy is rebuilt from its start cell (``vehicles`` table) and its ``move`` events
(a step into a cell ends at the move's time and took step length / speed seconds, so it started
that much earlier; the vehicle stood in its cell until then) and checked against the time model
of :func:`dispatch.api.motion.occupancy`: a standing vehicle holds its cell, a stepping one the
step's from and to cells (and the corner cells of a diagonal). Across random crowded scenarios (a
10 x 10 x 3 world with one-cell passages, 6-12 vehicles, static and periodic tasks):

* no two vehicles hold one cell at overlapping times, and no two swap cells head-on;
* every task ends in exactly one terminal state; ``wait`` / ``replan`` events and the
  ``vehicles`` table's ``waits``, ``replans`` and ``wait_seconds`` agree; a vehicle only stands
  still on the way after a ``wait`` event;
* PyBullet agrees: sampled along runs, no vehicle body touches an obstacle or another vehicle.

The kernel's reservation table, the occupancy rule and the conflict rule (the lower task cost
keeps its path) are tested directly on hand-built worlds too.
"""

from __future__ import annotations

import math
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from dispatch.api.contracts import Allocator
from dispatch.api.motion import EPS, occupancy, overlaps, step_box, step_is_legal, step_length
from dispatch.plan.reservation_table import ReservationTable
from dispatch.run.runner import RunResult, make_recorder
from dispatch.run.sim import Simulation
from dispatch.scenario.load import load_scenario
from dispatch.space.physics import Physics
from dispatch.space.world import world_for
from tests.conftest import write_scenario
from tests.dispatch.test_determinism import bitwise
from tests.dispatch.test_invariants import TERMINAL_EVENT, run_scenario

ALLOCATORS = ("hungarian", "greedy", "random")
N_CROWDED = 200  # random crowded scenarios in the default run
TOL = 1e-7  # seconds: float noise allowed when comparing rebuilt times


# ----------------------------------------------------------------------------- scenarios


def crowded_scenario(directory: Path, seed: int, *, planner: str = "reservation") -> Path:
    """A random crowded scenario (deterministic in ``seed``): a 10 x 10 x 3 world whose boxes
    (2 or 3 m tall) stand one free cell apart, 6-12 vehicles, static or periodic tasks."""
    rng = np.random.default_rng([7, seed])
    agents = int(rng.integers(6, 13))
    fleet = {"agents": agents, "uav_fraction": float(rng.choice([0.0, 0.25, 0.5, 0.5, 1.0])),
             "uav_speed": 5.0, "ugv_speed": 3.0,
             "uav_max_start_altitude": float(rng.choice([0.0, 2.0]))}
    obstacles = {"count": int(rng.integers(4, 10)), "min_size": [1, 1, 2],
                 "max_size": [3, 3, 3]}
    tasks: dict = {"ground_fraction": float(rng.choice([0.6, 0.8, 1.0])),
                   "service_time": float(rng.choice([0.0, 0.0, 0.5]))}
    if rng.random() < 0.5:
        tasks.update(source="static", count=int(rng.integers(agents, 2 * agents + 1)))
    else:
        tasks.update(source="periodic", interval=float(rng.choice([0.2, 0.5, 1.0])),
                     count=int(rng.integers(10, 31)), max_active=agents)
        if rng.random() < 0.5:
            tasks["ttl"] = 20.0
    dispatch = {"allocator": str(rng.choice(ALLOCATORS)), "planner": planner,
                "batch_window": float(rng.choice([0.0, 0.0, 0.5]))}
    return write_scenario(directory, f"crowded_{seed}.toml", name=f"crowded_{seed}", seed=seed,
                          duration=float(rng.choice([40.0, 90.0])), world={"size": [10, 10, 3]},
                          obstacles=obstacles, fleet=fleet, tasks=tasks, dispatch=dispatch)


# ----------------------------------------------------------------------------- rebuilding


def rebuild(events: pd.DataFrame, vehicles: pd.DataFrame, grid, end: float):
    """Occupancy intervals ``(agent, cell, start, end)`` and steps ``(agent, a, b, dep, arr)``
    of every vehicle, from the events table alone (see the module docstring). Also checks that
    every position event is where the vehicle is and every step is legal and not early."""
    cells, steps = [], []
    ev = events[events.agent_id >= 0]
    by_agent = dict(iter(ev.groupby("agent_id", sort=False)))
    for v in vehicles.itertuples():
        here = grid.cell_of((v.x0, v.y0, v.z0))
        since = 0.0
        g = by_agent.get(v.agent_id)
        for e in (() if g is None else g.itertuples()):
            cell = grid.cell_of((e.x, e.y, e.z))
            if e.event in ("depart", "wait", "pickup", "idle"):
                assert cell == here, (v.agent_id, e)
            elif e.event == "move":
                assert step_is_legal(grid, here, cell, v.kind == "uav"), (v.agent_id, here, cell)
                dep = e.t - step_length(here, cell) * grid.cell / v.speed
                assert dep >= since - TOL, f"vehicle {v.agent_id} steps before it arrived: {e}"
                cells.append((v.agent_id, here, since, e.t))
                cells.extend((v.agent_id, c, dep, e.t) for c in step_box(here, cell)
                             if c != here and c != cell)
                steps.append((v.agent_id, here, cell, dep, e.t))
                here, since = cell, dep
        cells.append((v.agent_id, here, since, end))
    return cells, steps


def shared_cells(cells) -> list:
    """Pairs of intervals of different vehicles on one cell that overlap by more than TOL."""
    per_cell = defaultdict(list)
    for agent, cell, s, e in cells:
        per_cell[cell].append((s, e, agent))
    bad = []
    for cell, ivs in per_cell.items():
        ivs.sort()
        for i, (s1, e1, a1) in enumerate(ivs):
            for s2, e2, a2 in ivs[i + 1:]:
                if s2 >= e1 - TOL:
                    break
                if a1 != a2 and e2 > s1 + TOL:
                    bad.append((cell, (a1, s1, e1), (a2, s2, e2)))
    return bad


def head_on_swaps(steps) -> list:
    """Pairs of steps ``a -> b`` and ``b -> a`` of different vehicles at overlapping times."""
    by_edge = defaultdict(list)
    for agent, a, b, dep, arr in steps:
        by_edge[(a, b)].append((agent, dep, arr))
    bad = []
    for (a, b), mine in by_edge.items():
        for agent, dep, arr in mine:
            for other, dep2, arr2 in by_edge.get((b, a), ()):
                if other != agent and dep < arr2 - TOL and dep2 < arr - TOL:
                    bad.append(((agent, a, b, dep, arr), (other, dep2, arr2)))
    return bad


def check_waits(events: pd.DataFrame, vehicles: pd.DataFrame, grid, end: float) -> None:
    """``wait`` events, standing still on the way to a task, and the vehicles table agree.
    (An idle vehicle may move out of another's way: its moves have task id -1.)"""
    for v in vehicles.itertuples():
        e = events[events.agent_id == v.agent_id]
        here = grid.cell_of((v.x0, v.y0, v.z0))
        ready, waiting, total, task = 0.0, None, 0.0, -1
        for r in e.itertuples():
            if r.event == "depart":
                ready, task = r.t, r.task_id
            elif r.event == "wait":
                assert task >= 0 and r.task_id == task and waiting is None, (v.agent_id, r)
                waiting = r.t
            elif r.event == "move":
                assert r.task_id == task, (v.agent_id, r)
                nxt = grid.cell_of((r.x, r.y, r.z))
                dep = r.t - step_length(here, nxt) * grid.cell / v.speed
                if waiting is not None:
                    assert waiting <= dep + TOL
                    total += dep - waiting
                    waiting = None
                elif task >= 0:  # on the way it never stands still without a wait event
                    assert dep <= ready + TOL, (v.agent_id, r)
                here, ready = nxt, r.t
            elif r.event == "pickup":
                assert waiting is None and r.task_id == task, (v.agent_id, r)
            elif r.event == "idle":
                task = -1
            elif r.event == "breakdown":  # its wait (if any) ends; it has no task any more
                if waiting is not None:
                    total += r.t - waiting
                    waiting = None
                task = -1
        if waiting is not None:
            total += end - waiting
        assert v.waits == (e.event == "wait").sum()
        assert v.replans == (e.event == "replan").sum()
        assert v.wait_seconds == pytest.approx(total, abs=1e-6)


def check_run(r) -> dict:
    """Every check of the module docstring on one run; returns a few counts."""
    grid = r.grid
    end = float(r.summary["sim_time"])
    cells, steps = rebuild(r.events, r.vehicles, grid, end)
    assert shared_cells(cells) == []
    assert head_on_swaps(steps) == []
    check_waits(r.events, r.vehicles, grid, end)
    # every task ends in exactly one terminal state, with one terminal event
    term = r.events[r.events.event.isin(TERMINAL_EVENT.values())]
    assert term.task_id.is_unique and set(term.task_id) == set(r.tasks.task_id)
    assert set(r.tasks.state) <= set(TERMINAL_EVENT)
    ev = r.events.set_index("task_id")
    for t in r.tasks.itertuples():
        assert ev.loc[[t.task_id]].event.isin([TERMINAL_EVENT[t.state]]).sum() == 1
    return {"waits": int(r.vehicles.waits.sum()), "replans": int(r.vehicles.replans.sum()),
            "steps": len(steps), "states": r.tasks.state.value_counts().to_dict()}


# ----------------------------------------------------------------------------- crowded runs


@pytest.fixture(scope="module")
def crowded(tmp_path_factory):
    d = tmp_path_factory.mktemp("crowded")
    return {seed: run_scenario(crowded_scenario(d, seed)) for seed in range(N_CROWDED)}


def test_crowded_runs_never_share_a_cell(crowded):
    totals = defaultdict(int)
    states = defaultdict(int)
    for seed, r in crowded.items():
        try:
            counts = check_run(r)
        except AssertionError as e:
            raise AssertionError(f"crowded scenario seed {seed}: {e}") from e
        for k in ("waits", "replans", "steps"):
            totals[k] += counts[k]
        for s, n in counts["states"].items():
            states[s] += n
    # the scenarios are crowded enough to exercise the conflict rule
    assert totals["waits"] > 50 and totals["replans"] > 10, dict(totals)
    assert states["completed"] > 0.8 * sum(states.values()), dict(states)


def test_the_checks_are_not_vacuous(tmp_path):
    """The same crowded scenarios run without reservations (``astar``) do share cells."""
    found = 0
    for seed in range(10):
        r = run_scenario(crowded_scenario(tmp_path, seed, planner="astar"))
        cells, steps = rebuild(r.events, r.vehicles, r.grid, float(r.summary["sim_time"]))
        found += bool(shared_cells(cells)) + bool(head_on_swaps(steps))
    assert found > 3


@pytest.mark.slow
@pytest.mark.parametrize("block", range(5))
def test_more_crowded_runs_never_share_a_cell(tmp_path, block):
    for seed in range(N_CROWDED + 200 * block, N_CROWDED + 200 * (block + 1)):
        check_run(run_scenario(crowded_scenario(tmp_path, seed)))


# ----------------------------------------------------------------------------- PyBullet


def physics_samples(spec, dt: float):
    """Run ``spec`` in steps of ``dt`` simulated seconds, asking its PyBullet mirror for
    contacts after each; then replay the recorded events with every body moving in a straight
    line during its steps and ask again every ``dt / 2``. Returns (samples, contacts)."""
    with tempfile.TemporaryDirectory() as out:
        recorder = make_recorder(spec, Path(out))
        sim = Simulation(spec, recorder)
        env, horizon = sim.env, spec.scenario.duration
        samples, contacts = 0, []
        try:
            while not sim.finished.triggered and env.now < horizon:
                env.run(until=min(env.now + dt, horizon))
                samples += 1
                contacts += sim.physics.contacts()
        finally:
            sim.physics.close()
        files = recorder.finish()
        events = pq.read_table(files["events"]).to_pandas().drop(columns="run_id")
    grid = sim.world.grid
    vehicles = pd.DataFrame([{"agent_id": v.id, "kind": v.kind, "speed": v.speed,
                              **dict(zip(("x0", "y0", "z0"), grid.centre(v.start)))}
                             for v in sim.vehicles])
    _, steps = rebuild(events, vehicles, grid, env.now)
    track = defaultdict(list)  # agent -> [(dep, arr, from centre, to centre)]
    for agent, a, b, dep, arr in steps:
        track[agent].append((dep, arr, np.array(grid.centre(a)), np.array(grid.centre(b))))
    with Physics(sim.world) as ph:
        for v in sim.vehicles:
            ph.add_vehicle(v.id, v.flies, grid.centre(v.start))
        for t in np.arange(0.0, env.now, dt / 2):
            for agent, moves in track.items():
                done = [m for m in moves if m[0] <= t]
                if done:
                    dep, arr, a, b = done[-1]
                    f = min(1.0, (t - dep) / (arr - dep))
                    ph.move(agent, tuple(a + f * (b - a)))
            samples += 1
            contacts += ph.contacts()
    return samples, contacts


@pytest.mark.parametrize("seed", [10, 12, 15, 17, 18, 32, 36, 38, 43, 48])  # the busiest
def test_pybullet_finds_no_contacts(tmp_path, seed):
    spec = load_scenario(crowded_scenario(tmp_path, seed)).runs()[0]
    samples, contacts = physics_samples(spec, dt=0.05)
    assert samples > 150
    assert contacts == []


def test_pybullet_check_is_not_vacuous(tmp_path):
    """Without reservations the same sampling does find vehicle-vehicle contacts."""
    found = []
    for seed in range(8):
        spec = load_scenario(crowded_scenario(tmp_path, seed, planner="astar")).runs()[0]
        found += physics_samples(spec, dt=0.1)[1]
        if found:
            break
    assert found


# ----------------------------------------------------------------------------- the rules


def test_occupancy_holds_cells_steps_and_the_goal():
    route = [(0.0, (0, 0, 0)), (1.0, (1, 0, 0)), (3.0, (2, 1, 0))]
    occ = occupancy(route, speed=1.0, cell_m=1.0)
    d = math.sqrt(2)
    assert occ == [
        ((0, 0, 0), 0.0, 1.0),  # stands, then steps out: held until the step ends
        ((1, 0, 0), 0.0, 3.0),  # held from the start of the step into it
        ((1, 1, 0), 3.0 - d, 3.0),  # the diagonal's corners, during the step only
        ((2, 0, 0), 3.0 - d, 3.0),
        ((2, 1, 0), 3.0 - d, math.inf),  # the goal: held for good
    ]
    assert occupancy([(5.0, (1, 1, 1))], 3.0, 1.0) == [((1, 1, 1), 5.0, math.inf)]
    assert len(step_box((0, 0, 0), (1, 1, 1))) == 8
    assert overlaps(0, 1, 0.5, 2) and not overlaps(0, 1, 1, 2)
    assert not overlaps(0, 1, 1 - EPS / 2, 2)  # float noise is no conflict


def test_table_views_merge_and_filter():
    t = ReservationTable()
    t.add(1, [((0, 0, 0), 0.0, 1.0), ((0, 0, 0), 1.0, 2.0), ((1, 0, 0), 0.0, 5.0)])
    t.add(2, [((0, 0, 0), 3.0, math.inf)], committed=True)
    everyone = t.view(lambda e: True, 0.0)
    assert everyone.blocked((0, 0, 0)) == ((0.0, 2.0), (3.0, math.inf))
    assert t.view(lambda e: e.owner != 1, 0.0).blocked((0, 0, 0)) == ((3.0, math.inf),)
    assert t.view(lambda e: e.committed, 0.0).blocked((1, 0, 0)) == ()
    assert everyone.conflicts([((0, 0, 0), 2.0, 3.0)]) is False
    assert everyone.conflicts([((0, 0, 0), 2.0, 3.5)]) is True
    assert t.view(lambda e: True, 2.5).blocked((0, 0, 0)) == ((3.0, math.inf),)  # past dropped
    t.clear(1)
    assert t.at((1, 0, 0)) == [] and len(t.owned(2)) == 1


class Scripted(Allocator):
    """An allocator that gives each task to the vehicle named for it (``{task_id: agent_id}``),
    when that vehicle is idle."""

    name = "scripted"

    def __init__(self, plan: dict[int, int]) -> None:
        self.plan = plan

    def allocate(self, problem):
        from dispatch.api.problem import Allocation

        agents = {a.id: i for i, a in enumerate(problem.agents)}
        pairs = [(agents[self.plan[t.id]], j) for j, t in enumerate(problem.tasks)
                 if self.plan.get(t.id) in agents]
        return Allocation.centralized(problem, pairs)


def corridor_run(tmp_path, monkeypatch, vehicles, tasks, plan, *, service=0.0):
    """Run a hand-built world: a corridor one cell wide along x at y = 1 (8 cells, ground
    only), with one side pocket at (3, 2). ``vehicles``: (kind, start cell); ``tasks``:
    (release time, cell); ``plan``: which vehicle gets each task (by task id = index)."""
    from dispatch.api.voxels import Grid
    from dispatch.fleet.placement import PLACERS
    from dispatch.plan.vehicles import Vehicle
    from dispatch.run import sim as sim_mod
    from dispatch.space.world import World

    occ = np.ones((8, 4, 1), dtype=bool)
    occ[:, 1, 0] = False
    occ[3, 2, 0] = False
    world = World(size=(8.0, 4.0, 1.0), grid=Grid(occ, 1.0), boxes=())
    fleet = [Vehicle(i, kind, 5.0 if kind == "uav" else 3.0, cell)
             for i, (kind, cell) in enumerate(vehicles)]
    monkeypatch.setattr(sim_mod, "space_for", lambda cfg, seed, path=None: world)
    monkeypatch.setitem(PLACERS, "voxel", lambda w, spec, rng: fleet)
    trace = tmp_path / "trace.csv"
    trace.write_text("release_time,x,y,z\n" + "".join(
        f"{t},{c[0] + 0.5},{c[1] + 0.5},0.5\n" for t, c in tasks), encoding="utf-8")
    path = write_scenario(tmp_path, world={"size": [8, 4, 1]}, obstacles={"count": 0},
                          fleet={"agents": len(vehicles), "uav_fraction": 0.0},
                          tasks={"source": "trace", "trace": "trace.csv", "ground_fraction": None,
                                 "service_time": service},
                          dispatch={"allocator": "hungarian", "planner": "reservation"},
                          duration=60.0)
    spec = load_scenario(path).runs()[0]
    recorder = make_recorder(spec, tmp_path / "out")
    sim = Simulation(spec, recorder, allocator=Scripted(plan))
    summary = sim.run()
    result = RunResult(spec, summary, tmp_path / "out", recorder.finish())
    t = {name: table.to_pandas() for name, table in result.tables.items()}
    r = Recorded(sim.world.grid, t)
    check_run(r)
    return r


class Recorded:
    """A run's tables, as :func:`check_run` reads them."""

    def __init__(self, grid, tables: dict[str, pd.DataFrame]) -> None:
        self.grid = grid
        self.summary = tables["summary"].iloc[0].to_dict()
        self.events, self.vehicles, self.tasks = (tables["events"], tables["vehicles"],
                                                  tables["tasks"])


def test_head_on_in_a_corridor_the_cheaper_task_keeps_its_path(tmp_path, monkeypatch):
    """Vehicles 0 and 1 start at the two ends of the corridor and are sent past each other:
    vehicle 1's task is cheaper (5 cells against 6), so it drives straight to it; vehicle 0 is
    displaced (``replan``) and waits, then makes vehicle 1 (idle by then, on the way) park in
    the pocket, and goes on."""
    r = corridor_run(tmp_path, monkeypatch, [("ugv", (0, 1, 0)), ("ugv", (7, 1, 0))],
                     [(0.0, (6, 1, 0)), (0.0, (2, 1, 0))], {0: 0, 1: 1})
    tasks = r.tasks.set_index("task_id")
    assert list(tasks.state) == ["completed", "completed"]
    cheap, dear = tasks.loc[1], tasks.loc[0]
    assert (cheap.agent_id, dear.agent_id) == (1, 0) and cheap.cost < dear.cost
    # the cheaper task's vehicle travels as costed: no wait on the way
    assert cheap.picked_up_at - cheap.assigned_at == pytest.approx(cheap.cost)
    ev = r.events
    assert not ((ev.agent_id == 1) & (ev.event == "wait")).any()
    # the other one was displaced, waited, and arrived later than its cost
    v = r.vehicles.set_index("agent_id")
    assert v.loc[0, "replans"] >= 1 and v.loc[0, "waits"] >= 1 and v.loc[0, "wait_seconds"] > 0
    assert dear.picked_up_at - dear.assigned_at > dear.cost + 0.5
    # vehicle 1, idle on vehicle 0's way, moved into the pocket (a move without a task)
    park = ev[(ev.agent_id == 1) & (ev.event == "move") & (ev.task_id == -1)]
    assert (3.5, 2.5) in set(zip(park.x, park.y))


def test_a_vehicle_on_its_way_is_displaced_by_a_cheaper_one(tmp_path, monkeypatch):
    """Vehicle 0 is driving down the corridor when vehicle 1 (in the pocket) gets a cheaper
    task ahead of it: vehicle 1 keeps its path, vehicle 0 replans while moving and waits."""
    r = corridor_run(tmp_path, monkeypatch, [("ugv", (0, 1, 0)), ("ugv", (3, 2, 0))],
                     [(0.0, (7, 1, 0)), (0.5, (5, 1, 0))], {0: 0, 1: 1})
    tasks = r.tasks.set_index("task_id")
    assert set(tasks.state) == {"completed"}
    late = tasks.loc[1]
    assert late.picked_up_at - late.assigned_at == pytest.approx(late.cost)
    ev = r.events
    replan = ev[(ev.event == "replan") & (ev.agent_id == 0)]
    assert len(replan) >= 1 and (replan.task_id == 0).all()
    assert replan.t.iloc[0] == pytest.approx(0.5)  # when vehicle 1 got its task
    v = r.vehicles.set_index("agent_id")
    assert v.loc[0, "waits"] >= 1


def test_two_tasks_on_one_cell(tmp_path, monkeypatch):
    """The second vehicle cannot park on a cell the first is serving; it waits (no route) and
    gets there once the first, idle again, has made way."""
    r = corridor_run(tmp_path, monkeypatch, [("ugv", (0, 1, 0)), ("ugv", (7, 1, 0))],
                     [(0.0, (4, 1, 0)), (0.0, (4, 1, 0))], {0: 1, 1: 0}, service=1.0)
    assert set(r.tasks.state) == {"completed"}
    assert r.vehicles.waits.sum() >= 1


def test_astar_runs_record_no_waits(tmp_path):
    r = run_scenario(crowded_scenario(tmp_path, 0, planner="astar"))
    assert (r.vehicles[["waits", "replans", "wait_seconds"]] == 0).all().all()
    assert not r.events.event.isin(["wait", "replan"]).any()


def test_crowded_scenario_file_runs():
    from dispatch.run.runner import run_one

    root = Path(__file__).resolve().parents[2]
    spec = load_scenario(root / "scenarios" / "crowded.toml").runs()[0]
    assert spec.planner == "reservation"
    result = run_one(spec)
    r = Recorded(world_for(spec.scenario.world, spec.seed).grid,
                 {n: tb.to_pandas() for n, tb in result.tables.items()})
    check_run(r)
    assert set(r.tasks.state) == {"completed"}


def test_same_seed_same_run(tmp_path):
    from dispatch.output.parquet import TIMING_COLUMNS

    path = crowded_scenario(tmp_path, 48)
    a, b = (run_scenario(path).result.tables for _ in range(2))
    for name in ("events", "vehicles", "tasks"):
        ta, tb = a[name], b[name]
        keep = [c for c in ta.column_names if c not in TIMING_COLUMNS]
        # bit for bit: Table.equals never finds NaN equal to NaN (tasks.dropoff_* are NaN)
        assert bitwise(ta.select(keep)).equals(bitwise(tb.select(keep))), name
    assert a["vehicles"].column("replans").to_pylist() != [0] * a["vehicles"].num_rows
