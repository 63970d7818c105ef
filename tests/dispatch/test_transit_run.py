"""A run with ``[transit]`` (dispatch.decide.riders): riders' legs in time order, each rider one
terminal state, train legs consistent with the feed (checked from ``legs.parquet``), fleet legs
kept in the tasks table under the rider's request id, and a feeder that lets its rider off
after the chosen departure re-plans the rest of the trip, never boarding a departed train."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import simpy
from scipy.sparse.csgraph import dijkstra

from dispatch.api.mode_choice import ModeChoice, Weights
from dispatch.api.space import space_for
from dispatch.decide.rider_legs import LEG_COLUMNS, Transit, seconds_of_day
from dispatch.decide.riders import Riders, summary_names
from dispatch.errors import ScenarioError
from dispatch.events import EventBus
from dispatch.plan.demand import demand_for
from dispatch.plan.tasks import TaskBook, TaskState
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "nyc_manhattan_transit.toml"
WINDOW = [("tasks.start", '"2014-12-21T17:00"', "--set"), ("tasks.count", "120", "--set"),
          ("fleet.agents", "40", "--set"), ("duration", "3600.0", "--set"),
          ("transit.mode_choice", '"logit"', "--set")]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The shipped scenario cut to 120 requests from 17:00, riders choosing by logit (so
    every kind of trip occurs), with its scenario, legs, tasks and summary."""
    sc = load_scenario(SCENARIO, overrides=WINDOW)
    [spec] = sc.runs()
    r = run_one(spec, tmp_path_factory.mktemp("transit"))
    legs = pq.read_table(r.files["legs"]).to_pandas()
    return sc, r, legs, r.tables["tasks"].to_pandas(), r.summary


def _goals(sc):
    """Per request id: its door's and goal's street nodes as the run made them."""
    space = space_for(sc.world, 0, sc.path)
    trips = sc.tasks.trips.take(np.arange(120))
    reqs = demand_for(space, sc.tasks, np.random.default_rng(0)).from_trace(trips)
    return space, {rid: next(reqs) for rid in trips.ids.tolist()}


def test_the_legs_table_and_summary_columns(run):
    _sc, r, legs, _tasks, s = run
    assert tuple(legs.columns) == ("run_id", *LEG_COLUMNS)
    assert set(summary_names()) <= set(s) and set(summary_names()) <= set(
        r.tables["summary"].column_names)
    assert s["riders"] == 120
    shares = [s[f"mode_share_{k}"] for k in ("fleet", "fleet_train", "train_fleet", "train")]
    assert math.isclose(sum(shares), 1.0) and all(x > 0 for x in shares)
    assert set(legs["mode"]) == {"fleet", "train", "walk"}
    km = r.tables["vehicles"].column("distance").to_numpy().sum() / 1000.0
    assert math.isclose(s["vehicle_km_per_rider"], km / s["riders_served"])


def test_every_leg_in_time_order_and_each_rider_one_terminal_state(run):
    """Legs numbered 0, 1, ... in time order, each starting where and when the one before
    ended; a served rider's last leg ends at their goal; a rider not served has a fleet
    request that ended otherwise, and no rider is both."""
    sc, _r, legs, tasks, s = run
    space, reqs = _goals(sc)
    served = set()
    for rid, g in legs.sort_values(["request_id", "leg"]).groupby("request_id"):
        assert list(g["leg"]) == list(range(len(g)))
        assert (g["end"] >= g["start"] - 1e-9).all()
        assert (g["start"].to_numpy()[1:] >= g["end"].to_numpy()[:-1] - 1e-6).all()
        assert np.allclose(g[["from_x", "from_y"]].to_numpy()[1:],
                           g[["to_x", "to_y"]].to_numpy()[:-1])
        goal = space.position(reqs[rid].dropoff)
        if np.allclose(g[["to_x", "to_y"]].to_numpy()[-1], goal[:2]):
            served.add(rid)
    failed = set(tasks.loc[tasks.state != "completed", "request_id"])
    assert not served & failed
    assert len(served) == s["riders_served"]
    assert len(served) + len(failed) == s["riders"] == len(reqs)
    # the fleet legs are the tasks' completed rides, under the rider's request id
    fleet = legs[legs["mode"] == "fleet"].set_index("request_id")
    done = tasks[tasks.state == "completed"].set_index("request_id")
    assert sorted(fleet.index) == sorted(done.index)
    assert (fleet.loc[done.index, "agent_id"] == done["agent_id"]).all()


def test_every_train_leg_is_consistent_with_the_feed(run):
    """Each train leg boards its trip at a call of the feed at the call's departure, no
    earlier than the rider reached the station, and leaves it at a later call of the same
    trip at that call's scheduled arrival (the feed's clock: the run's plus [tasks] start's
    time of day)."""
    sc, _r, legs, _tasks, _s = run
    tt = Transit(sc.transit, space_for(sc.world, 0, sc.path), 0.0).tt
    feed, offset = tt.feed, seconds_of_day(sc.tasks.start)
    station = np.where(feed.stop_parent >= 0, feed.stop_parent, np.arange(feed.stop_parent.size))
    calls = defaultdict(list)
    for t, st, a, d in zip(feed.call_trip, feed.call_stop, feed.call_arrival,
                           feed.call_departure):
        calls[str(feed.trip_ids[t])].append((str(feed.stop_ids[station[st]]), a, d))
    trains = 0
    for _rid, g in legs.sort_values(["request_id", "leg"]).groupby("request_id"):
        prev_end = -math.inf
        for leg in g.itertuples():
            if leg.mode == "train":
                trains += 1
                assert leg.start >= prev_end - 1e-6
                seq = calls[leg.trip_id]
                i = next(k for k, c in enumerate(seq) if c[0] == leg.from_stop_id
                         and math.isclose(c[2], leg.start + offset))
                assert any(c[0] == leg.to_stop_id and math.isclose(c[1], leg.end + offset)
                           for c in seq[i + 1:])
            else:
                assert leg.trip_id != leg.trip_id and leg.route_id != leg.route_id  # (nulls)
            assert (leg.mode == "fleet") == (leg.agent_id == leg.agent_id)
            prev_end = leg.end
    assert trains > 0


class _Pick(ModeChoice):
    """Takes the option of one kind (a test's rider)."""

    name = "pick"

    def __init__(self, kind: str) -> None:
        self.kind = kind

    def choose(self, options, weights, rng) -> int:
        return next(i for i, o in enumerate(options) if o.kind == self.kind)


class _Source:
    """What :meth:`Riders.start` needs of a task source: the clock, the book, ``leg``."""

    def __init__(self, env, book) -> None:
        self.env, self.book = env, book

    def leg(self, req, booking=None):
        return self.book.release(req.kind, req.loc, req.dropoff, max_wait=300.0,
                                 max_delay=600.0, request_id=req.request_id)


@pytest.fixture(scope="module")
def feeder():
    """A rider at 17:00 whose options include the fleet to a station and the train."""
    sc = load_scenario(SCENARIO, overrides=WINDOW)
    space, reqs = _goals(sc)
    transit = Transit(sc.transit, space, seconds_of_day(sc.tasks.start))
    time = space.time

    def between(u, v):
        return float(dijkstra(time, indices=int(u), min_only=True)[int(v)])

    rows = []
    riders = Riders(transit, _Pick("fleet+train"), Weights(1, 2, 2, 2, 300),
                    np.random.default_rng(0), between=between, limits=(300.0, 600.0),
                    on_leg=rows.append)
    for req in reqs.values():
        if any(o.kind == "fleet+train" for o, _ in transit.options(
                0.0, req.loc, req.dropoff, riders.estimate)):
            return riders, req, rows
    pytest.skip("no request with a feeder option")


@pytest.mark.parametrize("late", [False, True])
def test_a_feeder_after_the_departure_re_plans_the_trip(feeder, late):
    riders, req, rows = feeder
    rows.clear()
    riders.missed = 0
    env = simpy.Environment()
    book = TaskBook(env, EventBus())
    task = riders.start(req, _Source(env, book))
    trip = riders._by_task[task.id]
    assert trip.kind == "fleet+train" and task.dropoff != req.dropoff
    node, walk = riders.transit.street(trip.station)
    assert task.dropoff == node
    # the feeder's latest drop-off makes the train (the schedule rule's deadline)
    assert task.dropoff_deadline + walk <= trip.departure + 1e-6
    book.assign(task, 7, 0.0)
    book.picked_up(task)
    task.dropped_at = trip.departure - walk + (90.0 if late else -30.0)
    book.close(task, TaskState.COMPLETED)
    riders.closed(task)
    assert riders.missed == int(late)
    modes = [r[2] for r in rows]
    assert modes[:2] == ["fleet", "walk"] and rows[0][-1] == 7
    ready = rows[1][4]
    trains = [r for r in rows if r[2] == "train"]
    first = trip.rest[0]
    if late:
        assert ready > trip.departure
        assert all(r[3] >= ready for r in trains)  # no train boarded before the rider came
        assert (first.trip_id, first.start) not in {(r[12], r[3]) for r in trains}
    else:
        assert trains and (trains[0][12], trains[0][3]) == (first.trip_id, first.start)
    assert [r[1] for r in rows] == list(range(len(rows)))
    assert all(b[3] >= a[4] - 1e-6 for a, b in zip(rows, rows[1:]))
    with pytest.raises(RuntimeError, match="ended twice"):
        riders._end(trip, "completed")


def test_transit_with_booked_requests_is_refused(tmp_path):
    text = SCENARIO.read_text().replace("max_wait = 300.0", "max_wait = 300.0\nprebook_share = 0.5")
    p = tmp_path / "s.toml"
    p.write_text(text)
    [spec] = load_scenario(p, overrides=WINDOW).runs()
    with pytest.raises(ScenarioError, match=r"transit: riders who book ahead"):
        run_one(spec)


def test_the_soak_invariants_hold_for_a_transit_run(run, tmp_path):
    """The soak's checks from the tables alone (its legs_in_order among them) find nothing
    (but ``reachable``, which reads street speeds of the soak's own grid, 10 m/s, where
    Manhattan's OSM streets allow more)."""
    import tomllib

    from soak.invariants import check, read_tables

    _sc, r, _legs, _tasks, _s = run
    tables = read_tables(r.out)
    assert "legs" in tables
    doc = tomllib.loads(SCENARIO.read_text())
    assert [v for v in check(doc, tables) if v[0] != "reachable"] == []
    # and it sees a leg out of time order, and a fleet leg that is no ride of the rider
    bad = tables["legs"].copy()
    k = bad.index[bad["leg"] == 1][0]
    bad.loc[k, "start"] = bad.loc[k, "start"] - 1e5
    f = bad.index[bad["mode"] == "fleet"][0]
    bad.loc[f, "agent_id"] = -5
    found = {m for n, m in check(doc, {**tables, "legs": bad}) if n == "legs_in_order"}
    assert any("out of time order" in m for m in found)
    assert any("no completed ride" in m for m in found)
