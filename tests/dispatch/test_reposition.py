"""Repositioning in runs: ``stay`` changes nothing, ``demand`` moves an idle vehicle toward the
demand (times and metres computed by hand on a 6 x 2 grid), a repositioning vehicle can be
dispatched or break down part-way, the life-cycle invariants hold on random scenarios, same
seed same output, sweeps over repositioners, and clear one-line errors for bad configuration."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dispatch.errors import PluginError, ScenarioError
from dispatch.output.parquet import TIMING_COLUMNS
from dispatch.run.runner import execute, run_one
from dispatch.scenario.load import load_scenario

TERMINAL = {"completed": "complete", "expired": "expire", "rejected": "reject",
            "unreachable": "unreachable", "cut_off": "cut_off", "failed": "failed"}
#: 6 x 2 intersections, 200 m blocks at 10 m/s: an edge is 20 s. Node row * 6 + column at
#: (200 column, 200 row). 600 m zones: columns 0-2 zone 0 (centre node 1), 3-5 zone 1 (node 4).
GRID = 'network = "manhattan"\nblocks = [6, 2]\nblock = 200.0\nspeed = 10.0'
DEMAND = ('[reposition]\npolicy = "demand"\ninterval = 100.0\nhorizon = 1000.0\n'
          '[reposition.demand]\nzone = 600.0\n')
#: three requests in zone 1 nobody can reach within 1 s (rejected at once, but demand)
HOTSPOT = [(10.0, 10, 11, 1.0), (20.0, 10, 11, 1.0), (30.0, 3, 9, 1.0)]


def scenario(d: Path, *, trips, starts=(0,), extra: str = DEMAND, faults=None,
             name: str = "grid", duration: float = 1e5) -> Path:
    (d / "fleet.csv").write_text("vehicle_id,node\n" + "".join(f"{i},{n}\n"
                                                                for i, n in enumerate(starts)))
    (d / "trips.csv").write_text("t,origin_node,dest_node,max_wait\n" + "".join(
        f"{t},{o},{e},{'' if w is None else w}\n" for t, o, e, w in trips))
    fault = ""
    if faults:
        (d / "faults.csv").write_text("t,vehicle_id,duration\n" + "".join(
            f"{t},{v},{u}\n" for t, v, u in faults))
        fault = '[faults]\nfile = "faults.csv"\n'
    path = d / f"{name}.toml"
    path.write_text(f'name = "{name}"\nseed = 1\nduration = {duration!r}\n[world]\n{GRID}\n'
                    f'[fleet]\nstart = "fleet.csv"\n[tasks]\nsource = "trace"\n'
                    f'trace = "trips.csv"\nmax_wait = 600.0\n[dispatch]\nallocator = "fcfs"\n'
                    f'{fault}{extra}', encoding="utf-8")
    return path


def run(path: Path):
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def vehicle_events(t, agent=0):
    ev = t["events"]
    return ev[ev.agent_id == agent][["t", "event", "task_id", "x", "y"]].values.tolist()


# ----------------------------------------------------------------------------- by hand


def test_an_idle_vehicle_goes_where_the_demand_is(tmp_path):
    s, t = run(scenario(tmp_path, trips=[*HOTSPOT, (500.0, 5, 11, None)]))
    # t = 100: sent to zone 1's centre (node 4, x = 800), departs from node 0, 4 edges: 180 s
    # later calls: zone 1 holds the only vehicle and all the demand; nothing moves.
    # t = 500: the trip at node 5 is one edge away: pickup at 520, drop-off (node 11) at 540
    assert vehicle_events(t) == [
        [100.0, "reposition", -1, 800.0, 0.0], [100.0, "depart", -1, 0.0, 0.0],
        [180.0, "idle", -1, 800.0, 0.0],
        [500.0, "assign", 3, 1000.0, 0.0], [500.0, "depart", 3, 800.0, 0.0],
        [520.0, "pickup", 3, 1000.0, 0.0], [520.0, "depart", 3, 1000.0, 0.0],
        [540.0, "dropoff", 3, 1000.0, 200.0], [540.0, "complete", 3, 1000.0, 200.0],
        [540.0, "idle", -1, 1000.0, 200.0]]
    assert s["reposition"] == "demand" and s["repositions"] == 1
    assert s["reposition_distance"] == pytest.approx(800.0)
    assert s["wait_time_mean"] == pytest.approx(20.0)
    v = t["vehicles"].iloc[0]
    assert (v.distance, v.empty_distance, v.occupied_distance) == pytest.approx((1200, 1000, 200))
    assert s["tasks_rejected"] == 3 and s["tasks_completed"] == 1
    # with stay it waits at node 0: five edges to the pickup
    s0, t0 = run(scenario(tmp_path, trips=[*HOTSPOT, (500.0, 5, 11, None)],
                          extra='[reposition]\npolicy = "stay"\n', name="stay"))
    assert s0["wait_time_mean"] == pytest.approx(100.0)
    assert s0["repositions"] == 0 and s0["reposition_distance"] == 0.0
    assert "reposition" not in set(t0["events"].event)


def test_a_repositioning_vehicle_is_dispatched_mid_edge_and_serves_the_trip(tmp_path):
    # t = 100 it leaves node 0 for node 4; at t = 130 it is half-way along 1 -> 2 (x = 300,
    # 10 s before node 2) when a trip at node 0 is released: it finishes the edge and drives
    # back, 10 + 40 = 50 s; the trip (node 0 -> node 6) ends at 200
    s, t = run(scenario(tmp_path, trips=[*HOTSPOT, (130.0, 0, 6, None)]))
    assert vehicle_events(t) == [
        [100.0, "reposition", -1, 800.0, 0.0], [100.0, "depart", -1, 0.0, 0.0],
        [130.0, "assign", 3, 0.0, 0.0], [130.0, "depart", 3, 300.0, 0.0],
        [180.0, "pickup", 3, 0.0, 0.0], [180.0, "depart", 3, 0.0, 0.0],
        [200.0, "dropoff", 3, 0.0, 200.0], [200.0, "complete", 3, 0.0, 200.0],
        [200.0, "idle", -1, 0.0, 200.0]]
    task = t["tasks"].set_index("task_id").loc[3]
    assert task.state == "completed" and task.cost == pytest.approx(50.0)
    assert task.picked_up_at - task.released_at == pytest.approx(50.0)
    assert s["repositions"] == 1 and s["reposition_distance"] == pytest.approx(300.0)
    v = t["vehicles"].iloc[0]
    # 300 m repositioning + 100 m to finish the edge + 400 m back, then 200 m with the rider
    assert (v.distance, v.empty_distance, v.occupied_distance) == pytest.approx((1000, 800, 200))


def test_a_breakdown_stops_a_repositioning_drive_and_a_later_call_resumes_it(tmp_path):
    # down at t = 130 half-way along 1 -> 2 (300 m driven), repaired at 180; the call at 200
    # sends it on from there: 10 s to node 2, 40 s to node 4 (500 m), arriving at 250
    s, t = run(scenario(tmp_path, trips=[*HOTSPOT, (500.0, 5, 11, None)],
                        faults=[(130.0, 0, 50.0)]))
    ev = vehicle_events(t)
    assert ev[:7] == [
        [100.0, "reposition", -1, 800.0, 0.0], [100.0, "depart", -1, 0.0, 0.0],
        [130.0, "breakdown", -1, 300.0, 0.0], [180.0, "repair", -1, 300.0, 0.0],
        [180.0, "idle", -1, 300.0, 0.0],
        [200.0, "reposition", -1, 800.0, 0.0], [200.0, "depart", -1, 300.0, 0.0]]
    assert ev[7] == [250.0, "idle", -1, 800.0, 0.0]
    assert s["repositions"] == 2 and s["reposition_distance"] == pytest.approx(800.0)
    assert s["wait_time_mean"] == pytest.approx(20.0) and s["tasks_completed"] == 1
    v = t["vehicles"].iloc[0]
    assert (v.distance, v.empty_distance) == pytest.approx((1200, 1000))


def test_a_drive_cut_by_the_end_of_the_run_counts_what_was_driven(tmp_path):
    # the run ends at 150 (duration), 50 s after the vehicle left: 500 m driven
    s, t = run(scenario(tmp_path, trips=[*HOTSPOT, (900.0, 5, 11, None)], duration=150.0))
    assert s["repositions"] == 1 and s["reposition_distance"] == pytest.approx(500.0)
    assert t["vehicles"].iloc[0].empty_distance == pytest.approx(500.0)


# ----------------------------------------------------------------------------- stay


def test_stay_is_todays_run_and_layout(tmp_path):
    trips = [(float(10 * i), int(o), int(d), None) for i, (o, d) in
             enumerate(np.random.default_rng(2).integers(0, 12, (30, 2))) if o != d]
    plain = scenario(tmp_path, trips=trips, starts=(0, 5, 11), extra="", name="plain")
    [spec] = load_scenario(plain).runs()
    assert spec.run_id == "plain__fcfs__dijkstra__n3__s1"
    assert "reposition" not in spec.partition
    s, t = run(plain)
    assert s["reposition"] == "stay" and s["repositions"] == 0
    staying = scenario(tmp_path, trips=trips, starts=(0, 5, 11),
                       extra='[reposition]\npolicy = "stay"\n', name="plain")
    [spec2] = load_scenario(staying).runs()
    assert spec2.run_id == "plain__fcfs__dijkstra__stay__n3__s1"
    assert spec2.partition["reposition"] == "stay"
    s2, t2 = run(staying)
    drop = [*TIMING_COLUMNS, "run_id"]
    for name in ("tasks", "events", "vehicles", "assignments"):
        cols = [c for c in t[name].columns if c not in drop]
        pd.testing.assert_frame_equal(t[name][cols], t2[name][cols])
    assert {k: v for k, v in s.items() if k not in drop} == \
        {k: v for k, v in s2.items() if k not in drop}


# ----------------------------------------------------------------------------- invariants


def random_scenario(d: Path, seed: int, *, allocator: str, faults: bool) -> Path:
    g = np.random.default_rng(seed)
    # a hotspot: most pickups in the two right-hand columns, drop-offs anywhere
    trips, t = [], 0.0
    for _ in range(60):
        t += float(g.exponential(25.0))
        o = int(g.choice([4, 5, 10, 11])) if g.random() < 0.7 else int(g.integers(0, 12))
        e = int(g.integers(0, 12))
        trips.append((round(t, 3), o, e if e != o else (o + 1) % 12,
                      None if g.random() < 0.7 else 45.0))
    starts = tuple(int(x) for x in g.integers(0, 12, 4))
    extra = ('[reposition]\npolicy = "demand"\ninterval = 30.0\nhorizon = 300.0\n'
             '[reposition.demand]\nzone = 400.0\nmax_moves = 2\n')
    fl = [(float(g.uniform(0, 500)), int(g.integers(0, 4)), float(g.uniform(5, 80)))
          for _ in range(3)] if faults else None
    path = scenario(d, trips=trips, starts=starts, extra=extra, faults=fl, name=f"r{seed}")
    text = path.read_text().replace('allocator = "fcfs"', f'allocator = "{allocator}"')
    path.write_text(text)
    return path


CASES = [(seed, alloc, faults) for seed, alloc, faults in
         [(0, "fcfs", False), (1, "hungarian", False), (2, "greedy", True), (3, "fcfs", True),
          (4, "hungarian", True)]]


@pytest.mark.parametrize("seed, allocator, faults", CASES)
def test_invariants_with_repositioning(tmp_path, seed, allocator, faults):
    s, t = run(random_scenario(tmp_path, seed, allocator=allocator, faults=faults))
    tasks, ev, veh = t["tasks"], t["events"], t["vehicles"]
    # every task ends in exactly one terminal state, and the summary counts agree
    term = ev[ev.event.isin(TERMINAL.values())]
    assert term.task_id.is_unique and set(term.task_id) == set(tasks.task_id)
    assert (term.set_index("task_id").event.loc[tasks.task_id].values
            == tasks.state.map(TERMINAL).values).all()
    assert s["n_tasks"] == len(tasks) == (ev.event == "release").sum()
    for state in TERMINAL:
        assert s[f"tasks_{state}"] == (tasks.state == state).sum()
    done = tasks[tasks.state == "completed"]
    assert len(done) > 0
    assert ((done.picked_up_at - done.released_at) <= done.max_wait + 1e-6).all()
    # repositioning happened, was recorded, and its metres are empty metres
    assert s["repositions"] > 0 and s["repositions"] == (ev.event == "reposition").sum()
    assert ((ev.event == "reposition") & (ev.task_id != -1)).sum() == 0
    assert 0 < s["reposition_distance"] <= s["empty_distance"] + 1e-6
    assert np.allclose(veh.distance, veh.empty_distance + veh.occupied_distance)
    assert s["distance"] == pytest.approx(veh.distance.sum())
    # no vehicle holds two trips at once
    served = tasks[tasks.agent_id >= 0].sort_values(["agent_id", "assigned_at"])
    for _, g in served.groupby("agent_id"):
        assert (g.assigned_at.values[1:] >= g.closed_at.values[:-1] - 1e-9).all()
    # a reposition event names an idle vehicle: none between its assign and its trip's end
    for r in ev[ev.event == "reposition"].itertuples():
        busy = served[(served.agent_id == r.agent_id) & (served.assigned_at < r.t)
                      & (served.closed_at > r.t)]
        assert busy.empty, (r.t, r.agent_id)


def test_same_seed_same_output(tmp_path):
    a = tmp_path / "a"
    b = tmp_path / "b"
    a.mkdir(), b.mkdir()
    _, ta = run(random_scenario(a, 3, allocator="greedy", faults=True))
    sb, tb = run(random_scenario(b, 3, allocator="greedy", faults=True))
    assert sb["repositions"] > 0
    for name in ("tasks", "events", "vehicles", "assignments"):
        cols = [c for c in ta[name].columns if c not in TIMING_COLUMNS]
        pd.testing.assert_frame_equal(ta[name][cols], tb[name][cols])


# ----------------------------------------------------------------------------- sweeps, layout


def test_a_sweep_over_repositioners_names_them_in_ids_partitions_and_summaries(tmp_path):
    from analysis.io import open_results

    trips = [*HOTSPOT, (500.0, 5, 11, None)]
    path = scenario(tmp_path, trips=trips, name="sw",
                    extra=DEMAND + '[sweep]\nreposition = ["stay", "demand"]\n')
    specs = load_scenario(path).runs()
    assert [s.reposition for s in specs] == ["stay", "demand"]
    assert [s.run_id for s in specs] == ["sw__fcfs__dijkstra__stay__n1__s1",
                                         "sw__fcfs__dijkstra__demand__n1__s1"]
    out = tmp_path / "out"
    summaries = execute(specs, out)
    assert [s["reposition"] for s in summaries] == ["stay", "demand"]
    assert [s["wait_time_mean"] for s in summaries] == pytest.approx([100.0, 20.0])
    leaf = out / "summary/scenario=sw/allocator=fcfs/planner=dijkstra/reposition=demand"
    assert (leaf / "n_agents=1/seed=1/part-0.parquet").is_file()
    res = open_results(out)
    got = res.summary.set_index("run_id")[["reposition", "repositions"]].to_dict("index")
    assert got == {"sw__fcfs__dijkstra__stay__n1__s1": {"reposition": "stay", "repositions": 0},
                   "sw__fcfs__dijkstra__demand__n1__s1": {"reposition": "demand",
                                                          "repositions": 1}}
    ev = res.table("events")
    assert set(ev[ev.event == "reposition"].reposition) == {"demand"}


def test_results_without_repositioning_read_as_stay(tmp_path):
    """Folders written before repositioners existed (no reposition column or partition)."""
    import pyarrow.parquet as pq

    from analysis.io import open_results

    path = scenario(tmp_path, trips=[*HOTSPOT, (500.0, 5, 11, None)], extra="", name="old")
    out = tmp_path / "out"
    execute(load_scenario(path).runs(), out)
    for f in (out / "summary").rglob("part-0.parquet"):  # as an older version wrote it
        table = pq.read_table(f)
        pq.write_table(table.drop_columns(["reposition", "repositions",
                                           "reposition_distance"]), f)
    res = open_results(out)
    assert res.summary.reposition.tolist() == ["stay"]
    assert set(res.table("tasks").reposition) == {"stay"}


# ----------------------------------------------------------------------------- errors


def one_line_error(path: Path, error=ScenarioError):
    with pytest.raises(error) as info:
        from dispatch.run.prepare import checked_specs

        class Args:
            scenario = path
            ignore_limits = False
            allocator = planner = agents = seed = duration = None
            capacity = batch_window = None  # the override options run, sweep and validate have
            overrides: list[str] = []

        checked_specs(Args)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


BAD = [
    ('[reposition]\npolicy = "teleport"\n',
     "reposition.policy: unknown repositioner 'teleport'; installed repositioners: demand, stay"),
    ('[sweep]\nreposition = ["stay", "nope"]\n',
     "sweep.reposition: unknown repositioner 'nope'; installed repositioners: demand, stay"),
    ('[reposition]\npolicy = "demand"\ninterval = 0\n', "reposition.interval: must be > 0.0"),
    ('[reposition]\npolicy = "demand"\nhorizon = "long"\n', "reposition.horizon: must be a number"),
    ('[reposition]\npolicy = 3\n', "reposition.policy: must be a non-empty string"),
    ('[reposition]\npolicy = "demand"\nzone = 500\n', "reposition.zone: unknown key"),
    ('[reposition]\npolicy = "stay"\n[reposition.demand]\nzone = 500.0\n',
     "reposition.demand: parameters of repositioner 'demand', which does not run"),
    ('[reposition]\npolicy = "demand"\n[reposition.teleport]\nx = 1\n',
     "reposition.teleport: unknown repositioner 'teleport'"),
]


@pytest.mark.parametrize("extra, words", BAD, ids=[w.split(":")[0] for _, w in BAD])
def test_bad_configuration_is_one_line_naming_the_key(tmp_path, extra, words):
    msg = one_line_error(scenario(tmp_path, trips=HOTSPOT, extra=extra))
    assert words in msg and str(tmp_path) in msg


@pytest.mark.parametrize("params, words", [
    ("zone = -5.0", ("repositioner 'demand' rejected its parameters (reposition.demand: "
                     "zone = -5.0): ValueError: zone must be a number of metres > 0, got -5.0")),
    # a typo names the key itself, not Python's TypeError
    ("radius = 3", ("reposition.demand.radius: repositioner 'demand' takes no parameter "
                    "'radius'; its parameters: zone, max_moves")),
])
def test_bad_policy_parameters_are_one_line_naming_the_table(tmp_path, params, words):
    extra = f'[reposition]\npolicy = "demand"\n[reposition.demand]\n{params}\n'
    msg = one_line_error(scenario(tmp_path, trips=HOTSPOT, extra=extra), PluginError)
    assert words in msg and str(tmp_path) in msg
    with pytest.raises(PluginError, match="rejected its parameters|takes no parameter"):
        run_one(load_scenario(scenario(tmp_path, trips=HOTSPOT, extra=extra)).runs()[0])


def test_a_voxel_world_refuses_a_moving_repositioner(tmp_path):
    from tests.conftest import write_scenario

    path = write_scenario(tmp_path)
    path.write_text(path.read_text() + '\n[reposition]\npolicy = "demand"\n')
    msg = one_line_error(path)
    assert ("reposition.policy: repositioner 'demand' moves vehicles on road spaces, not this "
            "scenario's voxel world (use 'stay' there)") in msg
    with pytest.raises(ScenarioError, match="voxel world"):
        run_one(load_scenario(path).runs()[0])
    path.write_text(path.read_text().replace('"demand"', '"stay"'))
    assert run_one(load_scenario(path).runs()[0]).summary["reposition"] == "stay"


class _Bad:
    """A repositioner that misbehaves in a chosen way."""

    name = "bad"
    passive = False
    spaces = ("road",)

    def __init__(self, answer):
        self.answer = answer

    def reposition(self, view):
        if isinstance(self.answer, Exception):
            raise self.answer
        return self.answer


@pytest.mark.parametrize("answer, words", [
    ({99: 1}, "move for vehicle 99, which is not an idle vehicle of the view"),
    ({0: 12}, "vehicle 0 sent to 12, not a node index of the network (0 .. 11)"),
    ({0: 3.0}, "vehicle 0 sent to 3.0, not a node index"),
    ([(0, 4)], "reposition() must return a mapping of vehicle id to node, got list"),
    (ZeroDivisionError("oops"), "reposition() raised ZeroDivisionError: oops"),
])
def test_a_misbehaving_repositioner_stops_the_run_with_one_line(tmp_path, monkeypatch, answer,
                                                                words):
    import dispatch.run.sim as sim_module

    monkeypatch.setattr(sim_module, "make_repositioner", lambda sc, name: _Bad(answer))
    [spec] = load_scenario(scenario(tmp_path, trips=[*HOTSPOT, (500.0, 5, 11, None)])).runs()
    with pytest.raises(PluginError) as info:
        run_one(spec)
    msg = str(info.value)
    assert "\n" not in msg and words in msg
    assert msg.startswith("repositioner 'bad', run grid__fcfs__dijkstra__demand__n1__s1, "
                          "t = 100 s: ")


def test_the_plugin_check_catches_a_bad_repositioner():
    from dispatch.api.repositioner import Repositioner
    from dispatch.checks.repositioners import check_repositioner

    class Wild(Repositioner):
        name = "wild"

        def reposition(self, view):
            return {int(i): int(np.random.randint(0, view.space.n)) for i in view.vehicle_ids}

    report = check_repositioner(Wild)
    assert not report.ok
    assert {r.name for r in report.failed()} == {"rng"}

    class Lost(Wild):
        def reposition(self, view):
            return {-1: 0}

    assert "valid" in {r.name for r in check_repositioner(Lost).failed()}


def test_cli_lists_and_checks_repositioners(capsys):
    from dispatch.run.cli import main

    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "repositioners (entry-point group dispatch.repositioners)" in out
    assert "demand" in out and "stay" in out
    assert max(len(line) for line in out.splitlines()) <= 80
    assert main(["check", "demand", "--param", "zone=150.0"]) == 0
    assert "passes every check" in capsys.readouterr().out
    assert not math.isnan(0.0)


def test_a_folder_mixing_layouts_reads_every_run(tmp_path):
    """A scenario with repositioning and one without, written into one folder: the older
    layout's runs read as stay (pyarrow; DuckDB's Hive reader wants one layout per folder)."""
    from analysis.io import open_results

    trips = [*HOTSPOT, (500.0, 5, 11, None)]
    out = tmp_path / "out"
    for name, extra in (("a", ""), ("b", DEMAND)):
        d = tmp_path / name
        d.mkdir()
        execute(load_scenario(scenario(d, trips=trips, name=name, extra=extra)).runs(), out)
    res = open_results(out)
    got = dict(zip(res.summary.run_id, res.summary.reposition))
    assert got == {"a__fcfs__dijkstra__n1__s1": "stay",
                   "b__fcfs__dijkstra__demand__n1__s1": "demand"}
    tasks = res.table("tasks")
    assert dict(tasks.groupby("run_id").reposition.first()) == got
    for run_id in got:
        assert res.metadata(run_id, "summary")["dispatch.run_id"] == run_id


def test_the_vehicle_timeline_shows_repositioning_as_idle_driving(tmp_path):
    from analysis.timeline import vehicle_intervals

    _, t = run(scenario(tmp_path, trips=[*HOTSPOT, (130.0, 0, 6, None)]))
    iv = vehicle_intervals(t["events"], t["vehicles"])
    assert iv[["state", "start", "end", "task_id"]].values.tolist() == [
        ["idle", 0.0, 100.0, -1], ["reposition", 100.0, 130.0, -1],
        ["travel", 130.0, 180.0, 3], ["travel", 180.0, 200.0, 3]]
