"""Driver shifts and fleet sizing (dispatch.fleet.shifts): no pickup outside a vehicle's shift,
every
vehicle at its depot by its shift's end plus the grace or the overrun counted, neutral
machinery reproducing the runs without it, the ``utilization`` sizer within its bounds, and
one-line errors for bad shift columns."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

EPS = 1e-6


def _trace(directory: Path, seed: int, n: int = 70, max_pax: int = 1) -> None:
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(14.0))
        o, d = rng.choice(30, size=2, replace=False)
        rows.append((round(t, 3), int(o), int(d), int(rng.integers(1, max_pax + 1))))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "passengers"], rows)


FLEET = [  # vehicle_id, node, shift_start, shift_end, depot
    (0, 0, 0, 300, "0"),
    (1, 5, 200, 800, "210,290"),
    (2, 29, 500, "", "29"),
    (3, 14, 100, 650, ""),
]


def _run(directory: Path, *, allocator: str = "hungarian", capacity: int = 1,
         grace: float = 0.0, rows=FLEET, fleet_extra: str = "", extra: str = "",
         seed: int = 0, max_delay: float | None = None, columns=True, tasks_extra: str = ""):
    _trace(directory, seed, max_pax=min(capacity, 2))
    header = ["vehicle_id", "node", "shift_start", "shift_end", "depot"]
    if columns:
        write_csv(directory / "fleet.csv", header, rows)
    else:
        write_csv(directory / "fleet.csv", header[:2], [r[:2] for r in rows])
    tasks = 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0'
    if max_delay is not None:
        tasks += f"\nmax_delay = {max_delay}"
    tasks += tasks_extra
    fleet = f'start = "fleet.csv"\ncapacity = {capacity}\nshift_grace = {grace}\n{fleet_extra}'
    path = road_scenario(directory, tasks=tasks, fleet=fleet, allocator=allocator,
                         extra=extra, duration=1e5)
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def _position(tables, agent: int, t: float):
    ev = tables["events"]
    return ev[(ev.agent_id == agent) & (ev.t == t)]


@pytest.mark.parametrize("allocator,capacity,grace,max_delay", [
    ("hungarian", 1, 0.0, None), ("greedy", 1, 45.0, None), ("fcfs", 1, 0.0, None),
    ("hungarian", 3, 0.0, 300.0), ("greedy", 3, 60.0, None)])
def test_no_pickup_outside_the_shift_and_home_by_its_end(tmp_path, allocator, capacity, grace,
                                                         max_delay):
    summary, tables = _run(tmp_path, allocator=allocator, capacity=capacity, grace=grace,
                           max_delay=max_delay)
    check_shifts(summary, tables, grace)


@pytest.mark.parametrize("capacity,grace,max_delay,reorder", [
    (3, 0.0, 300.0, False), (2, 45.0, None, False), (3, 0.0, None, True),
    (4, 30.0, 400.0, True)])
def test_rtv_keeps_every_shift_limit(tmp_path, capacity, grace, max_delay, reorder):
    """``rtv`` routes its groups itself, each route ending by the vehicle's shift end plus the
    grace (``problem.until``): the same checks as the single-request allocators'."""
    extra = "\n[dispatch.allocator_params.rtv]\nreorder = true" if reorder else ""
    summary, tables = _run(tmp_path, allocator="rtv", capacity=capacity, grace=grace,
                           max_delay=max_delay, extra=extra)
    check_shifts(summary, tables, grace)


def check_shifts(summary: dict, tables: dict, grace: float) -> None:
    """No request assigned outside a vehicle's shift, every pickup and completion within it
    and the grace, each vehicle left once at its depot (an overrun counted), its hours."""
    ev, veh = tables["events"], tables["vehicles"].set_index("agent_id")
    tasks = tables["tasks"]
    assert summary["tasks_completed"] > 10
    for a, row in veh.iterrows():
        start, end = row.shift_start, row.shift_end
        mine = ev[ev.agent_id == a]
        # nothing assigned before its shift or after its end; every pickup and every
        # completion of its requests within [start, end + grace]
        assigned = mine[mine.event.isin(["assign", "insert"])].t
        assert (assigned >= start - EPS).all() and (assigned <= end + EPS).all(), (a, assigned)
        picks = mine[mine.event == "pickup"].t
        assert (picks >= start - EPS).all() and (picks <= end + grace + EPS).all(), (a, picks)
        done = tasks[(tasks.agent_id == a) & (tasks.state == "completed")].completed_at
        assert (done <= end + grace + EPS).all(), (a, done.max(), end + grace)
        assert mine.t.min() >= start - EPS or start == 0
        if not math.isfinite(end):
            assert row.overrun_seconds == 0
            continue
        # it left the fleet once, at its depot, in time or with the overrun counted
        left = mine[mine.event == "shift_end"]
        assert len(left) == 1, (a, left)
        t_left = float(left.t.iloc[0])
        assert t_left >= end - EPS
        assert row.overrun_seconds == pytest.approx(max(0.0, t_left - (end + grace)), abs=1e-6)
        assert mine[mine.t > t_left + EPS].empty, "nothing after it left"
    depot_0 = _position(tables, 0, float(ev[(ev.agent_id == 0) & (ev.event == "shift_end")]
                                         .t.iloc[0]))
    assert (depot_0.x.iloc[-1], depot_0.y.iloc[-1]) == (0.0, 0.0)  # node 0 is at (0, 0)
    assert summary["shift_overruns"] == int((veh.overrun_seconds > 0).sum())
    # on-duty hours: from its shift's start to its arrival at the depot (or the run's end)
    for a, row in veh.iterrows():
        left = ev[(ev.agent_id == a) & (ev.event == "shift_end")].t
        until = float(left.iloc[0]) if len(left) else summary["sim_time"]
        assert row.vehicle_hours == pytest.approx((until - row.shift_start) / 3600.0)
    assert summary["vehicle_hours"] == pytest.approx(veh.vehicle_hours.sum())
    assert summary["riders_per_vehicle_hour"] == pytest.approx(
        summary["tasks_completed"] / summary["vehicle_hours"])


def test_depot_xy_is_snapped_and_the_vehicle_starts_there(tmp_path):
    _, tables = _run(tmp_path)
    ev = tables["events"]
    first = ev[(ev.agent_id == 1)].iloc[0]
    assert first.event == "shift_start" and first.t == 200.0
    assert (first.x, first.y) == (200.0, 300.0)  # "210,290" snaps to the node at (200, 300)


@pytest.mark.parametrize("capacity", [1, 3])
def test_neutral_shifts_reproduce_the_run_without_them(tmp_path, capacity):
    """``fixed`` with no shift columns is today's run; blank columns, or shifts covering the
    whole run, change nothing either."""
    a = tmp_path / "a"
    b = tmp_path / "b"
    c = tmp_path / "c"
    for d in (a, b, c):
        d.mkdir()
    plain = [(v, n, "", "", "") for v, n, *_ in FLEET]
    covering = [(v, n, 0, 1e9, str(n)) for v, n, *_ in FLEET]
    s0, t0 = _run(a, capacity=capacity, columns=False)
    s1, t1 = _run(b, capacity=capacity, rows=plain, fleet_extra='sizing = "fixed"')
    s2, t2 = _run(c, capacity=capacity, rows=covering)
    cols = [k for k in s0 if k not in ("run_id", "alloc_seconds", "cost_seconds",
                                        "decide_seconds", "first_decision_seconds", "agent_seconds")]
    for s in (s1, s2):
        for k in cols:
            assert s[k] == s0[k] or (s[k] != s[k] and s0[k] != s0[k]), k
    for t in (t1, t2):
        pd.testing.assert_frame_equal(t["tasks"].drop(columns="run_id"),
                                      t0["tasks"].drop(columns="run_id"))
        pd.testing.assert_frame_equal(t["events"].drop(columns="run_id"),
                                      t0["events"].drop(columns="run_id"))
    assert s0["vehicle_hours"] == pytest.approx(len(FLEET) * s0["sim_time"] / 3600.0)


def test_utilization_sizer_keeps_its_bounds(tmp_path):
    rows = [(v, v * 3, "", "", str(v * 3)) for v in range(8)]
    params = ("[fleet.sizing_params]\nmin_vehicles = 2\nmax_vehicles = 6\ninterval = 120.0\n"
              "low = 0.3\nhigh = 0.6")
    summary, tables = _run(tmp_path, rows=rows, fleet_extra='sizing = "utilization"\n' + params)
    ev = tables["events"].sort_values("t", kind="stable")
    on = {a: a < 2 for a in range(8)}  # the first min_vehicles start on duty
    joined = left = 0
    for e in ev.itertuples(index=False):
        a = int(e.agent_id)
        if e.event == "shift_start":
            assert not on[a]
            on[a] = True
            joined += 1
        elif e.event == "shift_end":
            left += 1
            on[a] = False
        elif e.event in ("assign", "pickup", "insert"):
            assert on[a], (e.t, a, e.event)
        if e.event in ("shift_start", "shift_end"):
            assert 2 - 1 <= sum(on.values()) <= 6, (e.t, sum(on.values()))
    assert joined > 0 and left > 0
    assert summary["vehicle_hours"] < 8 * summary["sim_time"] / 3600.0


def _error(tmp_path, rows, header=("vehicle_id", "node", "shift_start", "shift_end", "depot"),
           tasks_extra=""):
    _trace(tmp_path, 0)
    write_csv(tmp_path / "fleet.csv", list(header), rows)
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n' + tasks_extra,
                         fleet='start = "fleet.csv"')
    with pytest.raises(ScenarioError) as e:
        [spec] = load_scenario(path).runs()
        run_one(spec)
    msg = str(e.value)
    assert "\n" not in msg and "fleet.csv" in msg
    return msg


def test_shift_ending_before_it_starts(tmp_path):
    msg = _error(tmp_path, [(0, 0, 0, 300, ""), (1, 3, 500, 400, "")])
    assert "row 2" in msg and "shift_end" in msg and "shift_start" in msg


def test_depot_off_the_network(tmp_path):
    msg = _error(tmp_path, [(0, 0, 0, 300, ""), (1, 3, 0, 400, "9999")])
    assert "row 2" in msg and "depot" in msg and "off the network" in msg
    msg = _error(tmp_path, [(0, 0, 0, 300, "5000,5000")])
    assert "row 1" in msg and "depot" in msg and "off the network" in msg


def test_bad_shift_cells(tmp_path):
    msg = _error(tmp_path, [(0, 0, "soon", 300, "")])
    assert "row 1" in msg and "shift_start" in msg and "[tasks] start" in msg
    msg = _error(tmp_path, [(0, 0, 0, 300, ""), (1, 0, 0, "nan", "")])
    assert "row 2" in msg and "shift_end" in msg


def test_date_time_shifts(tmp_path):
    """Date-times are read as seconds from [tasks] start, as a trace's departure_time."""
    rng = np.random.default_rng(0)
    rows = [(f"2014-12-21 00:{m:02d}:{s:02d}", int(o), int(d)) for m, s, (o, d) in
            zip(range(0, 20), rng.integers(0, 60, 20), rng.integers(0, 30, (20, 2))) if o != d]
    write_csv(tmp_path / "trips.csv", ["departure_time", "origin_node", "dest_node"], rows)
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node", "shift_start", "shift_end"],
              [(0, 0, "2014-12-21 00:05", "2014-12-21T00:15"), (1, 3, "", "")])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                         'start = "2014-12-21T00:00"', fleet='start = "fleet.csv"')
    sc = load_scenario(path)
    assert sc.fleet.shifts.start == (300.0, 0.0) and sc.fleet.shifts.end == (900.0, math.inf)


def test_unknown_sizer(tmp_path):
    _trace(tmp_path, 0)
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='agents = 2\nsizing = "utilisation"')
    with pytest.raises(ScenarioError, match="fleet.sizing.*did you mean 'utilization'"):
        load_scenario(path)


def test_utilization_rule():
    """The strategy's answer from its view, by its rule: in the band it keeps the fleet; above
    it, the size at the target utilisation; below it, smaller; a share unserved above
    max_unserved grows it; always within the bounds and what the pool allows."""
    from dispatch.api.sizer import SizingView
    from sizers.utilization import UtilizationSizer

    s = UtilizationSizer(min_vehicles=5, max_vehicles=40, low=0.4, high=0.8, target=0.6)
    rng = np.random.default_rng(0)

    def view(on, u, pool=100, unserved=0.0):
        return SizingView(0.0, on, 0, pool, u, rng, unserved)

    assert s.size(view(20, 0.5)) == 20
    assert s.size(view(20, 0.9)) == math.ceil(20 * 0.9 / 0.6)
    assert s.size(view(20, 0.2)) == math.ceil(20 * 0.2 / 0.6)
    assert s.size(view(20, 0.1)) == 5  # not below min_vehicles
    assert s.size(view(30, 1.0)) == 40  # not above max_vehicles
    assert s.size(view(20, 0.95, pool=3)) == 23  # not beyond the pool
    assert s.size(view(20, 0.5, unserved=0.2)) == 25  # 20 / (1 - 0.2)
    assert s.size(view(20, 0.2, unserved=0.2)) == 25  # unserved: no shrinking
    assert s.size(view(20, 0.5, unserved=1.0)) == 40  # none served: all the bounds allow
    assert s.size(view(20, float("nan"))) == 20
    assert s.initial(view(0, float("nan"), pool=50)) == 5
    with pytest.raises(ValueError, match="max_vehicles"):
        UtilizationSizer(min_vehicles=5, max_vehicles=3)


def test_shifts_with_meeting_points_keep_the_shift(tmp_path):
    # meeting points cost insertions for idle and busy vehicles alike; the shift limit reads
    # the busy ones' insertion times from them as it does door to door
    summary, tables = _run(tmp_path, capacity=3, max_delay=300.0,
                           tasks_extra="\nmax_walk = 200.0\nmeeting_points = 4")
    ev, veh, tasks = tables["events"], tables["vehicles"].set_index("agent_id"), tables["tasks"]
    assert summary["tasks_completed"] > 10 and (tasks.walk_to_board_m > 0).any()
    for a, row in veh.iterrows():
        picks = ev[(ev.agent_id == a) & (ev.event == "pickup")].t
        assert (picks >= row.shift_start - EPS).all() and (picks <= row.shift_end + EPS).all()

