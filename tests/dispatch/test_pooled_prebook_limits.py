"""Shared rides with stops that open later (a booked ride's requested departure, a walking
rider's arrival at the boarding point) keep every rider's limits.

A vehicle early for such a stop waits there; while it waits, its plan's times start at each
decision's ``now`` (:func:`dispatch.plan.vehicle_plan.starts_now`). Checked three ways:

* a shrunk case (two vehicles, four requests on a 25 x 2 grid) where a decision that read the
  waiting vehicle's plan early left a stale arrival for a later one, which then planned an
  immediate rider's drop-off 120 s too early and let a third request make it 47 s late;
* at every decision of random pooled runs with bookings (and walking): every plan the
  decision reads holds the times the plan has afresh, and after every hand-out the plan's
  times are the rule's over the planner's drives, every stop within its limits;
* from the tables alone, over seeds and allocators: no rider picked up after release +
  ``max_wait`` or dropped off after release + direct time + ``max_delay`` (less the walk from
  the alighting point), no booked rider picked up before the requested departure and no
  walker before reaching the boarding point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dispatch.decide.plan_costs import PlanTable
from dispatch.plan.operator import Operator
from dispatch.plan.stops import leave
from dispatch.plan.vehicle_plan import Plan
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

EPS = 1e-6
WALK_SPEED = 1.4  # ([tasks] walk_speed's default)


def broken_limits(tables: dict, walk_speed: float = WALK_SPEED) -> list[tuple]:
    """The limits a run broke, read from its ``tasks`` and ``events`` tables only: ``(task,
    what, seconds)`` for a pickup after release + ``max_wait``, a pickup before release + the
    walk to the boarding point (release: a booked ride's requested departure), a drop-off
    after release + direct time + ``max_delay`` - the walk from the alighting point. Riders
    moved after a breakdown are left aside (their limits are not the plan's)."""
    tasks = tables["tasks"].set_index("task_id")
    ev = tables["events"]
    drop = ev[ev.event == "dropoff"].groupby("task_id").t.max()
    out = []
    for k, t in tasks.iterrows():
        if not np.isfinite(t.picked_up_at) or t.reassigned > 0:
            continue
        walk_to = t.walk_to_board_m if np.isfinite(t.walk_to_board_m) else 0.0
        walk_from = t.walk_from_alight_m if np.isfinite(t.walk_from_alight_m) else 0.0
        if np.isfinite(t.max_wait) and t.picked_up_at > t.released_at + t.max_wait + EPS:
            out.append((k, "late pickup", t.picked_up_at - t.released_at - t.max_wait))
        if t.picked_up_at < t.released_at + walk_to / walk_speed - EPS:
            out.append((k, "early pickup", t.released_at + walk_to / walk_speed
                        - t.picked_up_at))
        if k in drop.index and np.isfinite(t.max_delay):
            latest = t.released_at + t.direct_time + t.max_delay - walk_from / walk_speed
            if drop[k] > latest + EPS:
                out.append((k, "late drop-off", drop[k] - latest))
    return out


def _run(path: Path) -> tuple[dict, dict]:
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


# ------------------------------------------------------------------ the shrunk case
def _shrunk(directory: Path, allocator: str) -> Path:
    """Nodes ``c`` (row 0) and ``25 + c`` (row 1) at column ``c``, 10 s a block. Vehicle 0
    stands at node 0, vehicle 1 at node 5, four seats each. A (booked at 0 for 600 s, node 1
    to 20) goes to vehicle 0, which waits at node 1 from 10 s. X (100 s, node 4) goes to
    vehicle 1, the decision reading vehicle 0's plan as well. Y (400 s, node 2 to 20,
    immediate) fits only vehicle 0, before A's pickup: its drop-off is due at 793 s and
    planned at 790 s (A's departure 600 s + 190 s). Z (450 s, node 26 to 35) fits only
    before A's pickup too: it would make vehicle 0 reach node 1 at 650 s and Y's drop-off
    840 s, so no vehicle may take it."""
    write_csv(directory / "trips.csv",
              ["t", "origin_node", "dest_node", "booked_at", "max_wait", "max_delay"],
              [(600.0, 1, 20, 0.0, 60.0, 300.0), (100.0, 4, 24, "", 120.0, 300.0),
               (400.0, 2, 20, "", 120.0, 213.0), (450.0, 26, 35, "", 120.0, 300.0)])
    write_csv(directory / "fleet.csv", ["vehicle_id", "x", "y"], [(0, 0.0, 0.0),
                                                                   (1, 500.0, 0.0)])
    return road_scenario(directory, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"\ncapacity = 4', allocator=allocator,
                         network='network = "manhattan"\nblocks = [25, 2]\nblock = 100.0\n'
                         'speed = 10.0', duration=3600.0, extra="batch_window = 0.0")


@pytest.mark.parametrize("allocator", ["hungarian", "greedy", "fcfs", "auction",
                                       "local_hungarian", "rtv"])
def test_the_shrunk_case_keeps_the_immediate_riders_drop_off(tmp_path, allocator):
    _, tables = _run(_shrunk(tmp_path, allocator))
    assert broken_limits(tables) == []
    tasks = tables["tasks"].set_index("task_id")
    # A (0), X (1) and Y (2) ride as planned; Y's drop-off is at 790 s, not after its 793 s
    assert (tasks.loc[[0, 1, 2]].state == "completed").all()
    ev = tables["events"]
    y_drop = ev[(ev.event == "dropoff") & (ev.task_id == 2)].t.iloc[0]
    assert y_drop == pytest.approx(790.0)
    assert tasks.loc[0].picked_up_at == pytest.approx(600.0)
    # Z (3): taken only where it keeps Y's limit, which no place in vehicle 0's plan does
    assert tasks.loc[3].state != "completed" or tasks.loc[3].agent_id == 1


# ------------------------------------------------------------------ at every decision
def _retimed(op: Operator, v, now: float) -> list[float]:
    """``v``'s plan timed afresh by the rule over the planner's drives (from its leg's end
    while it drives to the first stop, else from where it stands)."""
    stops, planner = v.plan.stops, op.driver.planner
    if v.heading is stops[0] and v.leg is not None:
        t = v.leg_start + v.leg.seconds
    else:
        t = max(now, v.free_at) + float(planner.between([v.location(now)],
                                                        [stops[0].loc])[0, 0])
    out = [t]
    for a, b in zip(stops, stops[1:]):
        t = leave(t, a.earliest, a.service) + float(planner.between([a.loc], [b.loc])[0, 0])
        out.append(t)
    return out


def _trace(directory: Path, seed: int, n: int, share: float) -> None:
    """``n`` trips on the 6 x 5 grid, ``share`` of them booked 60-900 s ahead; limits drawn
    per row (``max_wait`` 60-240 s, ``max_delay`` 60-400 s)."""
    rng = np.random.default_rng([seed, 42])
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(12.0))
        o, d = rng.choice(30, size=2, replace=False)
        booked = round(max(t - float(rng.uniform(60.0, 900.0)), 0.0), 1) \
            if rng.random() < share else ""
        rows.append((round(t, 1), int(o), int(d), booked,
                     round(float(rng.uniform(60.0, 240.0)), 1),
                     round(float(rng.uniform(60.0, 400.0)), 1)))
    write_csv(directory / "trips.csv",
              ["t", "origin_node", "dest_node", "booked_at", "max_wait", "max_delay"], rows)


def _scenario(directory: Path, seed: int, allocator: str, capacity: int, walk: float,
              mode: str) -> Path:
    _trace(directory, seed, 60, 0.5)
    tasks = f'source = "trace"\ntrace = "trips.csv"\nmax_walk = {walk!r}'
    extra = f'batch_window = 10.0\nprebook = "{mode}"\nprebook_lead = 300.0'
    return road_scenario(directory, tasks=tasks, fleet=f"agents = 3\ncapacity = {capacity}",
                         allocator=allocator, extra=extra)


CASES = [("hungarian", 3, 0.0, "at_booking"), ("greedy", 2, 0.0, "lead"),
         ("fcfs", 4, 0.0, "at_booking"), ("hungarian", 3, 150.0, "at_booking"),
         ("rtv", 3, 0.0, "at_booking"), ("rtv", 3, 150.0, "lead")]


@pytest.mark.parametrize("allocator,capacity,walk,mode", CASES)
def test_every_decision_reads_the_plans_times_afresh(tmp_path, monkeypatch, allocator,
                                                     capacity, walk, mode):
    seen = {"read": 0, "waiting": 0, "handed": 0}
    gather, arrays = PlanTable.gather, Plan.arrays
    assign, follow = Operator.assign, Operator.follow

    def checked_arrays(self, now):  # (what meeting points and allocators' views read)
        out = arrays(self, now)
        assert out[0] == pytest.approx(self.times(now), abs=EPS)
        seen["read"] += 1
        seen["waiting"] += self.vehicle.waiting
        return out

    def checked_gather(self, fleet, slots, now):
        out = gather(self, fleet, slots, now)
        off, arr = out[0], out[1]
        for i, k in enumerate(np.asarray(slots).tolist()):
            v = fleet.vehicles[k]
            assert arr[off[i]:off[i + 1]].tolist() == pytest.approx(v.plan.times(now),
                                                                    abs=EPS)
            seen["read"] += 1
            seen["waiting"] += v.waiting
        return out

    def checked(op, v):
        now = op.env.now
        if not v.plan:
            return
        planned, real = v.plan.times(now), _retimed(op, v, now)
        assert planned == pytest.approx(real, abs=EPS), (now, v.id)
        for s, t in zip(v.plan.stops, real):
            assert t <= s.latest + EPS, (now, v.id, s.kind, s.task.id, t, s.latest)
        seen["handed"] += 1

    def checked_assign(self, task, v, *args, **kw):
        assign(self, task, v, *args, **kw)
        checked(self, v)

    def checked_follow(self, v, *args, **kw):
        follow(self, v, *args, **kw)
        checked(self, v)

    monkeypatch.setattr(PlanTable, "gather", checked_gather)
    monkeypatch.setattr(Plan, "arrays", checked_arrays)
    monkeypatch.setattr(Operator, "assign", checked_assign)
    monkeypatch.setattr(Operator, "follow", checked_follow)
    summary, tables = _run(_scenario(tmp_path, 0, allocator, capacity, walk, mode))
    assert broken_limits(tables) == []
    assert summary["tasks_completed"] > 30 and seen["handed"] > 30
    assert seen["read"] > 50 and seen["waiting"] > 5, seen


# ------------------------------------------------------------------ from the tables, seeds
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("allocator,capacity,walk,mode", CASES)
def test_pooled_booked_rides_keep_every_limit(tmp_path, seed, allocator, capacity, walk,
                                              mode):
    summary, tables = _run(_scenario(tmp_path, seed, allocator, capacity, walk, mode))
    assert broken_limits(tables) == []
    tasks = tables["tasks"]
    booked = tasks[tasks.booked_at.notna() & tasks.picked_up_at.notna()]
    assert len(booked) > 5 and summary["shared_rate"] > 0
    if walk and allocator != "rtv":  # (rtv boards a rider where no vehicle waits for a walk)
        assert (tasks.walk_to_board_m.fillna(0) > 0).any()
    # the checker sees a broken limit where there is one (and only there)
    bad = tasks.copy()
    k = bad.index[bad.picked_up_at.notna()][0]
    bad.loc[k, "max_wait"] = bad.loc[k, "picked_up_at"] - bad.loc[k, "released_at"] - 1.0
    assert [b[:2] for b in broken_limits({**tables, "tasks": bad})] == \
        [(int(bad.loc[k, "task_id"]), "late pickup")]
