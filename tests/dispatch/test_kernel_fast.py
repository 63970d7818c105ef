"""The kernel's fast paths give the same numbers as the plain code they replace."""

from __future__ import annotations

import dataclasses
from itertools import accumulate
from pathlib import Path

import numpy as np
import pytest

from dispatch.api.legs import Leg, RoadPoint
from dispatch.space.roads import load_network, manhattan


@pytest.fixture(scope="module")
def chicago():
    return load_network("chicago", base=Path("."))


def _python_leg(net, start, nodes):
    """The leg's cumulative seconds and metres summed in Python, edge by edge (scipy's CSR
    lookup), as the kernel did before it had a compiled helper."""
    p = start if isinstance(start, RoadPoint) else RoadPoint(int(start))
    secs = [max(p.remaining, 0.0)] + [float(net.time[a, b]) for a, b in zip(nodes, nodes[1:])]
    mets = [max(p.remaining_m, 0.0)] + [float(net.length[a, b])
                                        for a, b in zip(nodes, nodes[1:])]
    return list(accumulate(secs)), list(accumulate(mets))


@pytest.mark.parametrize("which", ["manhattan", "chicago"])
def test_compiled_legs_equal_python_sums_bit_for_bit(which, chicago):
    net = manhattan(9, 7, block=173.0, speed=7.3) if which == "manhattan" else chicago
    assert net._edges.leg_sums is not None  # the compiled path serves these networks
    rng = np.random.default_rng(3)
    coo = net.time.tocoo()
    for k in range(40):
        src, dst = (int(x) for x in rng.integers(0, net.n, 2))
        route = net.route(src, dst)
        nodes = route.nodes.tolist()
        start = src
        if k % 2:  # start part-way along an edge into the path's first node
            into = np.flatnonzero(coo.col == nodes[0])
            e = int(into[rng.integers(into.size)]) if into.size else None
            if e is not None:
                f = float(rng.uniform(0.1, 0.9))
                start = RoadPoint(nodes[0], int(coo.row[e]), f * coo.data[e],
                                  f * net.length[coo.row[e], coo.col[e]])
        leg = net.leg(start, nodes)
        times, metres = _python_leg(net, start, nodes)
        assert leg.nodes.tolist() == nodes
        assert leg.times.tolist() == times and leg.metres.tolist() == metres  # exact
        assert leg.prev == (start.prev if isinstance(start, RoadPoint) else -1)
        # every field, and the seconds and metres the operator reads, set as the properties
        # would compute them
        assert set(leg.__dict__) == {f.name for f in dataclasses.fields(Leg)} \
            | {"seconds", "length"}
        assert leg.seconds == times[-1] and leg.length == metres[-1]


def test_compiled_legs_reject_what_the_python_path_rejects():
    net = manhattan(4, 4, block=100.0, speed=10.0)
    with pytest.raises(ValueError, match="no edge 0 -> 5"):
        net.leg(0, [0, 5])  # a diagonal: not an edge
    with pytest.raises(ValueError, match="must start there"):
        net.leg(0, [1, 2])
    with pytest.raises(ValueError, match="no edge"):
        net.leg(0, [0, 1, 99])  # not a node


def test_recorder_columns_equal_pa_array():
    """The recorder's numpy-built columns are the arrays ``pa.array`` makes, and whatever is
    not a plain float / int / bool / str column still goes through ``pa.array`` (same result,
    same errors)."""
    import pyarrow as pa

    from dispatch.output.parquet import arrow_column

    nan, inf = float("nan"), float("inf")
    cases = [
        ((1.5, nan, -inf, 0.0, -0.0, 1e308), pa.float64()),
        ((), pa.float64()),
        ((3, -2**63, 2**63 - 1, 0), pa.int64()),
        ((True, False, True, True, False, False, True, False, True), pa.bool_()),
        (("release", "", "dépôt ✓", "x" * 300), pa.string()),
        ((1, 2.5), pa.float64()),  # an int in a float column: pa.array's conversion
        ((None, 1.0), pa.float64()),  # a null
        ((np.float64(2.0), 1.0), pa.float64()),
        ((np.float64(-0.0), np.float64(nan), 3.0), pa.float64()),
        ((np.int64(-2**63), 7, np.int64(5)), pa.int64()),
        ((np.int32(4), 1), pa.int64()),
        ((np.float32(0.1), 1.0), pa.float64()),
        ((True, 1), pa.int64()),
    ]
    for values, typ in cases:
        try:
            want = pa.array(values, typ)
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, OverflowError) as e:
            with pytest.raises(type(e)):
                arrow_column(values, typ)
            continue
        got = arrow_column(values, typ)
        got.validate(full=True)
        assert got.type == want.type and got.null_count == want.null_count
        gl, wl = got.to_pylist(), want.to_pylist()
        assert len(gl) == len(wl)
        for a, b in zip(gl, wl):  # equal values, NaN where NaN, the sign of a zero kept
            assert repr(a) == repr(b)
    with pytest.raises(OverflowError):
        arrow_column((2**64,), pa.int64())


@pytest.mark.parametrize("value", ["city_day-fcfs__s0", "", "é ✓"])
@pytest.mark.parametrize("n", [0, 1, 7])
def test_recorder_constant_column(value, n):
    import pyarrow as pa

    from dispatch.output.parquet import ConstantColumn, arrow_column

    got = arrow_column(ConstantColumn(value, n), pa.string())
    got.validate(full=True)
    assert got.equals(pa.array([value] * n, pa.string()))


def test_centralized_allocation_equals_the_constructed_one():
    from dispatch.api.problem import Allocation, AllocationProblem, AgentView, Bid, TaskView

    rng = np.random.default_rng(5)
    cost = rng.uniform(1, 9, (4, 3))
    agents = tuple(AgentView(10 + k, "ugv", (k, 0, 0), 1.0) for k in range(4))
    tasks = tuple(TaskView(7 + k, "ground", (k, 1, 0), 0.0) for k in range(3))
    problem = AllocationProblem(0.0, agents, tasks, cost, np.ones((4, 4), bool), rng)
    got = Allocation.centralized(problem, [(2, 0), (0, 2)])
    want = Allocation(pairs=((12, 7), (10, 9)), rounds=1, messages=0,
                      requests=(Bid(0, 12, 7, float(cost[2, 0]), True),
                                Bid(0, 10, 9, float(cost[0, 2]), True)))
    # besides the fields, the answer made by index carries its (row, column) pairs: a hint
    # that dispatch.decide.answers.validate verifies against the problem
    assert got.index == ((2, 0), (0, 2))
    assert got == want and dataclasses.replace(got, index=()).__dict__ == want.__dict__
    assert [r.__dict__ for r in got.requests] == [r.__dict__ for r in want.requests]
    assert hash(got.requests[0]) == hash(want.requests[0])


@pytest.mark.parametrize("reassign", [False, True])
def test_fleet_arrays_follow_the_vehicles(tmp_path, reassign):
    """``driving_or_off_node`` stays ``driving | off_node`` through trips, breakdowns
    (vehicles stopped part-way along an edge) and re-assignments, checked after every event."""
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    path = tmp_path / "f.toml"
    path.write_text(
        'name = "f"\nseed = 4\nduration = 4000.0\n[world]\nnetwork = "manhattan"\n'
        'blocks = [6, 5]\nblock = 150.0\nspeed = 10.0\n[fleet]\nagents = 6\n[tasks]\n'
        'source = "poisson"\nrate = 0.05\ncount = 120\n[dispatch]\nallocator = "hungarian"\n'
        f'planner = "dijkstra"\nreassign = {"true" if reassign else "false"}\n'
        '[faults]\nrate = 2.0\nrepair = 120.0\non_board = "transfer"\n', encoding="utf-8")
    spec = load_scenario(path).runs()[0]
    sim = Simulation(spec, make_recorder(spec, tmp_path / "out"))
    fleet, seen = sim.fleet, set()

    def check(e):
        seen.add(e.kind)
        assert np.array_equal(fleet.driving_or_off_node, fleet.driving | fleet.off_node)
        assert fleet._off_node == fleet.off_node.tolist()

    sim.bus.subscribe(check)
    sim.run()
    assert {"breakdown", "dropoff"} <= seen and (not reassign or "reassign" in seen)


@pytest.mark.parametrize("flush_rows", [7, 10_000])
def test_event_rows_placed_per_chunk_equal_per_event_positions(tmp_path, flush_rows):
    """The events table places each event where ``space.position(loc)`` says (nodes, road
    points of vehicles stopped part-way by a breakdown, no place at all: NaN), whether a chunk
    holds a few events or all of them."""
    import math

    import pyarrow.parquet as pq

    from dispatch.api.legs import RoadPoint
    from dispatch.run.runner import make_recorder
    from dispatch.run.sim import Simulation
    from dispatch.scenario.load import load_scenario

    path = tmp_path / "e.toml"
    path.write_text(
        'name = "e"\nseed = 2\nduration = 3000.0\n[world]\nnetwork = "manhattan"\n'
        'blocks = [5, 4]\nblock = 150.0\nspeed = 10.0\n[fleet]\nagents = 5\n[tasks]\n'
        'source = "poisson"\nrate = 0.05\ncount = 80\nmax_active = 3\n[dispatch]\n'
        'allocator = "fcfs"\nplanner = "dijkstra"\n'
        '[faults]\nrate = 3.0\nrepair = 100.0\non_board = "transfer"\n', encoding="utf-8")
    spec = load_scenario(path).runs()[0]
    rec = make_recorder(spec, tmp_path / "out", flush_rows=flush_rows)
    sim = Simulation(spec, rec)
    seen = []
    sim.bus.subscribe(lambda e: seen.append(
        (e.t, e.kind, e.agent_id, e.task_id,
         *((math.nan,) * 3 if e.loc is None else sim.space.position(e.loc)), e.loc)))
    sim.run()
    files = rec.finish()
    got = pq.read_table(files["events"]).to_pylist()
    assert len(got) == len(seen) > 100
    kinds = {type(s[-1]) for s in seen}
    assert {int, RoadPoint, type(None)} <= kinds  # every kind of place occurs
    for row, want in zip(got, seen):
        assert (row["t"], row["event"], row["agent_id"], row["task_id"]) == want[:4]
        assert row["request_id"] == (sim.book.request_ids[want[3]] if want[3] >= 0 else None)
        for k, v in zip("xyz", want[4:7]):
            assert repr(row[k]) == repr(float(v))


def test_appender_columns_must_name_every_column(tmp_path):
    from dispatch.output.parquet import Recorder

    rec = Recorder(tmp_path, "r", {}, {})
    append = rec.appender("events", lambda items: {"t": [i for i in items]})
    append(1.0)
    with pytest.raises(ValueError, match="columns\\(\\) gave"):
        rec.flush("events")


def test_problem_made_equals_the_constructed_one():
    import dataclasses

    from dispatch.api.problem import AgentView, AllocationProblem, TaskView

    agents = (AgentView(3, "ugv", (0, 0, 0), 1.0), AgentView(5, "uav", (1, 0, 2), 2.0))
    tasks = (TaskView(9, "ground", (2, 1, 0), 0.0),)
    rng = np.random.default_rng(0)
    args = (4.0, agents, tasks, np.array([[1.0], [2.0]]), np.ones((2, 2), bool), rng)
    kw = dict(max_rounds=7, loss=0.1, latency=0.5, cell_size=2.0)
    made = AllocationProblem.made(*(a.copy() if isinstance(a, np.ndarray) else a for a in args),
                                  **kw, agent_pos=None, task_pos=lambda: np.zeros((1, 3)))
    built = AllocationProblem(*args, **kw, agent_pos=None, task_pos=np.zeros((1, 3)))
    for f in dataclasses.fields(AllocationProblem):  # every field, the same value
        a, b = getattr(made, f.name), getattr(built, f.name)
        assert (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b), f.name
    assert set(made.__dict__) == set(built.__dict__)
    assert not made.cost.flags.writeable and not made.agent_pos.flags.writeable
    with pytest.raises(ValueError, match="cost has shape"):
        AllocationProblem.made(*args[:3], np.ones((3, 1)), *args[4:], **kw, agent_pos=None,
                               task_pos=None)


def test_problem_with_lazy_positions_pickles():
    import pickle

    from dispatch.api.problem import AgentView, AllocationProblem, TaskView

    agents = (AgentView(3, "ugv", (0, 0, 0), 1.0),)
    tasks = (TaskView(9, "ground", (2, 1, 0), 0.0),)
    calls = []

    def where():  # a local function: not picklable itself
        calls.append(1)
        return np.full((1, 3), 7.0)

    p = AllocationProblem.made(1.0, agents, tasks, np.ones((1, 1)), np.ones((1, 1), bool),
                               np.random.default_rng(1), max_rounds=5, loss=0.0, latency=0.0,
                               cell_size=1.0, agent_pos=where, task_pos=None)
    assert calls == []  # not computed until read
    q = pickle.loads(pickle.dumps(p))
    assert calls == [1]
    assert np.array_equal(q.agent_pos, np.full((1, 3), 7.0)) and not q.agent_pos.flags.writeable
    assert np.array_equal(q.task_pos, p.task_pos) and np.array_equal(q.cost, p.cost)
    assert not q.cost.flags.writeable and not q.comm.flags.writeable
    assert q.time == 1.0 and q.max_rounds == 5 and q.agents == agents
