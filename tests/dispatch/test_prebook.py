"""Prebooking (dispatch.decide.prebook): requests booked ahead are promises that are kept or
counted.

Random runs on a small grid (allocators, both entry modes, breakdowns that transfer or fail
riders) checked from the tables alone: every promise ends completed, or failed after a
breakdown of a vehicle that held it; no booked rider is picked up before the requested
departure; booked and immediate requests ride in the same vehicles, and a vehicle holding a
promise serves an immediate request before it. Without bookings nothing changes; generated
demand books its seeded share; a booking after the departure is one clear error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dispatch.errors import ScenarioError
from dispatch.output.parquet import TIMING_COLUMNS
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

EPS = 1e-6


def _trace(directory: Path, seed: int, n: int = 24, share: float = 0.5,
           lead: tuple[float, float] = (60.0, 900.0)) -> None:
    """A trace of ``n`` trips on the 6 x 5 grid, ``share`` of them booked a random lead
    ahead (blank ``booked_at`` for the others)."""
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(20.0))
        o, d = rng.choice(30, size=2, replace=False)
        booked = round(max(t - float(rng.uniform(*lead)), 0.0), 3) \
            if rng.random() < share else ""
        rows.append((round(t, 3), int(o), int(d), booked))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "booked_at"], rows)


def _run(path: Path):
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


def _scenario(directory: Path, *, allocator: str = "hungarian", mode: str = "at_booking",
              faults: str = "", capacity: int = 1, agents: int = 3, tasks: str = "",
              duration: float = 1e5) -> Path:
    tasks = tasks or 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0'
    extra = f'prebook = "{mode}"\nprebook_lead = 120.0' + faults
    return road_scenario(directory, tasks=tasks, fleet=f"agents = {agents}\n"
                         f"capacity = {capacity}", allocator=allocator, extra=extra,
                         duration=duration)


def check_promises(summary: dict, tables: dict) -> None:
    """Every promise completed, or failed after a breakdown of a vehicle that held it; no
    booked pickup before its requested departure; the summary's counts are the table's."""
    tasks = tables["tasks"].set_index("task_id")
    ev = tables["events"]
    booked = tasks[tasks.booked_at.notna()]
    assert (booked.booked_at <= booked.released_at + EPS).all()
    assert not tasks[tasks.booked_at.isna()].promised.any()
    promised = booked[booked.promised]
    holders = ev[ev.event.isin(["assign", "insert"])].groupby("task_id").agent_id.agg(set)
    broke = ev[ev.event == "breakdown"]
    end = summary["sim_time"]
    for k, t in promised.iterrows():
        if t.state == "completed" or (t.state == "cut_off" and t.closed_at == end):
            continue  # (cut_off: cut by the run's end)
        assert t.state == "failed", (k, t.state)
        # a fault named: a breakdown of a vehicle that held the promise, before it ended
        named = broke[broke.agent_id.isin(holders[k]) & (broke.t <= t.closed_at + EPS)]
        assert len(named), (k, holders[k])
    # no booked rider picked up before the requested departure (the events say when)
    pick = ev[ev.event == "pickup"].groupby("task_id").t.min()
    got = pick.reindex(booked.index).dropna()
    assert (got >= booked.released_at.reindex(got.index) - EPS).all()
    assert summary["promises"] == len(promised)
    assert summary["promises_broken"] == int((~promised.state.isin(["completed", "cut_off"])
                                              ).sum())


@pytest.mark.parametrize("allocator,mode,faults,capacity", [
    ("hungarian", "at_booking", "", 1), ("hungarian", "lead", "transfer", 1),
    ("hungarian", "at_booking", "fail", 3), ("greedy", "at_booking", "transfer", 1),
    ("greedy", "lead", "", 3), ("fcfs", "at_booking", "transfer", 3),
    ("fcfs", "lead", "fail", 1), ("hungarian", "lead", "", 3)])
def test_a_promise_is_never_silently_dropped(tmp_path, allocator, mode, faults, capacity):
    seed = len(allocator) * 7 + len(mode) + len(faults) * 3 + capacity
    _trace(tmp_path, seed)
    f = "" if not faults else \
        f'\n\n[faults]\nrate = 3.0\nrepair = 200.0\non_board = "{faults}"'
    summary, tables = _run(_scenario(tmp_path, allocator=allocator, mode=mode, faults=f,
                                     capacity=capacity))
    check_promises(summary, tables)
    tasks = tables["tasks"]
    assert summary["promises"] > 0
    if not faults:  # nothing breaks a promise
        assert summary["promises_broken"] == 0
        assert (tasks[tasks.promised].state == "completed").all()


def test_faults_break_promises_and_they_are_counted(tmp_path):
    """Many breakdowns, riders failed on board: some promises break, each one counted."""
    _trace(tmp_path, 5, n=40, share=0.8)
    f = '\n\n[faults]\nrate = 20.0\nrepair = 2000.0\non_board = "fail"'
    summary, tables = _run(_scenario(tmp_path, faults=f, agents=3))
    check_promises(summary, tables)
    assert summary["promises_broken"] > 0


def test_booked_and_immediate_requests_share_vehicles(tmp_path):
    """Over a busy trace some vehicle serves booked and immediate requests alike."""
    _trace(tmp_path, 11, n=30)
    summary, tables = _run(_scenario(tmp_path, agents=2))
    check_promises(summary, tables)
    t = tables["tasks"]
    done = t[t.state == "completed"]
    kinds = done.groupby("agent_id").booked_at.agg(lambda b: (b.notna().any(), b.isna().any()))
    assert any(a and b for a, b in kinds), kinds


def test_a_vehicle_holding_a_promise_serves_a_request_before_it(tmp_path):
    """One taxi: a ride booked at 0 for 1000 s from node 0, a request at 10 s from node 29.
    The taxi takes the promise first, then serves the immediate ride before it, and picks
    the booked rider up at 1000 s, not sooner."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node", "booked_at"],
              [(1000.0, 0, 5, 0.0), (10.0, 29, 24, "")])
    summary, tables = _run(_scenario(tmp_path, agents=1))
    t = tables["tasks"].set_index("task_id")
    assert (t.state == "completed").all()
    booked = t[t.booked_at.notna()].iloc[0]
    now = t[t.booked_at.isna()].iloc[0]
    assert booked.promised and booked.assigned_at == 0.0
    assert booked.agent_id == now.agent_id
    assert now.completed_at <= booked.picked_up_at
    assert booked.picked_up_at == pytest.approx(1000.0)
    assert summary["promises"] == 1 and summary["promises_broken"] == 0


def _comparable(tables: dict, summary: dict):
    out = {n: t.drop(columns=[c for c in t.columns if c in TIMING_COLUMNS])
           for n, t in tables.items()}
    return out, {k: v for k, v in summary.items() if k not in TIMING_COLUMNS
                 and k != "allocator_info"}


def test_without_bookings_results_are_unchanged(tmp_path):
    """A trace without a booked_at column, with a blank one, and with prebook_share = 0: the
    same run, value for value."""
    rng = np.random.default_rng(3)
    rows, t = [], 0.0
    for _ in range(25):
        t += float(rng.exponential(15.0))
        o, d = rng.choice(30, size=2, replace=False)
        rows.append((round(t, 3), int(o), int(d)))
    runs = []
    for k, (header, extra, tasks_extra) in enumerate((
            (["t", "origin_node", "dest_node"], "", ""),
            (["t", "origin_node", "dest_node", "booked_at"], "", ""),
            (["t", "origin_node", "dest_node"], "", "\nprebook_share = 0.0"))):
        d = tmp_path / str(k)
        d.mkdir()
        write_csv(d / "trips.csv", header, [r + ("",) * (len(header) - 3) for r in rows])
        path = road_scenario(d, tasks='source = "trace"\ntrace = "trips.csv"\nmax_wait = 200.0'
                             + tasks_extra, allocator="hungarian")
        summary, tables = _run(path)
        assert summary["promises"] == 0 and tables["tasks"].booked_at.isna().all()
        runs.append(_comparable(tables, summary))
    for tables, summary in runs[1:]:
        assert summary == runs[0][1]
        for n, t in tables.items():
            assert t.equals(runs[0][0][n]), n


@pytest.mark.parametrize("mode", ["at_booking", "lead"])
def test_generated_demand_books_its_share(tmp_path, mode):
    """Poisson demand with prebook_share = 0.5 books about half its requests, each
    prebook_lead seconds ahead; the same seed, the same bookings."""
    tasks = ('source = "poisson"\nrate = 0.05\ncount = 60\nmax_wait = 300.0\n'
             'prebook_share = 0.5\nprebook_lead = 600.0')
    path = _scenario(tmp_path, tasks=tasks, mode=mode)
    summary, tables = _run(path)
    check_promises(summary, tables)
    t = tables["tasks"]
    booked = t[t.booked_at.notna()]
    assert len(t) == 60 and 15 <= len(booked) <= 45
    assert np.allclose(booked.released_at - booked.booked_at, 600.0)
    again = _run(path)[1]["tasks"]
    assert again.booked_at.equals(t.booked_at)


def test_a_trace_share_is_synthesised_from_the_seed(tmp_path):
    """A trace without booked_at and prebook_share: the share booked prebook_lead ahead."""
    _trace(tmp_path, 2, n=40, share=0.0)
    tasks = ('source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0\n'
             'prebook_share = 0.5\nprebook_lead = 300.0')
    summary, tables = _run(_scenario(tmp_path, tasks=tasks))
    check_promises(summary, tables)
    b = tables["tasks"].dropna(subset=["booked_at"])
    assert 8 <= len(b) <= 32
    assert np.allclose(b.released_at - b.booked_at, np.minimum(300.0, b.released_at))


@pytest.mark.parametrize("header,row,bad", [
    (["t", "origin_node", "dest_node", "booked_at"], (50.0, 1, 2, 60.0), "booked_at = 60"),
    (["departure_time", "origin_node", "dest_node", "booked_at"],
     ("2014-12-21 00:01:00", 1, 2, "2014-12-21 00:02:00"), "booked_at = 120"),
    (["departure_time", "origin_node", "dest_node", "booked_at"],
     ("2014-12-21 00:01:00", 1, 2, "soon"), "booked_at 'soon' is not a date-time"),
])
def test_a_booking_after_departure_is_one_clear_error(tmp_path, header, row, bad):
    ok = (10.0, 3, 4, "") if header[0] == "t" else ("2014-12-21 00:00:10", 3, 4, "")
    write_csv(tmp_path / "trips.csv", header, [ok, ok, row])
    tasks = 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0'
    if header[0] == "departure_time":
        tasks += '\nstart = "2014-12-21T00:00"'
    path = road_scenario(tmp_path, tasks=tasks)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert "\n" not in msg
    assert "trips.csv" in msg and "row 3" in msg and bad in msg, msg


def test_prebooking_needs_a_road_network_and_no_reassign(tmp_path):
    voxel = tmp_path / "v.toml"
    voxel.write_text('name = "v"\n[world]\nsize = [20, 20, 4]\n[tasks]\nsource = "poisson"\n'
                     'rate = 0.1\nprebook_share = 0.5\n', encoding="utf-8")
    with pytest.raises(ScenarioError, match="prebook_share: prebooking needs a road network"):
        load_scenario(voxel)
    _trace(tmp_path, 1)
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         extra="reassign = true")
    with pytest.raises(ScenarioError, match="reassign"):
        load_scenario(path)
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"\n'
                                         'prebook_share = 0.3')
    with pytest.raises(ScenarioError, match="booked_at column"):
        load_scenario(path)
    path = road_scenario(tmp_path, tasks='source = "poisson"\nrate = 0.1\nprebook_share = 1.5')
    with pytest.raises(ScenarioError, match="prebook_share"):
        load_scenario(path)


@pytest.mark.parametrize("mode,faults,capacity,reorder", [
    ("at_booking", "", 2, False), ("lead", "", 3, True), ("at_booking", "transfer", 3, False),
    ("lead", "fail", 2, True)])
def test_rtv_keeps_every_promise(tmp_path, mode, faults, capacity, reorder):
    """``rtv`` routes its groups itself, each booked pickup waiting for its requested
    departure: no booked rider picked up early, every promise kept or its fault named, and
    its groups pool booked and immediate requests."""
    _trace(tmp_path, 4 + capacity + len(faults), n=40, share=0.6)
    f = "" if not faults else \
        f'\n\n[faults]\nrate = 3.0\nrepair = 200.0\non_board = "{faults}"'
    if reorder:
        f += '\n\n[dispatch.allocator_params.rtv]\nreorder = true'
    summary, tables = _run(_scenario(tmp_path, allocator="rtv", mode=mode, faults=f,
                                     capacity=capacity, agents=2))
    check_promises(summary, tables)
    assert summary["promises"] > 0
    tasks = tables["tasks"]
    if not faults:
        assert summary["promises_broken"] == 0
        assert (tasks[tasks.promised].state == "completed").all()
    done = tasks[tasks.state == "completed"]
    both = done.groupby("agent_id").booked_at.agg(lambda b: b.notna().any() and b.isna().any())
    assert both.any()


def test_lead_mode_enters_a_booking_its_lead_before_departure(tmp_path):
    """prebook = "lead", prebook_lead = 120 s: a ride booked at 0 for 1000 s is first offered
    (and accepted) at 880 s, and still picked up at 1000 s, not sooner."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node", "booked_at"],
              [(1000.0, 0, 5, 0.0)])
    summary, tables = _run(_scenario(tmp_path, agents=1, mode="lead"))
    t = tables["tasks"].iloc[0]
    assert t.state == "completed" and t.promised
    assert t.assigned_at == pytest.approx(880.0)
    assert t.picked_up_at == pytest.approx(1000.0)
    ev = tables["events"]
    assert ev[ev.event == "release"].t.iloc[0] == pytest.approx(880.0)


@pytest.mark.parametrize("allocator,capacity", [("hungarian", 1), ("hungarian", 3), ("rtv", 3)])
def test_walking_riders_booked_ahead_board_no_sooner(tmp_path, allocator, capacity):
    """Meeting points and bookings together: a booked rider boarding at the origin itself (no
    walk) still boards no sooner than the requested departure, as at any other point."""
    _trace(tmp_path, 3, n=40, share=0.6)
    tasks = 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0\nmax_walk = 150.0'
    summary, tables = _run(_scenario(tmp_path, allocator=allocator, capacity=capacity,
                                     tasks=tasks, agents=2))
    check_promises(summary, tables)
    t = tables["tasks"]
    assert t[t.booked_at.notna()].picked_up_at.notna().sum() > 0


@pytest.mark.parametrize("capacity", [1, 3])
def test_an_offer_to_a_booked_rider_estimates_the_pickup_at_its_departure(tmp_path,
                                                                         monkeypatch, capacity):
    """A booked rider offered a ride (an acceptor that may decline) is told a pickup no sooner
    than the requested departure, as the plan will pick up: the estimate of a vehicle setting
    out follows the schedule rule's earliest time, as the insertion's and a route's do."""
    from dispatch.decide.offer_step import Offering

    seen = []
    real = Offering.offer

    def offer(self, task, vehicle_id, now, estimates):
        seen.append((task.earliest_pickup, now, estimates[0]))
        return real(self, task, vehicle_id, now, estimates)

    monkeypatch.setattr(Offering, "offer", offer)
    _trace(tmp_path, 5, share=1.0, lead=(600.0, 900.0))
    path = _scenario(tmp_path, capacity=capacity)
    path.write_text(path.read_text() + '\n[acceptor]\nname = "threshold"\n'
                    '[acceptor.threshold]\nmax_wait = 1e9\n', encoding="utf-8")
    summary, tables = _run(path)
    booked = [(e, now, at) for e, now, at in seen if e > now]  # offered before departure
    assert len(booked) >= 3, seen
    assert all(at >= e - EPS for e, _, at in booked), [x for x in booked if x[2] < x[0]]
    check_promises(summary, tables)
