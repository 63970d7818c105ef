"""Invariants of every run, on random small scenarios of every task-source kind.

For each (source, allocator, seed) a random tiny scenario is drawn (fleet mix, task mix, ttl,
service time, batching window, horizon), run with :func:`dispatch.run.runner.run_one`, and its
tables are checked:

* every released task ends in exactly one terminal state, with exactly one terminal event;
* no task is held by two vehicles, and ``tasks.agent_id`` agrees with the winning request;
* a vehicle serves one task at a time (depart ... idle intervals never overlap);
* the summary's counts and total cost add up from the tasks table;
* vehicles move by legal steps only, one step taking step length / speed seconds;
* UGVs stay on the ground layer and are never given air tasks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dispatch.api.motion import step_is_legal, step_length
from dispatch.config.scenario import RunSpec
from dispatch.run.runner import RunResult, run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.world import world_for
from tests.conftest import write_scenario

SOURCES = ("static", "periodic", "poisson", "trace_csv", "trace_parquet")
ALLOCATORS = ("hungarian", "greedy", "random")
SEEDS = range(8)
TERMINAL_EVENT = {"completed": "complete", "expired": "expire", "unreachable": "unreachable",
                  "cut_off": "cut_off", "rejected": "reject", "failed": "failed"}
WORLD = (12.0, 12.0, 6.0)


# ----------------------------------------------------------------------------- scenarios


def random_trace(rng: np.random.Generator, n: int) -> dict[str, list[float]]:
    """``n`` rows anywhere in the world (some land in obstacles: those become unreachable),
    about half on the ground layer, some sharing a release time."""
    t = np.sort(np.round(rng.uniform(0.0, 20.0, n), 1))
    t[: n // 4] = 0.0  # a burst at t = 0
    x = rng.uniform(0.0, WORLD[0] - 1e-6, n)
    y = rng.uniform(0.0, WORLD[1] - 1e-6, n)
    z = np.where(rng.random(n) < 0.5, rng.uniform(0.0, 1.0, n), rng.uniform(0.0, WORLD[2], n))
    rng.shuffle(t)  # the reader sorts by time
    return {"release_time": t.tolist(), "x": x.tolist(), "y": y.tolist(), "z": z.tolist()}


def random_scenario(directory: Path, source: str, allocator: str, seed: int) -> Path:
    """A random tiny scenario of the given source kind (deterministic in its arguments)."""
    rng = np.random.default_rng([SOURCES.index(source), ALLOCATORS.index(allocator), seed])
    agents = int(rng.integers(2, 6))
    fleet = {"agents": agents, "uav_fraction": float(rng.choice([0.0, 0.5, 1.0, 0.34])),
             "uav_speed": float(rng.choice([2.0, 5.0])), "ugv_speed": float(rng.choice([1.0, 3.0])),
             "uav_max_start_altitude": float(rng.choice([0.0, 3.0, 10.0]))}
    tasks: dict = {"ground_fraction": float(rng.choice([0.0, 0.5, 1.0])),
                   "service_time": float(rng.choice([0.0, 0.0, 1.5]))}
    if rng.random() < 0.5:  # with and without ttl
        tasks["ttl"] = float(rng.choice([2.0, 8.0]))
    duration = float(rng.choice([6.0, 40.0, 300.0]))  # a short horizon leaves tasks cut off
    if source == "static":
        tasks.update(source="static", count=int(rng.integers(1, 3 * agents + 1)))
        if rng.random() < 0.5:
            tasks.pop("ttl", None)
    elif source == "periodic":
        tasks.update(source="periodic", interval=float(rng.choice([0.5, 1.0, 2.0])),
                     max_active=int(rng.integers(1, 4)), count=int(rng.integers(3, 15)))
    elif source == "poisson":
        tasks.update(source="poisson", rate=float(rng.choice([0.5, 2.0])),
                     count=int(rng.integers(3, 15)))
        if rng.random() < 0.7:
            tasks["max_active"] = int(rng.integers(1, 5))
    else:
        data = random_trace(rng, int(rng.integers(3, 15)))
        if source == "trace_csv":
            name = "trace.csv"
            lines = ["release_time,x,y,z"] + [
                ",".join(repr(float(c[i])) for c in data.values())
                for i in range(len(data["x"]))
            ]
            (directory / name).write_text("\n".join(lines) + "\n", encoding="utf-8")
        else:
            name = "trace.parquet"
            pq.write_table(pa.table(data), directory / name)
        del tasks["ground_fraction"]
        tasks.update(source="trace", trace=name)
    dispatch = {"allocator": allocator, "planner": "astar",
                "batch_window": float(rng.choice([0.0, 0.0, 0.5]))}
    return write_scenario(directory, f"{source}.toml", name=f"inv_{source}", seed=seed,
                          duration=duration, fleet=fleet, tasks=tasks, dispatch=dispatch)


@dataclass
class Run:
    spec: RunSpec
    result: RunResult
    summary: dict
    tasks: pd.DataFrame
    events: pd.DataFrame
    assignments: pd.DataFrame
    vehicles: pd.DataFrame

    @property
    def grid(self):
        return world_for(self.spec.scenario.world, self.spec.seed).grid


def run_scenario(path: Path) -> Run:
    specs = load_scenario(path).runs()
    assert len(specs) == 1
    result = run_one(specs[0])
    t = {name: table.to_pandas() for name, table in result.tables.items()}
    assert len(t["summary"]) == 1
    return Run(specs[0], result, t["summary"].iloc[0].to_dict(), t["tasks"], t["events"],
               t["assignments"], t["vehicles"])


CASES = [(s, a, seed) for s in SOURCES for a in ALLOCATORS for seed in SEEDS]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[tuple[str, str, int], Run]:
    """Every case run once per module, shared by the checks below."""
    out = {}
    for source, allocator, seed in CASES:
        d = tmp_path_factory.mktemp(f"{source}_{allocator}_{seed}")
        out[(source, allocator, seed)] = run_scenario(random_scenario(d, source, allocator, seed))
    return out


def case_ids(cases):
    return [f"{s}-{a}-s{seed}" for s, a, seed in cases]


parametrize_cases = pytest.mark.parametrize("case", CASES, ids=case_ids(CASES))


# ----------------------------------------------------------------------------- the checks


def cell_of(grid, row) -> tuple[int, int, int]:
    return grid.cell_of((row.x, row.y, row.z))


@parametrize_cases
def test_every_task_ends_in_exactly_one_terminal_state(runs, case):
    r = runs[case]
    tasks, ev = r.tasks, r.events
    released = ev[ev.event == "release"]
    # each task id appears once in the tasks table, and every released task is in it
    assert tasks.task_id.is_unique
    assert sorted(tasks.task_id) == sorted(released.task_id)
    assert released.task_id.is_unique
    assert set(tasks.state) <= set(TERMINAL_EVENT)
    # exactly one terminal event per task, and it matches the task's state
    term = ev[ev.event.isin(TERMINAL_EVENT.values())]
    assert term.task_id.is_unique
    assert set(term.task_id) == set(tasks.task_id)
    by_task = term.set_index("task_id").event
    for row in tasks.itertuples():
        assert by_task[row.task_id] == TERMINAL_EVENT[row.state], row
        # the terminal event comes at the task's closing time, after its release
        assert term[term.task_id == row.task_id].t.iloc[0] == pytest.approx(row.closed_at)
        assert row.closed_at >= row.released_at
    # the life cycle's timestamps are consistent with the state
    done = tasks[tasks.state == "completed"]
    assert (done.agent_id >= 0).all()
    assert (done.released_at <= done.assigned_at).all()
    assert (done.assigned_at <= done.picked_up_at).all()
    service = r.spec.scenario.tasks.service_time
    assert np.allclose(done.completed_at - done.picked_up_at, service)
    assert np.allclose(done.completed_at, done.closed_at)
    never = tasks[tasks.state.isin(["expired", "unreachable"])]
    assert (never.agent_id == -1).all() and never.assigned_at.isna().all()
    ttl = r.spec.scenario.tasks.ttl
    expired = tasks[tasks.state == "expired"]
    if ttl is None:
        assert expired.empty
    else:
        assert np.allclose(expired.closed_at - expired.released_at, ttl)
    not_done = tasks[tasks.state != "completed"]
    assert not_done.completed_at.isna().all()


@parametrize_cases
def test_no_task_is_held_by_two_vehicles(runs, case):
    r = runs[case]
    tasks, asg, ev = r.tasks, r.assignments, r.events
    won = asg[asg.won]
    assert won.task_id.is_unique, "a task won twice"
    # an agent wins at most one task per decision
    assert not won.duplicated(["decision", "agent_id"]).any()
    # winning requests and the tasks table agree
    winner = won.set_index("task_id").agent_id
    assigned = tasks[tasks.agent_id >= 0]
    assert set(assigned.task_id) == set(winner.index)
    for row in assigned.itertuples():
        assert winner[row.task_id] == row.agent_id
    # one assign event per assigned task, naming the same vehicle
    assign = ev[ev.event == "assign"]
    assert assign.task_id.is_unique
    assert dict(zip(assign.task_id, assign.agent_id)) == dict(
        zip(assigned.task_id, assigned.agent_id))
    # every request names a task of this run and has a finite cost
    assert set(asg.task_id) <= set(tasks.task_id)
    assert np.isfinite(asg.cost).all()
    # the recorded cost of a task is the cost of its winning request
    cost = won.set_index("task_id").cost
    for row in assigned.itertuples():
        assert row.cost == pytest.approx(cost[row.task_id])


@parametrize_cases
def test_a_vehicle_serves_one_task_at_a_time(runs, case):
    r = runs[case]
    ev = r.events
    for vid in r.vehicles.agent_id:
        current = None
        intervals = []
        for e in ev[ev.agent_id == vid].itertuples():
            if e.event == "assign":
                assert current is None, f"vehicle {vid} assigned task {e.task_id} while busy"
            elif e.event == "depart":
                assert current is None, f"vehicle {vid} departs for {e.task_id} while busy"
                current, start = e.task_id, e.t
            elif e.event in ("move", "pickup"):
                assert current == e.task_id, (vid, e)
            elif e.event == "idle":
                assert current is not None, (vid, e)
                intervals.append((start, e.t, current))
                current = None
            elif e.event == "complete":
                assert current == e.task_id, (vid, e)
            elif e.event == "cut_off":
                # only the task it is serving when the horizon comes
                assert current == e.task_id, (vid, e)
        if current is not None:  # still serving at the horizon
            assert r.tasks.set_index("task_id").state[current] == "cut_off"
        for (s0, e0, _), (s1, _, _) in zip(intervals, intervals[1:]):
            assert e0 <= s1
    # and per task: the service intervals of one vehicle never overlap
    tasks = r.tasks[r.tasks.agent_id >= 0].sort_values(["agent_id", "assigned_at"])
    for _, group in tasks.groupby("agent_id"):
        ends = group.closed_at.to_numpy()
        starts = group.assigned_at.to_numpy()
        assert (ends[:-1] <= starts[1:]).all()


@parametrize_cases
def test_summary_counts_add_up(runs, case):
    r = runs[case]
    s, tasks = r.summary, r.tasks
    states = tasks.state.value_counts().to_dict()
    assert s["n_tasks"] == len(tasks)
    assert s["n_agents"] == len(r.vehicles) == r.spec.agents
    assert s["tasks_completed"] == states.get("completed", 0)
    assert s["tasks_unfinished"] == len(tasks) - states.get("completed", 0)
    assert s["tasks_expired"] == states.get("expired", 0)
    assert s["tasks_unreachable"] == states.get("unreachable", 0)
    assert s["tasks_cut_off"] == states.get("cut_off", 0)
    assert (s["tasks_completed"] + s["tasks_expired"] + s["tasks_unreachable"]
            + s["tasks_cut_off"]) == s["n_tasks"]
    assigned = tasks[tasks.agent_id >= 0]
    assert s["total_cost"] == pytest.approx(assigned.cost.sum())
    assert s["n_uav"] + s["n_ugv"] == s["n_agents"]
    assert s["n_uav"] == (r.vehicles.kind == "uav").sum() == r.spec.fleet.n_uav
    assert s["conflicts"] == tasks.conflicted.sum()
    decisions = r.result.tables["decisions"].to_pandas()
    assert s["decisions"] == len(decisions)
    assert list(decisions.decision) == list(range(len(decisions)))
    assert set(r.assignments.decision) <= set(decisions.decision)
    assert decisions.n_assigned.sum() == len(assigned)
    assert s["rounds"] == decisions.rounds.sum()
    arrived = tasks[tasks.picked_up_at.notna()]
    assert s["realized_travel"] == pytest.approx(
        (arrived.picked_up_at - arrived.assigned_at).sum())
    assert r.vehicles.tasks_completed.sum() == s["tasks_completed"]
    done = tasks[tasks.state == "completed"]
    assert s["makespan"] == pytest.approx(done.completed_at.max() if len(done) else 0.0)
    assert s["sim_time"] <= r.spec.scenario.duration + 1e-9
    # runs end when the work is done, or at the horizon with cut-off tasks
    if s["tasks_cut_off"]:
        assert s["sim_time"] == pytest.approx(r.spec.scenario.duration)
    if r.spec.scenario.tasks.source == "static":
        assert s["n_tasks"] == r.spec.n_static_tasks
    if r.spec.scenario.tasks.source == "trace":
        assert s["n_tasks"] <= len(r.spec.scenario.tasks.trips)
    if r.spec.scenario.tasks.count is not None:
        assert s["n_tasks"] <= r.spec.scenario.tasks.count


def test_released_tasks_respect_max_active(runs):
    capped = [r for r in runs.values() if r.spec.scenario.tasks.max_active is not None]
    assert capped
    for r in capped:
        cap = r.spec.scenario.tasks.max_active
        open_now = 0
        for e in r.events.itertuples():
            if e.event == "release":
                open_now += 1
                assert open_now <= cap, r.spec.run_id
            elif e.event in TERMINAL_EVENT.values():
                open_now -= 1
        assert open_now == 0


@parametrize_cases
def test_vehicles_move_by_legal_timed_steps(runs, case):
    r = runs[case]
    grid, cell_m = r.grid, r.grid.cell
    ev, tasks = r.events, r.tasks.set_index("task_id")
    for v in r.vehicles.itertuples():
        flies = v.kind == "uav"
        here = grid.cell_of((v.x0, v.y0, v.z0))
        assert grid.is_free(here)
        t_prev = None
        metres = 0.0
        for e in ev[ev.agent_id == v.agent_id].itertuples():
            if e.event == "depart":
                assert cell_of(grid, e) == here, "a vehicle departs from where it is"
                t_prev = e.t
            elif e.event == "move":
                nxt = cell_of(grid, e)
                assert step_is_legal(grid, here, nxt, flies), (v.agent_id, here, nxt)
                length = step_length(here, nxt) * cell_m
                assert e.t - t_prev == pytest.approx(length / v.speed, rel=1e-9, abs=1e-9)
                metres += length
                here, t_prev = nxt, e.t
            elif e.event == "pickup":
                assert cell_of(grid, e) == here
                assert here == grid.cell_of(tuple(tasks.loc[e.task_id, ["x", "y", "z"]]))
                assert e.t == pytest.approx(t_prev)
                # the travel time is the planner's cost: the path followed is the costed one
                task = tasks.loc[e.task_id]
                assert task.picked_up_at - task.assigned_at == pytest.approx(task.cost, abs=1e-6)
            elif e.event == "idle":
                assert cell_of(grid, e) == here
        assert v.distance == pytest.approx(metres, abs=1e-9)


@parametrize_cases
def test_ugvs_stay_on_the_ground_and_serve_ground_tasks(runs, case):
    r = runs[case]
    ground_z = r.grid.centre((0, 0, 0))[2]
    assert ground_z == 0.5  # 1 m cells: the ground layer's centres are at z = 0.5 m
    ugvs = set(r.vehicles[r.vehicles.kind == "ugv"].agent_id)
    vehicles = r.vehicles.set_index("agent_id")
    for vid in ugvs:
        assert vehicles.z0[vid] == ground_z
    ev = r.events
    positions = ev[ev.agent_id.isin(ugvs) & ev.event.isin(["depart", "move", "pickup", "idle"])]
    assert (positions.z == ground_z).all()
    ugv_tasks = r.tasks[r.tasks.agent_id.isin(ugvs)]
    assert (ugv_tasks.kind == "ground").all()
    assert (ugv_tasks.z == ground_z).all()
    # no request of a UGV names an air task
    air = set(r.tasks[r.tasks.kind == "air"].task_id)
    asg = r.assignments
    assert asg[asg.agent_id.isin(ugvs) & asg.task_id.isin(air)].empty
    # task kinds follow their layer
    assert ((r.tasks.kind == "ground") == (r.tasks.z == ground_z)).all()


def test_cases_cover_every_outcome(runs):
    """The random scenarios exercise every terminal state and both task kinds."""
    states = pd.concat([r.tasks.state for r in runs.values()]).value_counts()
    assert {"completed", "expired", "unreachable", "cut_off"} <= set(states.index), states
    kinds = set(pd.concat([r.tasks.kind for r in runs.values()]))
    assert kinds == {"ground", "air"}
    skipped = sum((r.events.event == "skipped").sum() for r in runs.values())
    assert skipped > 0, "max_active never held a release back"
    assert any(r.summary["conflicts"] > 0 for r in runs.values())
    assert math.isfinite(sum(r.summary["total_cost"] for r in runs.values()))
