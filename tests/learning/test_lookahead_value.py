"""The value of a vehicle's post-decision state (dispatch.api.value, learning.value,
learning.value_train): TD targets of a hand-computed chain, a value of zero deciding exactly as
no value in every allocator (and repositioner) that takes one, one seed one file, a value of
another network refused, value paths read next to the scenario file."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dispatch.api.value import NetworkMismatch, ZeroValue, network_key, value_costs
from dispatch.output.parquet import TIMING_COLUMNS
from learning.value import ZoneValue
from learning.value_train import pooled_transitions, scenario_for, td_learn, train
from learning.zones import Zones
from tests.dispatch.test_determinism import bitwise

ROOT = Path(__file__).resolve().parents[2]
MANHATTAN = ROOT / "scenarios" / "manhattan.toml"
HALF_HOUR = 0.5 ** (1 / 1800)


# ------------------------------------------------------------------ TD on a hand-made chain
def test_pooled_td_targets_match_a_hand_computed_chain():
    """Two zones (nodes 0 and 1, 1 km apart), one 2-seat vehicle starting in zone 0. It takes
    request a at t=0 (to zone 1, done at 600) and, while carrying it, request b at t=100 (to
    zone 0, done at 900); after that nothing until the day ends at 3600."""
    zones = Zones(np.array([[0.0, 0.0], [1000.0, 0.0]]), 500.0)
    tasks = pd.DataFrame({
        "task_id": [1, 2], "agent_id": [7, 7], "state": ["completed", "completed"],
        "assigned_at": [0.0, 100.0], "completed_at": [600.0, 900.0], "passengers": [1, 1],
        "dropoff_x": [1000.0, 0.0], "dropoff_y": [0.0, 0.0]})
    vehicles = pd.DataFrame({"agent_id": [7], "x0": [0.0], "y0": [0.0]})
    tr = pooled_transitions(tasks, vehicles, zones, 3600.0, capacity=2)
    S = 3  # seat classes 0, 1, 2
    # start (zone 0, 2 free) -> after a: plan ends in zone 1 at 600, 1 seat free (a held)
    # -> after b: ends in zone 0 at 900 (b completes last), 0 free (a and b held)
    # -> terminal at the day's end
    assert tr["z"].tolist() == [0 * S + 2, 1 * S + 1, 0 * S + 0]
    assert tr["z2"].tolist() == [1 * S + 1, 0 * S + 0, -1]
    assert tr["t"].tolist() == [0.0, 600.0, 900.0]
    assert tr["t2"].tolist() == [600.0, 900.0, 3600.0]
    assert tr["r"].tolist() == [1.0, 1.0, 0.0]
    table, _ = td_learn(tr, zones.n * S, 1, 3600.0, gamma=HALF_HOUR, shrink=0.0)
    # by hand: V(end) = 0; V(after b) = 0; V(after a) = 1 + 0; V(start) = 1 + g^600 * 1
    assert table[0 * S + 0, 0] == pytest.approx(0.0)
    assert table[1 * S + 1, 0] == pytest.approx(1.0)
    assert table[0 * S + 2, 0] == pytest.approx(1.0 + 0.5 ** (600 / 1800))
    # the value answers by node, time and seats left
    v = ZoneValue(zones, zones.centres, 3600.0, table, HALF_HOUR, 100.0,
                  np.tile([0.0, 0.1], (24, 1)), {}, seats=S)
    assert v.value(np.array([1]), np.array([10.0]), np.array([1]))[0] == pytest.approx(1.0)
    assert v.value(np.array([0]), np.array([10.0]))[0] == pytest.approx(table[2, 0])  # all free
    assert v.value(np.array([0]), np.array([4000.0]))[0] == 0.0  # past the last bin


# ------------------------------------------------------------------ zero value == myopic
def _zero_file(tmp_path: Path, sc, seats: int = 1) -> Path:
    from dispatch.api.space import space_for

    xy = np.asarray(space_for(sc.world, 0, sc.path).node_positions, float)[:, :2]
    zones = Zones(xy, 1000.0)
    v = ZoneValue(zones, xy, 3600.0, np.zeros((zones.n * seats, 2)), HALF_HOUR, 300.0,
                  np.tile([30.0, 0.1], (24, 1)), {"scenario": "manhattan.toml"}, seats)
    out = tmp_path / f"zero{seats}.npz"
    v.save(out)
    return out


def _tables(sc, allocator, params, reposition=None, reposition_params=()):
    from dispatch.run.runner import run_one

    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=tuple(params.items())))
    if reposition is not None:
        sc = replace(sc, reposition=replace(sc.reposition, policy=reposition, declared=True,
                                            params=((reposition, reposition_params),)))
    res = run_one(sc.runs(allocator=allocator, agents=25, seed=3)[0])
    out = {}
    for name, t in res.tables.items():
        drop = [c for c in t.column_names if c in TIMING_COLUMNS or c == "allocator_info"]
        # floats as their bit patterns: byte for byte, NaN ("never") equal to NaN
        out[name] = bitwise(t.drop_columns(drop).replace_schema_metadata(None))
    return out, res.summary


SETUPS = {  # (allocator, seats, objective, repositioner)
    "hungarian": ("hungarian", 1, "pickup_time", None),
    "local_hungarian": ("local_hungarian", 1, "pickup_time", None),
    "hungarian_pooled_insertion": ("hungarian", 3, "added_time", None),
    "rtv": ("rtv", 3, "pickup_time", None),
    "demand": ("hungarian", 1, "pickup_time", "demand"),
}


@pytest.mark.parametrize("setup", sorted(SETUPS))
def test_a_zero_value_decides_exactly_as_no_value(tmp_path, setup):
    allocator, seats, objective, repo = SETUPS[setup]
    sc = scenario_for(MANHATTAN, 30.0, hours=0.4, capacity=seats)
    sc = replace(sc, dispatch=replace(sc.dispatch, objective=objective))
    zero = str(_zero_file(tmp_path, sc, seats + 1 if seats > 1 else 1))
    if repo is None:
        plain, s0 = _tables(sc, allocator, {})
        zeroed, s1 = _tables(sc, allocator, {"value": zero})
    else:
        plain, s0 = _tables(sc, allocator, {}, repo)
        zeroed, s1 = _tables(sc, allocator, {}, repo, (("value", zero),))
    assert s0["tasks_completed"] > 0
    for name in plain:
        assert plain[name].equals(zeroed[name]), f"{setup}: table {name} differs"


def test_a_nonzero_value_changes_decisions_and_zero_weight_does_not():
    """The same formula answers through the protocol for any ValueFunction: ZeroValue leaves
    the costs as they are (the same array), a value that favours node 1 lowers the pairs
    whose trips end there by weight x the discounted value."""
    from allocators.hungarian import HungarianAllocator
    from tests.learning.test_value import _problem, _value

    p = _problem([[100.0, 90.0]])
    assert value_costs(p, ZeroValue()) is p.cost
    assert value_costs(p, ZeroValue(), 500.0).tolist() == p.cost.tolist()
    v = _value(weight=100.0)
    adj = value_costs(p, v)
    trip = float(v.trip_seconds(np.array([0]), np.array([1]), 0.0)[0])
    assert adj[0, 0] == pytest.approx(100.0 - 100.0 * 3.0 * 0.5 ** ((100.0 + trip) / 3600))
    assert adj[0, 1] == 90.0
    assert value_costs(p, v, 0.0) is p.cost
    assert HungarianAllocator().allocate(p).pairs == ((10, 2),)


# ------------------------------------------------------------------ one seed, one file
@pytest.mark.parametrize("allocator,capacity", [("hungarian", None), ("rtv", 2)])
def test_training_twice_with_one_seed_writes_the_same_file(tmp_path, allocator, capacity):
    kw = dict(agents=20, seeds=(100,), zone=1000.0, hours=0.25, allocator=allocator,
              capacity=capacity, log=lambda s: None)
    a = train(MANHATTAN, tmp_path / "a.npz", **kw)
    b = train(MANHATTAN, tmp_path / "b.npz", **kw)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    assert a.meta["seeds"] == [100] and a.meta["allocator"] == allocator
    assert a.seats == (1 if capacity is None else capacity + 1)
    assert a.table.max() > 0 and np.array_equal(a.table, b.table)
    got = ZoneValue.load(tmp_path / "a.npz")
    assert got.network == a.network == network_key(a.node_xy)
    assert [d["seed"] for d in a.meta["days"]] == [100]


# ------------------------------------------------------------------ another network
def test_a_value_of_another_network_is_refused_in_one_line(tmp_path):
    from tests.learning.test_value import _value

    other = _value()  # learned on a three-node network
    other.meta["scenario"] = "tiny.toml"
    other.save(tmp_path / "other.npz")
    sc = scenario_for(MANHATTAN, 30.0, hours=0.2)
    with pytest.raises(Exception) as err:
        _tables(sc, "hungarian", {"value": str(tmp_path / "other.npz")})
    text = str(err.value)
    assert "another road network" in text and "\n" not in text.strip()
    # and the check itself, on a problem whose pickups lie elsewhere
    from tests.learning.test_value import _problem

    p = _problem([[100.0, 90.0]])
    moved = replace(p, task_pos=np.full((2, 3), 777.0))
    v = ZoneValue.load(tmp_path / "other.npz")
    with pytest.raises(NetworkMismatch, match="another road network"):
        v.adjusted(moved)


def test_a_value_path_is_read_next_to_the_scenario_file(tmp_path):
    from dispatch.scenario.load import load_scenario

    text = MANHATTAN.read_text().replace('start = "data/', f'start = "{ROOT}/scenarios/data/') \
        .replace('trace = "data/', f'trace = "{ROOT}/scenarios/data/')
    text = text.replace('planner = "dijkstra"', 'planner = "dijkstra"\n'
                        'allocator_params = { value = "values/v.npz" }')
    (tmp_path / "values").mkdir()
    (tmp_path / "sc.toml").write_text(text)
    sc = load_scenario(tmp_path / "sc.toml")
    assert dict(sc.dispatch.allocator_params)["value"] == str(tmp_path / "values" / "v.npz")


@pytest.mark.parametrize("setup", sorted(SETUPS))
def test_a_value_that_is_not_zero_changes_what_is_decided(tmp_path, setup):
    """The same runs with a value of random numbers (seeded): some decision differs, so the
    zero-value identity above is not that the value is never asked."""
    allocator, seats, objective, repo = SETUPS[setup]
    sc = scenario_for(MANHATTAN, 30.0, hours=0.4, capacity=seats)
    sc = replace(sc, dispatch=replace(sc.dispatch, objective=objective))
    path = _zero_file(tmp_path, sc, seats + 1 if seats > 1 else 1)
    v = ZoneValue.load(path)
    v.table = np.random.default_rng(5).uniform(0.0, 3.0, v.table.shape)
    v.save(path)
    if repo is None:
        plain, _ = _tables(sc, allocator, {})
        valued, _ = _tables(sc, allocator, {"value": str(path)})
    else:
        plain, _ = _tables(sc, allocator, {}, repo)
        valued, _ = _tables(sc, allocator, {}, repo, (("value", str(path)),))
    assert not plain["events"].equals(valued["events"])


def test_the_pooled_post_decision_states_are_the_plans_ends(tmp_path, monkeypatch):
    """Every pair's post-decision state in a pooled run (capacity 3, added time): an empty
    vehicle's plan ends at the request's drop-off ``cost`` seconds from now (the added time
    of an empty plan is its whole trip); a busy one's ends at the drop-off or at its plan's
    last stop, no earlier than that stop; free seats within [0, seats - passengers]."""
    import dispatch.api.value as api

    seen = []
    real = api.post_decision

    def spy(problem, value):
        got = real(problem, value)
        # the plans as the decision sees them (the mapping reads the vehicles when asked)
        plans = {aid: problem.plans.get(aid, ()) for aid in problem.agent_ids.tolist()}
        seen.append((problem, plans, got))
        return got

    monkeypatch.setattr(api, "post_decision", spy)
    sc = scenario_for(MANHATTAN, 30.0, hours=0.4, capacity=3)
    sc = replace(sc, dispatch=replace(sc.dispatch, objective="added_time"))
    _tables(sc, "hungarian", {"value": str(_zero_file(tmp_path, sc, 4))})
    busy_pairs = ends_at_drop = 0
    for problem, plans, post in seen:
        assert problem.post is not None
        now = problem.time
        drops = np.array([t.dropoff for t in problem.tasks])
        finite = np.isfinite(problem.cost)
        for i, aid in enumerate(problem.agent_ids.tolist()):
            plan = plans[aid]
            for j in np.flatnonzero(finite[i]).tolist():
                assert 0 <= post.seats[i, j] <= 3 - problem.tasks[j].passengers
                if not plan:
                    assert post.place[i, j] == drops[j]
                    assert post.after[i, j] == pytest.approx(problem.cost[i, j])
                    continue
                busy_pairs += 1
                last = plan[-1]
                assert post.place[i, j] in (drops[j], last.loc)
                ends_at_drop += post.place[i, j] == drops[j]
                assert now + post.after[i, j] >= last.eta - 1e-6
        # taking nothing: an idle vehicle stays where it is, now, all seats free; a busy one's
        # plan ends at its last stop as planned, with no fewer seats than after taking any
        place, after, seats = post.rest
        here = api.nodes_of(problem)[0]
        for i, aid in enumerate(problem.agent_ids.tolist()):
            plan = plans[aid]
            if not plan:
                assert place[i] == here[i] and after[i] == 0.0 and seats[i] == 3
            else:
                assert place[i] == plan[-1].loc and now + after[i] >= plan[-1].eta - 1e-6
                assert (seats[i] >= post.seats[i][np.isfinite(problem.cost[i])]).all()
    assert busy_pairs > 20 and 0 < ends_at_drop < busy_pairs  # both kinds of end seen


def test_the_value_before_a_decision_is_the_vehicles_own_plan_end():
    """With plans, a pair's score subtracts the value of the vehicle taking nothing (its own
    plan's end, discounted), not of where it is now with all seats free: one vehicle whose
    plan ends at node 1 (worth 3) in 600 s, one idle at node 0 (worth nothing)."""
    from dispatch.api.value import PostDecision
    from tests.learning.test_value import _problem, _value

    v = _value(weight=100.0)
    p = _problem([[100.0, 90.0], [100.0, 90.0]])
    after = np.array([[900.0, 800.0], [700.0, 600.0]])
    rest = (np.array([1, 0]), np.array([600.0, 0.0]), np.array([1, 1]))
    post = PostDecision(np.array([[1, 2], [1, 2]]), after, np.ones((2, 2), np.int64), rest)
    object.__setattr__(p, "post", lambda problem: post)
    adj = value_costs(p, v)
    g = v.gamma
    before = np.array([3.0 * g ** 600.0, 0.0])
    for i in range(2):
        assert adj[i, 0] == pytest.approx(100.0 - 100.0 * (3.0 * g ** after[i, 0] - before[i]))
        assert adj[i, 1] == pytest.approx(90.0 + 100.0 * before[i])


def test_the_trace_halves_are_disjoint_fixed_and_whole(tmp_path):
    """``--half a`` and ``--half b`` split one trace into two disjoint samples of its day (a
    day to learn on, another to test on), the same trips every time, together all of them."""
    from learning.value_train import trace_half

    sc = scenario_for(ROOT / "scenarios" / "nyc_manhattan_pooled.toml", 30.0)
    trips = sc.tasks.trips
    a, b = trace_half(trips, "a"), trace_half(trips, "b")
    assert len(a) + len(b) == len(trips) and 0.45 < len(a) / len(trips) < 0.55
    ids_a, ids_b = set(a.row.tolist()), set(b.row.tolist())
    assert not ids_a & ids_b and ids_a | ids_b == set(trips.row.tolist())
    assert np.array_equal(trace_half(trips, "a").row, a.row)
    assert np.all(np.diff(a.t) >= 0) and np.all(np.diff(b.t) >= 0)  # still in release order
    half = scenario_for(ROOT / "scenarios" / "nyc_manhattan_pooled.toml", 30.0, half="b")
    assert np.array_equal(half.tasks.trips.row, b.row)
    with pytest.raises(ValueError, match="half must be"):
        trace_half(trips, "c")
    with pytest.raises(ValueError, match="needs \\[tasks\\] source"):
        scenario_for(ROOT / "scenarios" / "chicago_taxi.toml", 30.0, half="a")


def test_a_half_of_a_scenario_without_a_trace_is_one_line(tmp_path, capsys):
    from dispatch.run import cli

    code = cli.main(["train", "value", "--half", "a", "--out", str(tmp_path / "v.npz")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error: chicago_taxi.toml: half of a trace needs")
    assert not (tmp_path / "v.npz").exists()
