"""Drivers' breaks (``[fleet.breaks]``, dispatch.plan.breaks), checked from a run's tables alone:
a break never starts before ``after`` seconds on duty (from the run's start, then from the end
of the break before), lasts ``duration``, is taken with no rider on board and no stop made
during it; no promised pickup or drop-off is moved past its window by one (riders single and
shared); ``break_seconds`` sums each vehicle's; a plan never carries a rider across a planned
break (the insertion respects it); and a scenario that cannot plan breaks is refused."""

from __future__ import annotations

import numpy as np
import pytest

from dispatch.errors import ScenarioError
from dispatch.plan.breaks import BREAK
from dispatch.plan.stops import TOL
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

AFTER, DURATION, MAX_WAIT, MAX_DELAY, SERVICE = 900.0, 240.0, 300.0, 400.0, 10.0


def _trips(directory, seed: int, n: int = 160) -> None:
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(20.0))
        o, d = rng.choice(30, size=2, replace=False)
        rows.append((round(t, 3), int(o), int(d)))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node"], rows)


def _run(directory, *, capacity: int, allocator: str = "hungarian", seed: int = 0,
         extra: str = ""):
    _trips(directory, seed)
    tasks = (f'source = "trace"\ntrace = "trips.csv"\nmax_wait = {MAX_WAIT}\n'
             f'service_time = {SERVICE}' + (f"\nmax_delay = {MAX_DELAY}" if capacity > 1 else ""))
    fleet = (f"agents = 4\ncapacity = {capacity}\n\n[fleet.breaks]\nafter = {AFTER}\n"
             f"duration = {DURATION}")
    path = road_scenario(directory, tasks=tasks, fleet=fleet, allocator=allocator,
                         extra=('objective = "added_time"\n' if capacity > 1 else "") + extra,
                         duration=1e5)
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def check_breaks(tables) -> int:
    """Every promise of the module doc, from the events, tasks and vehicles tables; returns
    the breaks seen."""
    ev, tasks, veh = tables["events"], tables["tasks"], tables["vehicles"]
    seen = 0
    for agent, mine in ev[ev.agent_id >= 0].groupby("agent_id"):
        onboard, on_break, last_end, taken = 0, None, 0.0, 0.0
        riders = dict(zip(tasks.task_id, tasks.passengers))
        for e in mine.sort_values("t", kind="stable").itertuples():
            if e.event == "break_start":
                assert on_break is None
                assert onboard == 0, f"vehicle {agent}: {onboard} on board at its break"
                assert e.t >= last_end + AFTER - TOL, f"vehicle {agent}: a break at {e.t} s"
                on_break = e.t
            elif e.event == "break_end":
                assert on_break is not None
                assert e.t - on_break == pytest.approx(DURATION)
                taken += e.t - on_break
                last_end, on_break = e.t, None
                seen += 1
            elif on_break is not None:
                assert e.event not in ("pickup", "dropoff", "depart", "breakdown"), \
                    f"vehicle {agent}: {e.event} during its break"
            if e.event == "pickup":
                onboard += riders[e.task_id]
            elif e.event == "dropoff":
                onboard -= riders[e.task_id]
        if on_break is not None:  # (cut by the run's end)
            taken += float(ev.t.max()) - on_break
        row = veh[veh.agent_id == agent].iloc[0]
        assert row.break_seconds == pytest.approx(taken)
    done = tasks[(tasks.state == "completed") & (tasks.transfers == 0)]
    assert (done.picked_up_at - done.released_at <= MAX_WAIT + 1e-6).all()
    limited = done[done.max_delay.notna()]
    # (the drop-off is reached SERVICE seconds before the ride completes)
    late = limited.completed_at - SERVICE - limited.released_at - limited.direct_time
    assert (late <= limited.max_delay + 1e-6).all()
    return seen


@pytest.mark.parametrize("capacity,allocator", [(1, "hungarian"), (1, "fcfs"),
                                                (4, "hungarian"), (4, "greedy")])
def test_breaks_keep_every_promise(tmp_path, capacity, allocator):
    summary, tables = _run(tmp_path, capacity=capacity, allocator=allocator)
    assert check_breaks(tables) >= 8  # every vehicle breaks more than once in the hour
    assert summary["tasks_completed"] > 100
    assert (tables["vehicles"].break_seconds > 0).all()


def test_without_breaks_no_break_is_taken(tmp_path):
    _trips(tmp_path, 0)
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                         'max_wait = 300.0', fleet="agents = 4")
    [spec] = load_scenario(path).runs()
    tables = {n: t.to_pandas() for n, t in run_one(spec).tables.items()}
    assert not tables["events"].event.isin(["break_start", "break_end"]).any()
    assert (tables["vehicles"].break_seconds == 0).all()


def test_the_same_seed_gives_the_same_breaks(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _run(tmp_path / "a", capacity=4)[1]
    b = _run(tmp_path / "b", capacity=4)[1]
    cols = ["t", "event", "agent_id", "task_id"]
    assert a["events"][cols].equals(b["events"][cols])


def test_the_insertion_never_carries_a_rider_across_a_break():
    """A plan [drop-off, break, pickup]: a new request may ride before the break or after
    the stop that follows it, never across the break (the break holds the seats)."""
    from dispatch.plan.insertion import insertion_costs
    from dispatch.plan.stops import ADDED_TIME, Stop, occupancies

    plan = [Stop("dropoff", None, 1, -1, 1e9, True),
            Stop(BREAK, None, 1, 0, np.inf, False, earliest=0.0, service=100.0,
                 holds_seats=True),
            Stop("pickup", None, 2, 1, 1e9, False)]
    occupancies(1, plan, 4)
    assert [s.occupancy for s in plan] == [0, 4, 1]

    def tt(a, b):
        return abs(a - b) * 10.0

    locs = [s.loc for s in plan]
    arr = [10.0, 10.0, 120.0]
    req = (3, 4)  # a request from node 3 to node 4, loose windows
    got = insertion_costs(
        np.zeros(1, np.int64), np.arange(1), ready=[0.0], first_tt=[tt(0, req[0])], off=[0, 3],
        s_arr=arr, s_svc=[s.service for s in plan], s_latest=[s.latest for s in plan],
        s_occ=[s.occupancy for s in plan], load=[1], cap=[4],
        to_p=np.array([[tt(x, req[0])] for x in locs]),
        from_p=np.array([[tt(req[0], x) for x in locs]]),
        to_d=np.array([[tt(x, req[1])] for x in locs]),
        from_d=np.array([[tt(req[1], x) for x in locs]]), pd_tt=[tt(*req)], req_n=[1],
        req_lp=[1e9], req_ld=[1e9], req_svc_p=[0.0], req_svc_d=[0.0], objective=ADDED_TIME,
        s_earliest=[s.earliest for s in plan], req_earliest=[-np.inf])
    at = got.of(0)
    assert np.isfinite(got.cost[0])
    # the pickup and the drop-off both before the break, or both after the stop after it
    assert (at.i <= 1 and at.j <= 1) or at.i == 3, at


@pytest.mark.parametrize("allocator,capacity,extra", [
    ("rtv", 2, ""), ("hungarian", 1, "reassign = true")])
def test_a_scenario_that_cannot_plan_breaks_is_refused(tmp_path, capsys, allocator, capacity,
                                                        extra):
    from dispatch.run.cli import main

    _trips(tmp_path, 0)
    fleet = f"agents = 4\ncapacity = {capacity}\n\n[fleet.breaks]\nafter = {AFTER}"
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                         'max_wait = 300.0\nmax_delay = 300.0', fleet=fleet,
                         allocator=allocator, extra=extra)
    assert main(["validate", str(path)]) == 2
    assert "fleet.breaks" in capsys.readouterr().err


def test_breaks_need_a_road_network(tmp_path):
    path = tmp_path / "v.toml"
    path.write_text('name = "v"\nseed = 0\n\n[world]\nsize = [40, 40, 3]\n\n'
                    '[fleet]\nagents = 2\n\n[fleet.breaks]\nafter = 60.0\n\n'
                    '[tasks]\nsource = "static"\ncount = 2\n', encoding="utf-8")
    with pytest.raises(ScenarioError, match="road network"):
        load_scenario(path)


def test_the_fleet_states_and_the_replay_show_the_breaks(tmp_path):
    """The analysis' fleet states (which the replay and the fleet-state plots draw) hold each
    vehicle ``on_break`` exactly its ``break_seconds``."""
    from analysis.timeline import fleet_states

    _, tables = _run(tmp_path, capacity=4)
    states = fleet_states(tables["events"], tables["vehicles"])
    on = states[states.state == "on_break"]
    got = (on.end - on.start).groupby(on.agent_id).sum()
    want = tables["vehicles"].set_index("agent_id").break_seconds
    assert got.reindex(want.index, fill_value=0.0).to_numpy() == pytest.approx(want.to_numpy())
