"""Meeting points (dispatch.decide.meeting): every decision's costs equal an exhaustive search over
every candidate boarding and alighting point and every pair of stop positions (the independent
reference of tests/dispatch/reference.py) on the plans of small pooled runs; the rides keep the
walking limits (boarding no sooner than release + walk time, walks within ``max_walk``, the
straight line from the origin no longer than the walk, the drop-off by the latest arrival less
the walk from it); ``max_walk = 0`` is door to door; bad input is one line naming the place."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

import dispatch.decide.pipeline as decision
from dispatch.decide.meeting import Walks, meeting_costs
from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import manhattan
from tests.dispatch.reference import brute_force_insertion
from tests.dispatch.test_pooling import check_invariants
from tests.dispatch.test_trips import road_scenario, write_csv

EPS = 1e-6
SPEED = 1.4


def _trace(directory: Path, seed: int, n: int = 16, walk_column: bool = False) -> None:
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(10.0))
        o, d = rng.choice(30, size=2, replace=False)
        row = [round(t, 3), int(o), int(d), int(rng.integers(1, 3))]
        if walk_column:
            row.append(float(rng.choice([0.0, 100.0, 250.0])))
        rows.append(tuple(row))
    header = ["t", "origin_node", "dest_node", "passengers"]
    write_csv(directory / "trips.csv", header + (["max_walk"] if walk_column else []), rows)


def _scenario(directory: Path, *, walk: float | None, allocator: str = "hungarian",
              objective: str = "added_time", capacity: int = 3, agents: int = 3,
              service: float = 0.0, faults: bool = False) -> Path:
    tasks = ('source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0\nmax_delay = 300.0'
             f"\nservice_time = {service}")
    if walk is not None:
        tasks += f"\nmax_walk = {walk}\nwalk_speed = {SPEED}\nmeeting_points = 4"
    extra = f'objective = "{objective}"'
    if faults:
        extra += '\n\n[faults]\nrate = 30.0\nrepair = 60.0\non_board = "transfer"'
    return road_scenario(directory, tasks=tasks, fleet=f"agents = {agents}\ncapacity = "
                         f"{capacity}", allocator=allocator, extra=extra)


def _tables(path: Path):
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def _brute(walks, cost, slots, agents, tasks, now, holders, fleet, operator, planner,
           objective):
    """Every (vehicle, request, candidate pair of points): the least cost over every pair of
    positions, by re-simulating each plan (tests/dispatch/reference.py), as an array
    ``(vehicles, requests, pairs)`` (inf past a request's pairs). A plan's
    stops keep their planned drives between them (as a decision reads a plan: the drive
    between two consecutive stops of a plan is the one planned), every other drive is the
    planner's."""
    out = np.full((*cost.shape, 64), math.inf)
    svc = operator.service_time

    def node(x):
        return x[1] if isinstance(x, tuple) else x

    for r, k in enumerate(slots.tolist()):
        v = fleet.vehicles[k]
        loc = agents[r].loc
        planned = bool(fleet.busy_mask[k]) and v.id not in holders
        ready = max(float(fleet.free_at[k]), now) if planned else now
        stops, load, legs = [], 0, {}
        if planned:
            times, svcs, latest, occ, where, earliest = v.plan.arrays(now)
            load = before = v.load
            for g, (x, s, lt, o, e) in enumerate(zip(where, svcs, latest, occ, earliest)):
                stops.append(((g, int(x)), o - before, lt, s, e))
                before = o
                if g:
                    legs[g] = times[g] - max(times[g - 1], earliest[g - 1]) - svcs[g - 1]
            arrive0 = times[0] if times else None

        def tt(a, b, legs=legs):
            if isinstance(a, tuple) and isinstance(b, tuple) and b[0] == a[0] + 1:
                return legs[b[0]]
            return float(planner.between([node(a)], [node(b)])[0, 0])

        def first_tt(x, loc=loc, ready=ready):
            if isinstance(x, tuple) and x[0] == 0:
                return arrive0 - ready  # (the plan's first stop, as planned)
            return float(planner.between([loc], [node(x)])[0, 0])

        for c, t in enumerate(tasks):
            for q, (b, a, e, ld) in enumerate(_points(walks, t)):
                req = (b, a, t.passengers, t.deadline, ld, 0.0, svc, e)
                out[r, c, q] = brute_force_insertion(ready, first_tt, stops, load, v.capacity,
                                                     req, tt, objective)[0]
    return out


def _points(walks, t):
    """``t``'s candidate pairs in order: (board, alight, earliest pickup, latest drop-off)."""
    cand = walks.of(t)
    return [(b, a, t.released_at + wb / t.walk_speed if wb > 0 else -math.inf,
             t.dropoff_deadline - wa / t.walk_speed)
            for b, wb in zip(cand.board.tolist(), cand.board_m.tolist())
            for a, wa in zip(cand.alight.tolist(), cand.alight_m.tolist())]


@pytest.mark.parametrize("seed,objective,service", [(0, "added_time", 0.0),
                                                    (1, "pickup_time", 0.0),
                                                    (2, "added_time", 5.0)])
def test_costs_equal_a_brute_force_over_points_and_positions(tmp_path, monkeypatch, seed,
                                                             objective, service):
    """Each decision of a small pooled run: the meeting costs are the exhaustive minimum."""
    checked = []

    def spy(walks, cost, slots, agents, tasks, now, *, holders, fleet, operator, planner,
            objective, one_point):
        assert not one_point
        got, inserts, _ = meeting_costs(walks, cost, slots, agents, tasks, now,
                                        holders=holders, fleet=fleet, operator=operator,
                                        planner=planner, objective=objective)
        each = _brute(walks, cost, slots, agents, tasks, now, holders, fleet, operator,
                      planner, objective)
        want = each.min(axis=2)
        assert (np.isfinite(got) == np.isfinite(want)).all(), (now, got, want)
        fin = np.isfinite(want)
        np.testing.assert_allclose(got[fin], want[fin], rtol=0, atol=1e-6)
        for r, c in zip(*np.nonzero(fin)):  # the points handed out are a cheapest pair's
            m = inserts.get((r, c)).meeting
            pts = _points(walks, tasks[c])
            q = [(p[0], p[1]) for p in pts].index((m.board, m.alight))
            assert each[r, c, q] == pytest.approx(want[r, c], abs=1e-6)
            assert (m.earliest, m.latest_drop) == pts[q][2:]
        checked.append(int(fin.sum()))
        return got, inserts, {}

    monkeypatch.setattr(decision, "meeting_costs", spy)
    _trace(tmp_path, seed)
    summary, _ = _tables(_scenario(tmp_path, walk=200.0, objective=objective,
                                   service=service))
    assert summary["tasks_completed"] > 0
    assert sum(checked) > 20  # decisions with feasible pairs, busy plans among them


@pytest.mark.parametrize("seed", [0, 4])
def test_one_point_per_request_equals_a_brute_force(tmp_path, monkeypatch, seed):
    """``rtv``'s meeting points: one pair per request, the cheapest insertion's among the pairs
    whose boarding point the rider reaches before any vehicle of the decision can; every
    vehicle's cost is that pair's exhaustive minimum over positions."""
    checked = []

    def spy(walks, cost, slots, agents, tasks, now, *, holders, fleet, operator, planner,
            objective, one_point):
        assert one_point
        got, inserts, chosen = meeting_costs(walks, cost, slots, agents, tasks, now,
                                             holders=holders, fleet=fleet, operator=operator,
                                             planner=planner, objective=objective,
                                             one_point=True)
        each = _brute(walks, cost, slots, agents, tasks, now, holders, fleet, operator,
                      planner, objective)
        for c, t in enumerate(tasks):
            pts = _points(walks, t)
            soon = [min(float(planner.between([ag.loc], [p[0]])[0, 0]) for ag in agents)
                    for p in pts]
            allowed = [q for q, p in enumerate(pts)
                       if p[2] <= max(now, t.released_at) + soon[q] + 1e-9]
            best = min((each[:, c, q].min() for q in allowed), default=math.inf)
            if not math.isfinite(best):
                assert c not in chosen and not np.isfinite(got[:, c]).any()
                continue
            m = chosen[c]
            q = [(p[0], p[1]) for p in pts].index((m.board, m.alight))
            assert q in allowed and each[:, c, q].min() == pytest.approx(best, abs=1e-6)
            col = each[:, c, q]
            assert (np.isfinite(got[:, c]) == np.isfinite(col)).all()
            np.testing.assert_allclose(got[np.isfinite(col), c], col[np.isfinite(col)],
                                       rtol=0, atol=1e-6)
            checked.append(c)
        return got, inserts, chosen

    monkeypatch.setattr(decision, "meeting_costs", spy)
    _trace(tmp_path, seed)
    summary, tables = _tables(_scenario(tmp_path, walk=200.0, allocator="rtv"))
    assert len(checked) > 10 and summary["walk_mean"] > 0
    _walk_invariants(tables, 200.0)


def _walk_invariants(tables: dict, walk: dict | float) -> None:
    tasks = tables["tasks"].set_index("task_id")
    done = tasks[(tasks.state == "completed") & (tasks.transfers == 0)]
    assert len(done)
    limit = done.index.map(lambda k: walk[k]) if isinstance(walk, dict) else walk
    # boarding never before the rider gets there; walks within the limit
    assert (done.picked_up_at >= done.released_at + done.walk_to_board_m / SPEED - EPS).all()
    assert (done.walk_to_board_m <= limit + EPS).all()
    assert (done.walk_from_alight_m <= limit + EPS).all()
    # the straight line is never longer than the walk
    assert (np.hypot(done.board_x - done.x, done.board_y - done.y)
            <= done.walk_to_board_m + EPS).all()
    assert (np.hypot(done.alight_x - done.dropoff_x, done.alight_y - done.dropoff_y)
            <= done.walk_from_alight_m + EPS).all()
    # the walk from the alighting point counts in max_delay
    ev = tables["events"]
    drop = ev[ev.event == "dropoff"].groupby("task_id").t.max()[done.index]
    arrive = drop + done.walk_from_alight_m / SPEED
    assert (arrive <= done.released_at + done.direct_time + done.max_delay + EPS).all()


@pytest.mark.parametrize("allocator", ["hungarian", "greedy", "fcfs", "auction", "rtv"])
def test_rides_keep_the_walking_limits(tmp_path, allocator):
    _trace(tmp_path, 5, n=20)
    summary, tables = _tables(_scenario(tmp_path, walk=250.0, allocator=allocator))
    check_invariants(summary, tables)
    _walk_invariants(tables, 250.0)
    assert summary["walk_mean"] > 0
    assert summary["meeting_points"] > 0


def test_breakdowns_with_riders_walking(tmp_path):
    """Breakdowns (riders transferred): the invariants hold, the rides not transferred keep
    the walking limits."""
    _trace(tmp_path, 8, n=24)
    summary, tables = _tables(_scenario(tmp_path, walk=250.0, faults=True))
    assert summary["failures"] > 0
    check_invariants(summary, tables)
    _walk_invariants(tables, 250.0)


def test_per_row_max_walk(tmp_path):
    """The trace's ``max_walk`` column: each rider walks within their own limit."""
    _trace(tmp_path, 7, n=20, walk_column=True)
    summary, tables = _tables(_scenario(tmp_path, walk=None))
    with (tmp_path / "trips.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    # task ids follow release order (the trace is sorted by t already)
    limits = {k: float(r["max_walk"]) for k, r in enumerate(rows)}
    _walk_invariants(tables, limits)
    assert summary["meeting_points"] > 0


def test_max_walk_zero_is_door_to_door(tmp_path):
    """``max_walk = 0`` (written out) is the run without the key: no candidate step, the same
    tables, every ride boarding at its pickup."""
    _trace(tmp_path, 3)
    a = _tables(_scenario(tmp_path, walk=None))
    (tmp_path / "b").mkdir()
    _trace(tmp_path / "b", 3)
    b = _tables(_scenario(tmp_path / "b", walk=0.0))
    drop = ["run_id", "alloc_seconds", "cost_seconds", "decide_seconds",
            "first_decision_seconds", "agent_seconds"]
    sa = {k: v for k, v in a[0].items() if k not in drop}
    sb = {k: v for k, v in b[0].items() if k not in drop}
    assert sa.keys() == sb.keys()
    for k in sa:
        assert sa[k] == sb[k] or (sa[k] != sa[k] and sb[k] != sb[k]), k
    assert sa["meeting_points"] == 0 and sa["walk_mean"] == 0.0
    ta, tb = a[1]["tasks"].drop(columns="run_id"), b[1]["tasks"].drop(columns="run_id")
    assert ta.equals(tb)
    done = ta[ta.state == "completed"]
    assert (done.board_x == done.x).all() and (done.alight_y == done.dropoff_y).all()
    assert (done.walk_to_board_m == 0).all() and (done.walk_from_alight_m == 0).all()


def test_candidates_are_bounded_and_within_the_radius():
    net = manhattan(6, 5, block=100.0)
    walks = Walks(net, 3)
    nodes, metres = walks.near(14, 150.0)
    assert nodes[0] == 14 and metres[0] == 0.0
    assert nodes.size == 3 and (metres <= 150.0).all() and (np.diff(metres) >= 0).all()
    assert walks.cut == 2  # 5 nodes within 150 m (itself and 4 neighbours), 3 kept
    nodes, metres = walks.near(14, 0.0)
    assert nodes.tolist() == [14] and metres.tolist() == [0.0]


def test_negative_max_walk_in_the_scenario(tmp_path):
    _trace(tmp_path, 0)
    with pytest.raises(ScenarioError) as e:
        load_scenario(_scenario(tmp_path, walk=-5.0))
    msg = str(e.value)
    assert "\n" not in msg and "road.toml" in msg and "max_walk" in msg


def test_negative_max_walk_in_a_trace_row(tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node", "max_walk"],
              [(0.0, 1, 2, 100.0), (5.0, 3, 4, -20.0)])
    with pytest.raises(ScenarioError) as e:
        load_scenario(_scenario(tmp_path, walk=None))
    msg = str(e.value)
    assert "\n" not in msg and "trips.csv" in msg and "row 2" in msg and "max_walk" in msg


def test_meeting_points_need_a_road_network(tmp_path):
    path = tmp_path / "v.toml"
    path.write_text('name = "v"\n[world]\nsize = [20.0, 20.0, 5.0]\n[fleet]\nagents = 2\n'
                    '[tasks]\nsource = "static"\ncount = 2\nmax_walk = 100.0\n', "utf-8")
    with pytest.raises(ScenarioError, match="max_walk"):
        load_scenario(path)


def test_a_booked_rider_who_walks_boards_after_departure_and_walk(tmp_path):
    # prebooking: a booked ride's released_at is its requested departure; with meeting points
    # its boarding is no earlier than that plus the walk (door to door: the departure)
    _trace(tmp_path, 5, n=30)
    path = _scenario(tmp_path, walk=200.0)
    text = path.read_text().replace("[tasks]\n", "[tasks]\nprebook_share = 0.5\n"
                                    "prebook_lead = 300.0\n", 1)
    path.write_text(text)
    summary, tables = _tables(path)
    t = tables["tasks"]
    booked = t[t.booked_at.notna() & t.picked_up_at.notna()]
    assert len(booked) >= 5 and summary["promises"] >= 5
    assert (booked.walk_to_board_m + booked.walk_from_alight_m > 0).any()  # booked ones walk too
    walk_s = booked.walk_to_board_m / SPEED
    assert (booked.picked_up_at >= booked.released_at + walk_s - EPS).all()

