"""learning.value: the learned value of where a vehicle ends up, and hungarian's value option."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from allocators.hungarian import HungarianAllocator
from dispatch.api.problem import AgentView, AllocationProblem, TaskView
from learning.value import ZoneValue
from learning.value_train import td_learn, train
from learning.zones import Zones

ROOT = Path(__file__).resolve().parents[2]
MANHATTAN = ROOT / "scenarios" / "manhattan.toml"


def test_zones_number_occupied_squares_only():
    xy = np.array([[0.0, 0.0], [50.0, 10.0], [250.0, 0.0], [1000.0, 1000.0]])
    z = Zones(xy, 100.0)
    assert z.n == 3
    assert z.of_node[0] == z.of_node[1] != z.of_node[2]
    assert z.of_xy(np.array([[500.0, 500.0]]))[0] == -1
    assert (z.of_xy(xy) == z.of_node).all()


def test_td_learns_the_discounted_trips_of_a_chain():
    # zone 0 at t=0: a trip (reward 1) to zone 1 ending at t=100; then idle to the end
    tr = {"z": np.array([0, 1]), "t": np.array([0.0, 100.0]), "r": np.array([1.0, 0.0]),
          "z2": np.array([1, -1]), "t2": np.array([100.0, 3600.0])}
    table, _ = td_learn(tr, 2, 2, 1800.0, gamma=0.5 ** (1 / 3600), shrink=0.0)
    assert table[0, 0] == pytest.approx(1.0)
    assert table[1, 0] == pytest.approx(0.0)
    # a second trip from zone 1 makes zone 0 worth 1 + discounted 1
    tr2 = {k: np.append(v, x) for (k, v), x in zip(tr.items(), [1, 200.0, 1.0, 1, 300.0])}
    table, _ = td_learn(tr2, 2, 2, 1800.0, gamma=0.5 ** (1 / 3600), shrink=0.0)
    assert table[0, 0] > 1.0


XY = np.array([[0.0, 0.0], [5000.0, 0.0], [0.0, 5000.0]])  # a three-node network


def _value(weight=100.0) -> ZoneValue:
    xy = XY
    zones = Zones(xy, 1000.0)
    table = np.zeros((zones.n, 2))
    table[zones.of_node[1]] = 3.0  # node 1's zone is worth three requests
    return ZoneValue(zones, xy, 3600.0, table, 0.5 ** (1 / 3600), weight,
                     np.tile([0.0, 0.1], (24, 1)), {})


def _problem(cost) -> AllocationProblem:
    cost = np.asarray(cost, dtype=float)
    agents = tuple(AgentView(id=10 + i, kind="car", loc=0, speed=10.0)
                   for i in range(cost.shape[0]))
    tasks = (TaskView(id=1, kind="trip", loc=0, released_at=0.0, dropoff=1),
             TaskView(id=2, kind="trip", loc=0, released_at=0.0, dropoff=2))
    return AllocationProblem(time=0.0, agents=agents, tasks=tasks, cost=cost,
                             comm=np.ones((len(agents),) * 2, bool),
                             rng=np.random.default_rng(0),
                             agent_pos=np.zeros((len(agents), 3)), task_pos=np.zeros((2, 3)))


def test_value_prefers_trips_that_end_where_vehicles_are_worth_more():
    v = _value()
    p = _problem([[100.0, 90.0]])
    adj = v.adjusted(p)
    assert adj[0, 1] == pytest.approx(90.0)  # zone without value: the cost as it was
    assert adj[0, 0] < 100.0 - 200.0  # discounted 3 x 100 s off
    assert HungarianAllocator().allocate(p).pairs == ((10, 2),)
    assert v.adjusted(_problem([[np.inf, 90.0]]))[0, 0] == np.inf


def test_value_file_round_trip_and_hungarian_option(tmp_path):
    v = _value()
    v.save(tmp_path / "v.npz")
    h = HungarianAllocator(value=str(tmp_path / "v.npz"))
    assert not h.minimizes_total_cost and HungarianAllocator.minimizes_total_cost
    p = _problem([[100.0, 90.0]])
    assert h.allocate(p).pairs == ((10, 1),)
    assert HungarianAllocator(value=str(tmp_path / "v.npz"), value_weight=0.0) \
        .allocate(p).pairs == ((10, 2),)
    assert np.allclose(ZoneValue.load(tmp_path / "v.npz").table, v.table)


def test_train_on_a_short_day_and_run_with_it(tmp_path):
    from dispatch.run.runner import run_one
    from learning.value_train import scenario_for

    out = tmp_path / "value.npz"
    v = train(MANHATTAN, out, agents=50, seeds=(0,), zone=1000.0, hours=0.5, log=lambda s: None)
    assert out.exists() and v.table.max() > 0 and v.meta["transitions"] > 50
    sc = scenario_for(MANHATTAN, 30.0, hours=0.5)
    sc = replace(sc, dispatch=replace(sc.dispatch, allocator_params=(("value", str(out)),)))
    s = run_one(sc.runs(allocator="hungarian", seed=0)[0]).summary
    assert s["tasks_completed"] > 0


def _road_problem(seed: int, n: int, m: int, comm=None) -> AllocationProblem:
    """A hand-built road decision: agents and trips on the nodes of :func:`_value`'s network,
    costs of a city's taxis (minutes), some infeasible."""
    rng = np.random.default_rng(seed)
    cost = rng.uniform(60.0, 900.0, (n, m))
    cost[rng.random((n, m)) < 0.2] = np.inf
    agents = tuple(AgentView(id=100 + i, kind="car", loc=int(rng.integers(3)), speed=10.0)
                   for i in range(n))
    tasks = tuple(TaskView(id=200 + j, kind="trip", loc=int(rng.integers(3)), released_at=0.0,
                           dropoff=int(rng.integers(3))) for j in range(m))
    # the pickups' positions are their nodes' (the value checks it is on its network)
    task_pos = np.column_stack([XY[[t.loc for t in tasks]], np.zeros(m)])
    return AllocationProblem(time=600.0, agents=agents, tasks=tasks, cost=cost,
                             comm=np.ones((n, n), bool) if comm is None else comm,
                             rng=np.random.default_rng(seed), agent_pos=rng.random((n, 3)),
                             task_pos=task_pos)


@pytest.mark.parametrize("ranged", [False, True])
def test_magnnet_with_a_value_is_magnnet_on_the_adjusted_costs(tmp_path, ranged):
    from allocators.magnnet.allocator import MagnnetAllocator
    from learning.value import ValueOption

    v = _value(weight=150.0)
    v.save(tmp_path / "v.npz")
    opt = ValueOption(tmp_path / "v.npz")
    with_value = MagnnetAllocator(value=str(tmp_path / "v.npz"))
    plain = MagnnetAllocator()
    changed = 0
    for seed in range(6):
        n, m = 9, 7
        comm = None
        if ranged:  # a line of agents, each hearing its neighbours: partial views
            idx = np.arange(n)
            comm = np.abs(idx[:, None] - idx[None, :]) <= 2
        p = _road_problem(seed, n, m, comm)
        adj = opt.costs(p)
        assert (adj + opt.offset >= p.cost - 1e-9).all()  # never below the travel time
        got = with_value.allocate(p)
        # the same decision (a fresh rng of the same seed: flooding draws from it)
        ref = plain.allocate(replace(p, cost=adj + opt.offset, rng=np.random.default_rng(seed)))
        assert got.pairs == ref.pairs and got.rounds == ref.rounds
        assert got.messages == ref.messages and got.hops == ref.hops
        # the requests record travel times, not the adjusted costs
        row = {a: i for i, a in enumerate(p.agent_ids.tolist())}
        col = {t: j for j, t in enumerate(p.task_ids.tolist())}
        assert all(r.cost == p.cost[row[r.agent_id], col[r.task_id]] for r in got.requests)
        changed += got.pairs != plain.allocate(_road_problem(seed, n, m, comm)).pairs
    assert changed > 0  # the value changes some decisions
    assert with_value.describe()["value"].startswith("v.npz@")
    with pytest.raises(TypeError):
        MagnnetAllocator(variant="paper", value=str(tmp_path / "v.npz"))
