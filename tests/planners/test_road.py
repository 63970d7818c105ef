"""The ``dijkstra`` road planner against scipy's Dijkstra on the network's own CSR matrix."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from dispatch.api.contracts import Planner
from dispatch.api.legs import RoadPoint
from dispatch.api.registry import load
from dispatch.space.roads import RoadNetwork, load_network, manhattan
from planners import road
from planners.road import RoadPlanner


@dataclass(frozen=True)
class Agent:
    id: int
    kind: str
    loc: Any
    speed: float = 10.0


@dataclass(frozen=True)
class Task:
    id: int
    kind: str
    loc: int


@pytest.fixture(scope="module")
def chicago() -> RoadNetwork:
    return load_network("chicago", base=Path("."))


def _agents(net: RoadNetwork, rng: np.random.Generator, k: int) -> list[Agent]:
    """Half on nodes, half part-way along random edges."""
    coo = net.time.tocoo()
    out = []
    for i in range(k):
        if i % 2:
            e = int(rng.integers(coo.nnz))
            f = float(rng.uniform(0.1, 0.9))
            loc = RoadPoint(int(coo.col[e]), int(coo.row[e]), f * coo.data[e],
                            f * net.length[coo.row[e], coo.col[e]])
        else:
            loc = int(rng.integers(net.n))
        out.append(Agent(i, "ugv", loc))
    return out


def _expected(net: RoadNetwork, agents, tasks) -> np.ndarray:
    nodes = [a.loc.node if isinstance(a.loc, RoadPoint) else a.loc for a in agents]
    rem = np.array([a.loc.remaining if isinstance(a.loc, RoadPoint) else 0.0 for a in agents])
    return dijkstra(net.time, indices=nodes)[:, [t.loc for t in tasks]] + rem[:, None]


def test_costs_backward_fields_then_cached(chicago):
    rng = np.random.default_rng(1)
    planner = RoadPlanner(chicago)
    agents = _agents(chicago, rng, 30)
    nodes = rng.integers(0, chicago.n, 8)
    tasks = [Task(i, "ground", int(n)) for i, n in enumerate(nodes)]
    tasks.append(Task(8, "ground", int(nodes[0])))  # shares task 0's node
    got = planner.costs(agents, tasks)
    np.testing.assert_allclose(got, _expected(chicago, agents, tasks), rtol=1e-12)
    assert planner.stats.extra["fields_computed"] == len(set(nodes.tolist()))  # one per node
    assert planner.stats.extra["forward_searches"] == 0

    moved = _agents(chicago, rng, 30)  # vehicles moved, tasks unchanged: only cached reads
    again = planner.costs(moved, tasks)
    np.testing.assert_allclose(again, _expected(chicago, moved, tasks), rtol=1e-12)
    assert planner.stats.extra["fields_computed"] == len(set(nodes.tolist()))
    assert planner.stats.extra["field_reuses"] == len(tasks)


def test_costs_forward_when_tasks_outnumber_agent_nodes(chicago):
    rng = np.random.default_rng(2)
    planner = RoadPlanner(chicago)
    agents = _agents(chicago, rng, 3)
    tasks = [Task(i, "ground", int(n)) for i, n in enumerate(rng.integers(0, chicago.n, 40))]
    got = planner.costs(agents, tasks)
    np.testing.assert_allclose(got, _expected(chicago, agents, tasks), rtol=1e-12)
    assert planner.stats.extra["forward_searches"] == 3
    assert planner.stats.extra["fields_computed"] == 0 and not planner._fields

    # mixed: a few tasks cached by a backward decision, then many fresh ones answered forward
    planner.costs(_agents(chicago, rng, 20), tasks[:5])
    assert planner.stats.extra["fields_computed"] == 5
    fresh = rng.integers(0, chicago.n, 30)
    more = tasks[:5] + [Task(100 + i, "ground", int(n)) for i, n in enumerate(fresh)]
    got = planner.costs(agents, more)
    np.testing.assert_allclose(got, _expected(chicago, agents, more), rtol=1e-12)
    assert planner.stats.extra["forward_searches"] == 6
    assert planner.stats.extra["fields_computed"] == 5


def test_forward_ratio_threshold_is_exact_either_side():
    net = manhattan(15, 10, block=120.0, speed=8.0)
    rng = np.random.default_rng(4)
    agents = _agents(net, rng, 2)
    agent_nodes = {a.loc if isinstance(a.loc, int) else a.loc.node for a in agents}
    for k in (road.FORWARD_RATIO * 2 - 1, road.FORWARD_RATIO * 2 + 5):
        nodes = rng.choice(net.n, k, replace=False)
        tasks = [Task(i, "ground", int(n)) for i, n in enumerate(nodes)]
        planner = RoadPlanner(net)
        got = planner.costs(agents, tasks)
        np.testing.assert_allclose(got, _expected(net, agents, tasks), rtol=1e-12)
        forward = planner.stats.extra["forward_searches"] > 0
        assert forward == (k >= road.FORWARD_RATIO * len(agent_nodes))


def test_plan_path_time_equals_cost(chicago):
    rng = np.random.default_rng(6)
    planner = RoadPlanner(chicago)
    agents = _agents(chicago, rng, 6)
    tasks = [Task(i, "ground", int(n)) for i, n in enumerate(rng.integers(0, chicago.n, 6))]
    cost = planner.costs(agents, tasks)
    for a, agent in enumerate(agents):
        for t, task in enumerate(tasks):
            path = planner.plan(agent, task.loc)
            start = agent.loc.node if isinstance(agent.loc, RoadPoint) else agent.loc
            assert path[0] == start and path[-1] == task.loc
            seconds = sum(float(chicago.time[u, v]) for u, v in zip(path[:-1], path[1:]))
            rem = agent.loc.remaining if isinstance(agent.loc, RoadPoint) else 0.0
            assert rem + seconds == pytest.approx(cost[a, t], rel=1e-12)
    assert planner.plan(Agent(0, "ugv", 7), 7) == [7]
    assert planner.stats.plans == 37


def test_task_closed_drops_the_cache_shared_nodes_last(monkeypatch):
    monkeypatch.setattr(road, "RETIRED_FIELD_BYTES", 0)  # keep nothing after closing
    net = manhattan(6, 6)
    planner = RoadPlanner(net)
    agents = [Agent(0, "ugv", 0), Agent(1, "ugv", RoadPoint(8, 7, 3.0, 30.0))]
    tasks = [Task(1, "ground", 20), Task(2, "ground", 20), Task(3, "ground", 35)]
    planner.costs(agents, tasks)
    assert set(planner._fields) == {20, 35} and planner.stats.extra["fields_computed"] == 2
    planner.task_closed(1)
    assert 20 in planner._fields  # task 2 still stands on node 20
    planner.task_closed(2)
    planner.task_closed(3)
    planner.task_closed(99)  # unknown: nothing to forget
    assert not planner._fields and not planner._node_of
    planner.costs(agents, tasks[:1])
    assert planner.stats.extra["fields_computed"] == 3  # recomputed after closing


def test_closed_fields_are_kept_bounded_and_revived_exact(monkeypatch):
    net = manhattan(6, 6)
    field_bytes = net.n * 8
    monkeypatch.setattr(road, "RETIRED_FIELD_BYTES", 3 * field_bytes)  # room for 3 fields
    planner = RoadPlanner(net)
    agents = [Agent(0, "ugv", 0), Agent(1, "ugv", RoadPoint(8, 7, 3.0, 30.0))]
    nodes = [20, 35, 3, 11, 20, 35]
    for k, node in enumerate(nodes[:4]):  # four tasks, each closed after its decision
        planner.costs(agents, [Task(k, "ground", node)])
        planner.task_closed(k)
        assert planner._retired_bytes <= 3 * field_bytes
    assert list(planner._retired) == [35, 3, 11]  # the oldest (20) went first
    assert planner.stats.extra["fields_computed"] == 4
    tasks = [Task(10, "ground", 35), Task(11, "ground", 20), Task(12, "ground", 11)]
    got = planner.costs(agents, tasks)  # 35, 11 revived, 20 computed again
    assert planner.stats.extra["fields_computed"] == 5
    assert planner.stats.extra["fields_revived"] == 2
    assert set(planner._fields) == {35, 20, 11} and list(planner._retired) == [3]
    np.testing.assert_array_equal(got, _expected(net, agents, tasks))
    path = planner.plan(agents[0], 35)  # a revived field is walked as a fresh one would be
    assert path[0] == 0 and path[-1] == 35


def test_refuses_a_non_road_space_and_is_registered():
    with pytest.raises(TypeError, match="serves road networks"):
        RoadPlanner(object())  # type: ignore[arg-type]
    assert load("planner", "dijkstra") is RoadPlanner
    assert RoadPlanner.spaces == ("road",) and Planner.spaces == ("voxel",)
    net = manhattan(2, 2)
    planner = RoadPlanner(net)
    assert planner.space is net
    assert planner.costs([], [Task(0, "ground", 1)]).shape == (0, 1)


# ---------------------------------------------------------------- PHAST on the hierarchy
def _close(got: np.ndarray, want: np.ndarray) -> None:
    assert np.array_equal(np.isfinite(got), np.isfinite(want))
    assert np.abs(got - want).max(initial=0.0) < 1e-9


@pytest.fixture
def hierarchy_everywhere(monkeypatch):
    """Give small networks (Manhattan) a contraction hierarchy too."""
    monkeypatch.setattr(road, "CH_MIN_NODES", 0)


@pytest.mark.parametrize("threads", [1, 2])
def test_phast_decisions_equal_scipy_on_chicago(chicago, threads, monkeypatch):
    monkeypatch.setattr(road, "FIELD_THREADS", threads)
    planner = RoadPlanner(chicago)
    assert planner._hierarchy is road.hierarchy(chicago)  # one hierarchy per network
    rng = np.random.default_rng(11)
    nodes = rng.choice(chicago.n, 37, replace=False)  # 37: blocks of 8 and a ragged one
    tasks = [Task(i, "ground", int(n)) for i, n in enumerate(nodes)]
    for step in range(4):  # repeated decisions: fields reused, some requests closed and new
        agents = _agents(chicago, rng, 60)
        _close(planner.costs(agents, tasks), _expected(chicago, agents, tasks))
        for t in tasks[:5]:
            planner.task_closed(t.id)
        new = rng.integers(0, chicago.n, 5)
        tasks = tasks[5:] + [Task(100 * (step + 1) + i, "ground", int(n))
                             for i, n in enumerate(new)]
    assert planner.stats.extra["field_reuses"] > 0
    assert len(planner._fields) <= 37


def test_phast_fields_equal_scipy_both_directions(chicago):
    h = road.hierarchy(chicago)
    nodes = np.random.default_rng(12).integers(0, chicago.n, 10)
    back = np.stack(h.fields(nodes, to=True))[:, h.pos]
    fwd = np.stack(h.fields(nodes, to=False))[:, h.pos]
    _close(back, dijkstra(chicago.time.T.tocsr(), indices=nodes))
    _close(fwd, dijkstra(chicago.time, indices=nodes))


@pytest.mark.usefixtures("hierarchy_everywhere")
@pytest.mark.parametrize("shape", [(60, 9), (3, 40), (1, 1), (1, 7), (7, 1)])
def test_phast_on_manhattan_equals_scipy(shape):
    net = manhattan(17, 11, block=130.0, speed=9.0)
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    planner = RoadPlanner(net)
    assert planner._hierarchy is not None
    for _ in range(3):
        agents = _agents(net, rng, shape[0])
        tasks = [Task(i, "ground", int(n)) for i, n in enumerate(rng.integers(0, net.n, shape[1]))]
        _close(planner.costs(agents, tasks), _expected(net, agents, tasks))


@pytest.mark.usefixtures("hierarchy_everywhere")
def test_phast_edge_cases():
    net = manhattan(9, 8, block=100.0, speed=10.0)
    planner = RoadPlanner(net)
    # a vehicle on the request's node, duplicated vehicle nodes, a mid-edge vehicle ending there
    agents = [Agent(0, "ugv", 5), Agent(1, "ugv", 5), Agent(2, "ugv", RoadPoint(5, 4, 3.5, 35.0)),
              Agent(3, "ugv", 40), Agent(4, "ugv", RoadPoint(40, 41, 1.0, 10.0))]
    tasks = [Task(0, "ground", 5), Task(1, "ground", 5), Task(2, "ground", 40)]
    got = planner.costs(agents, tasks)
    _close(got, _expected(net, agents, tasks))
    assert got[0, 0] == 0.0 and got[1, 1] == 0.0 and got[2, 0] == 3.5 and got[3, 2] == 0.0
    assert planner.stats.extra["fields_computed"] == 2  # one per distinct node
    assert planner.costs([], tasks).shape == (0, 3)
    assert planner.costs(agents, []).shape == (5, 0)
    one = planner.costs(agents[:1], tasks[2:])
    _close(one, _expected(net, agents[:1], tasks[2:]))
    for t in tasks:
        planner.task_closed(t.id)
    assert not planner._fields


@pytest.mark.usefixtures("hierarchy_everywhere")
def test_phast_single_node_and_two_node_networks():
    for columns, rows in ((1, 1), (2, 1)):
        net = manhattan(columns, rows)
        planner = RoadPlanner(net)
        agents = [Agent(i, "ugv", i) for i in range(net.n)]
        tasks = [Task(i, "ground", i) for i in range(net.n)]
        _close(planner.costs(agents, tasks), _expected(net, agents, tasks))


def test_stop_dijkstra_kernel_is_exact_at_wanted_nodes(chicago):
    from planners import _road_fast

    t = chicago.time.T.tocsr()
    ip, ix = t.indptr.astype(np.int64), t.indices.astype(np.int64)
    hk, hn = np.empty(ix.size + 1), np.empty(ix.size + 1, np.int64)
    dist = np.empty(chicago.n)
    rng = np.random.default_rng(13)
    for k in (0, 1, 50):
        want = np.zeros(chicago.n, dtype=np.bool_)
        picks = rng.integers(0, chicago.n, k)
        want[picks] = True
        src = int(picks[0]) if k == 1 else 17  # k == 1: the wanted node is the source
        settled = _road_fast.dijkstra_until(ip, ix, t.data, src, want, int(want.sum()), dist, hk, hn)
        ref = dijkstra(t, indices=src)
        if k == 0:  # nothing wanted: a complete field
            assert settled == chicago.n
            np.testing.assert_array_equal(dist, ref)
        else:
            np.testing.assert_array_equal(dist[picks], ref[picks])
            assert settled <= chicago.n
        if k == 1:
            assert settled == 1


# ----------------------------------------------------------------------------- disk cache


def test_hierarchy_disk_cache_round_trip(tmp_path, monkeypatch, caplog):
    """A hierarchy written by one process is read by the next (a new network object of the
    same graph) and is the same as a fresh contraction: same arrays, same fields; a damaged
    file is contracted again and replaced; ``off`` caches nothing."""
    monkeypatch.setenv("DISPATCH_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(road, "CH_MIN_NODES", 0)
    first = manhattan(23, 19, block=110.0, speed=8.0)
    path = road.hierarchy_cache(first)
    assert path.parent == tmp_path / "hierarchies" and not path.exists()
    h1 = road.hierarchy(first)
    assert path.is_file()
    written = path.read_bytes()

    calls = []
    monkeypatch.setattr(road, "contract", lambda net: calls.append(net) or road_contract(net))
    second = manhattan(23, 19, block=110.0, speed=8.0)  # another object, the same graph
    assert road.hierarchy_cache(second) == path
    h2 = road.hierarchy(second)
    assert calls == [] and h2 is not h1  # read from the file, not contracted
    fresh = road_contract(second)
    for a, b, c in zip(h1.contracted, h2.contracted, fresh):
        assert np.array_equal(a, b) and np.array_equal(a, c) and a.dtype == c.dtype
    nodes = np.arange(0, second.n, 7)
    for f1, f2 in zip(h1.fields(nodes, to=True), h2.fields(nodes, to=True)):
        assert np.array_equal(f1, f2)
    _close(np.stack(h2.fields(nodes, to=True))[:, h2.pos],
           dijkstra(second.time.T.tocsr(), indices=nodes))

    other = manhattan(23, 19, block=111.0, speed=8.0)  # other times: another file
    assert road.hierarchy_cache(other) != path

    path.write_bytes(b"not an npz file")
    third = manhattan(23, 19, block=110.0, speed=8.0)
    with caplog.at_level("WARNING", logger="planners.road"):
        h3 = road.hierarchy(third)
    assert len(calls) == 1 and "ignoring the cached road hierarchy" in caplog.text
    assert all(np.array_equal(a, b) for a, b in zip(h3.contracted, fresh))
    assert path.read_bytes() == written  # replaced by a good one

    monkeypatch.setenv("DISPATCH_CACHE_DIR", "off")
    assert road.hierarchy_cache(third) is None


road_contract = road.contract


def test_between_equals_scipy_in_every_form():
    """``between``: the matrix (forward fields for few sources, backward for few targets) and
    the pairwise form (small and large) equal scipy's Dijkstra on the time matrix, road points
    counting what is left of their edge."""
    from scipy.sparse.csgraph import dijkstra

    from dispatch.api.legs import RoadPoint
    from dispatch.space.roads import manhattan
    from planners.road import RoadPlanner

    net = manhattan(6, 5, 100.0, 10.0)
    p = RoadPlanner(net)
    full = dijkstra(net.time)
    rng = np.random.default_rng(3)
    src = [int(x) for x in rng.integers(net.n, size=12)]
    src[3] = RoadPoint(int(src[3]), prev=int(net.time[int(src[3])].indices[0]), remaining=4.0)
    tgt = [int(x) for x in rng.integers(net.n, size=12)]

    def want(s, t):
        return (full[s.node, t] + 4.0) if isinstance(s, RoadPoint) else full[s, t]

    expect = np.array([[want(s, t) for t in tgt] for s in src])
    assert np.allclose(p.between(src, tgt), expect, atol=1e-9)  # backward (as many targets)
    assert np.allclose(p.between(src[:2], tgt), expect[:2], atol=1e-9)  # forward
    assert np.allclose(p.between(src, tgt[:2]), expect[:, :2], atol=1e-9)
    # one target (a new request's pickup: its field's column), one source (forward: its row),
    # a road point among the sources in both; and the matrix of a whole fleet's stops as a
    # node array, as a decision asks
    assert np.allclose(p.between(src, tgt[5:6]), expect[:, 5:6], atol=1e-9)
    assert np.allclose(p.between(src[3:4], tgt), expect[3:4], atol=1e-9)
    assert np.allclose(p.between(src[4:5], tgt), expect[4:5], atol=1e-9)
    nodes = np.array(src[4:], dtype=np.int64)
    assert np.allclose(p.between(nodes, tgt[:1]), expect[4:, :1], atol=1e-9)
    assert np.allclose(p.between(tgt[:1], nodes), full[tgt[0], nodes][None, :], atol=1e-9)
    diag = np.diag(expect)
    assert np.allclose(p.between(src, tgt, pairwise=True), diag, atol=1e-9)
    assert np.allclose(p.between(src[:4], tgt[:4], pairwise=True), diag[:4], atol=1e-9)


def test_distinct_nodes_are_numpys_unique():
    """The road planner's small-array ``np.unique`` (a decision's few new requests) answers as
    numpy's does, sizes on both sides of its cut-over."""
    from planners.road import _distinct

    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 7, 64, 65, 200):
        nodes = rng.integers(0, 9, n).astype(np.int64)
        got, want = _distinct(nodes), np.unique(nodes, return_inverse=True)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape
            np.testing.assert_array_equal(g, w)
