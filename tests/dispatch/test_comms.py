"""The communication model: the graph, broadcasts with loss, the [comms] scenario section, the
decision rounds under local knowledge, and latency in the simulation."""

from __future__ import annotations

import dataclasses
import math
import random

import numpy as np
import pytest

from allocators.greedy import GreedyAllocator
from allocators.randomized import RandomAllocator
from dispatch.api import registry
from dispatch.api.comms import (Channel, comm_graph, components, diameter, hop_distances,
                                neighbours, relay_needed)
from dispatch.api.decentralized import DecentralizedAllocator, run_rounds
from dispatch.api.problem import Allocation, Bid
from dispatch.config.comms import CommsConfig
from dispatch.errors import PluginError, ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.allocators.helpers import assert_valid, make_problem, random_problem
from tests.dispatch.test_determinism import bitwise


def _installed(name: str):
    """The allocator class registered as ``name``, or None (MAGNNET is issue 4: until it is
    installed, its part of these tests is skipped)."""
    if name not in registry.available("allocator"):
        return None
    try:
        return registry.load("allocator", name)
    except PluginError:
        return None


MagnnetAllocator = _installed("magnnet")
NO_MAGNNET = "needs the magnnet allocator (its entry point: pip install -e .)"


def line(n: int) -> np.ndarray:
    c = np.eye(n, dtype=bool)
    i = np.arange(n - 1)
    c[i, i + 1] = c[i + 1, i] = True
    return c


def with_comm(problem, comm, loss=0.0):
    return dataclasses.replace(problem, comm=np.asarray(comm, dtype=bool), loss=loss)


# ----------------------------------------------------------------------------- the graph


def test_comm_graph_links_agents_within_range_inclusive():
    pos = [(0, 0, 0), (3, 4, 0), (6, 8, 0), (0, 0, 20)]
    g = comm_graph(pos, 5.0)
    assert g.dtype == bool and g.shape == (4, 4)
    assert (g == g.T).all() and g.diagonal().all()
    assert g[0, 1] and g[1, 2]  # exactly 5 m apart: linked
    assert not g[0, 2] and not g[0, 3] and not g[2, 3]
    assert comm_graph(pos, None).all()
    assert comm_graph(pos, math.inf).all()
    assert (comm_graph(pos, 0.0) == np.eye(4, dtype=bool)).all()
    assert comm_graph(np.zeros((0, 3)), 3.0).shape == (0, 0)
    with pytest.raises(ValueError, match="range"):
        comm_graph(pos, -1.0)


def test_components_hops_and_diameter():
    g = line(5)
    g2 = np.zeros((7, 7), dtype=bool)
    g2[:5, :5] = g
    g2[5:, 5:] = True
    count, labels = components(g2)
    assert count == 2 and len(set(labels[:5])) == 1 and labels[5] == labels[6] != labels[0]
    d = hop_distances(g2)
    assert d[0, 4] == 4 and d[1, 3] == 2 and d[0, 0] == 0 and d[0, 5] == -1
    assert diameter(g) == 4 and diameter(np.ones((3, 3), bool)) == 1
    assert diameter(np.eye(1, dtype=bool)) == 0
    assert not neighbours(g).diagonal().any()


def test_relay_needed_is_self_pruning():
    assert not relay_needed(np.ones((5, 5), bool)).any()  # complete graph: nobody relays
    need = relay_needed(line(4))
    # after 0's broadcast, 1 must pass it on to 2; after 1's, 0 has nobody new but 2 has 3
    assert need[0, 1] and need[1, 2] and need[2, 1] and need[3, 2]
    assert not need[1, 0] and not need[2, 3]
    assert not need[0, 2] and not need[0, 3]  # 2 and 3 do not hear 0 at all
    star = np.eye(4, dtype=bool)
    star[0, :] = star[:, 0] = True
    need = relay_needed(star)
    assert need[1, 0] and not need[0, 1]  # the hub forwards a leaf's news, leaves never do


def test_comm_graph_and_relays_equal_the_dense_definitions_on_random_fleets():
    """The k-d tree graph and the float32 relay product give exactly the dense answers:
    distance <= range (boundary included) and need[a, b] = b hears a and has a neighbour a
    does not reach."""
    rng = np.random.default_rng(11)
    for trial in range(30):
        n = int(rng.integers(1, 60))
        pos = np.zeros((n, 3))
        pos[:, :2] = rng.integers(0, 40, (n, 2))  # integer grid: many distances exactly r
        r = float(rng.choice([0.0, 1.0, 3.0, 5.0, 10.0, 100.0]))
        d = np.linalg.norm(pos[:, None] - pos[None, :], axis=-1)
        dense = d <= r + 1e-9
        np.fill_diagonal(dense, True)
        adj = comm_graph(pos, r)
        assert np.array_equal(adj, dense)
        nb = adj & ~np.eye(n, dtype=bool)
        want = np.array([[nb[a, b] and bool((nb[b] & ~adj[a]).any()) for b in range(n)]
                         for a in range(n)], dtype=bool).reshape(n, n)
        assert np.array_equal(relay_needed(adj), want)


def test_channel_counts_broadcasts_and_drops_with_the_given_rng():
    g = np.ones((4, 4), bool)
    rng = np.random.default_rng(0)
    before = rng.bit_generator.state
    ch = Channel(g, 0.0, rng)
    got = ch.broadcast_all(np.arange(4))
    assert (got == neighbours(g)).all() and ch.transmissions == 4 and ch.receptions == 12
    assert rng.bit_generator.state == before  # no loss: nothing drawn
    lonely = Channel(np.eye(3, dtype=bool), 0.0, rng)
    assert lonely.broadcast(0).size == 0 and lonely.transmissions == 0
    lossy = Channel(np.ones((30, 30), bool), 0.3, np.random.default_rng(1))
    for _ in range(20):
        lossy.broadcast_all(np.arange(30))
    rate = lossy.receptions / (20 * 30 * 29)
    assert abs(rate - 0.7) < 0.02


# ----------------------------------------------------------------------------- scenarios


def test_comms_section_defaults_and_values(make_scenario):
    sc = load_scenario(make_scenario())
    assert sc.comms == CommsConfig() and sc.comms.unlimited
    assert (sc.comms.range, sc.comms.latency, sc.comms.loss) == (None, 0.0, 0.0)
    sc = load_scenario(make_scenario(extra="[comms]\nrange = 5\nlatency = 0.5\nloss = 0.25\n"))
    assert sc.comms == CommsConfig(range=5.0, latency=0.5, loss=0.25)
    assert isinstance(sc.comms.range, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sc.comms.range = 3.0  # type: ignore[misc]


@pytest.mark.parametrize(
    "body, key, reason",
    [
        ("range = -1.0", "comms.range", "must be >= 0"),
        ("range = 'far'", "comms.range", "must be a number"),
        ("latency = -0.1", "comms.latency", "must be >= 0"),
        ("loss = 1.0", "comms.loss", "must be < 1"),
        ("loss = -0.2", "comms.loss", "must be >= 0"),
        ("loss = true", "comms.loss", "must be a number"),
        ("rnage = 3.0", "comms.rnage", "unknown key"),
    ],
)
def test_bad_comms_section_names_file_key_and_reason(make_scenario, body, key, reason):
    path = make_scenario(extra=f"[comms]\n{body}\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert path.name in str(err) and err.key == key and reason in err.reason


# ----------------------------------------------------------------------------- local knowledge


def test_complete_graph_rounds_are_the_global_knowledge_rounds():
    """On a complete graph without loss nobody relays: messages are the requests, two hops a
    round, and the answer is the plain conflict-rule answer."""
    for seed in range(30):
        p = random_problem(seed, 6, 5)
        a = GreedyAllocator().allocate(p)
        assert a.messages == len(a.requests)
        assert a.hops == 2 * a.rounds
        assert len(a.agent_seconds) == 6


def test_no_links_greedy_still_assigns_every_task_through_the_arbiters():
    """Nobody hears anybody: agents learn that a task is taken only from the arbiter's answer,
    so stale requests lose (and count as conflicts), but every task is still assigned."""
    for seed in range(40):
        p = with_comm(random_problem(seed, 6, 6), np.eye(6, dtype=bool))
        for cls in (GreedyAllocator, RandomAllocator):
            a = cls().allocate(p)
            assert len(assert_valid(p, a)) == 6
            assert a.messages == len(a.requests)  # requests only: no neighbours, no relays
            assert sum(r.won for r in a.requests) == 6


def test_stale_request_loses_and_is_a_conflict():
    # Both agents prefer task 0; agent 0 is cheaper and wins in round 0; agent 1 (alone, no
    # radio) asked for it at the same time, loses, then takes task 1.
    cost = np.array([[1.0, 5.0], [2.0, 3.0]])
    p = with_comm(make_problem(cost), np.eye(2, dtype=bool))
    a = GreedyAllocator().allocate(p)
    assert sorted(a.pairs) == [(100, 500), (101, 501)]
    assert a.conflicted_tasks() == {500}
    # A request in a later round for a task won earlier is a conflict too.
    late = Allocation(pairs=((100, 500),), requests=(Bid(0, 100, 500, 1.0, True),
                                                     Bid(2, 101, 500, 2.0, False)))
    assert late.conflicted_tasks() == {500}


def test_news_travels_one_hop_per_round_on_a_line():
    """Line 0-1-2-3. Agents 0 and 3 both want task 0 first (0 is cheaper); agent 3 only hears
    agent 2. Agent 3 loses task 0 at the arbiter in round 0 and takes task 1 in round 1."""
    cost = np.array([
        [1.0, 9.0, 9.0, 9.0],
        [9.0, 9.0, 1.0, 9.0],
        [9.0, 9.0, 9.0, 1.0],
        [2.0, 3.0, 9.0, 9.0],
    ])
    p = with_comm(make_problem(cost), line(4))
    a = GreedyAllocator().allocate(p)
    assert sorted(a.pairs) == [(100, 500), (101, 502), (102, 503), (103, 501)]
    assert a.rounds == 2
    # round 0: four requests; 1 and 2 each relay what they heard from an edge agent (2 relays
    # from agents without a request of their own in round 1); round 1: agent 3's request.
    assert len(a.requests) == 5
    assert a.messages == 5 + 2


def test_loss_draws_only_from_problem_rng_and_is_reproducible():
    p0 = random_problem(3, 8, 8)
    comm = comm_graph(np.random.default_rng(3).uniform(0, 30, (8, 3)), 12.0)
    np.random.seed(0)
    random.seed(0)
    first = GreedyAllocator().allocate(with_comm(p0, comm, loss=0.3))
    np.random.seed(1)
    random.seed(1)
    again = GreedyAllocator().allocate(with_comm(random_problem(3, 8, 8), comm, loss=0.3))
    assert first == again


def test_problem_checks_comm_shape_and_loss():
    p = random_problem(0, 3, 2)
    with pytest.raises(ValueError, match="comm has shape"):
        dataclasses.replace(p, comm=np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="loss"):
        dataclasses.replace(p, loss=1.0)
    with pytest.raises(ValueError, match="latency"):
        dataclasses.replace(p, latency=-1.0)


# ----------------------------------------------------------------------------- tiny range


@pytest.mark.parametrize("cls", [GreedyAllocator, RandomAllocator])
def test_range_so_small_nobody_talks_still_gives_valid_allocations(cls):
    rng = np.random.default_rng(11)
    for seed in range(60):
        n, m = (int(x) for x in rng.integers(1, 9, 2))
        p = with_comm(random_problem(seed, n, m, p_inf=0.2), np.eye(n, dtype=bool), loss=0.2)
        a = cls().allocate(p)
        pairs = assert_valid(p, a)
        busy = {x for x, _ in pairs}
        taken = {t for _, t in pairs}
        for x in set(range(n)) - busy:  # maximal: no idle agent with a feasible open task
            for t in set(range(m)) - taken:
                assert not np.isfinite(p.cost[x, t])


@pytest.mark.skipif(MagnnetAllocator is None, reason=NO_MAGNNET)
def test_magnnet_with_no_links_gives_a_valid_allocation():  # pragma: no cover - until issue 4
    for seed in range(20):
        p = with_comm(random_problem(seed, 6, 6), np.eye(6, dtype=bool))
        assert_valid(p, MagnnetAllocator().allocate(p))


# ----------------------------------------------------------------------------- simulation

COMMS_ALLOCATORS = ["hungarian", "greedy", "random", "auction",
                    pytest.param("magnnet", marks=pytest.mark.skipif(MagnnetAllocator is None,
                                                                     reason=NO_MAGNNET))]


@pytest.mark.parametrize("allocator", COMMS_ALLOCATORS)
def test_simulation_with_tiny_range_loss_and_latency(make_scenario, allocator):
    """Nobody can talk (range 0.1 m), half the receptions lost, 0.5 s per hop: every run still
    ends with every task in one terminal state, and decisions take hops * latency seconds."""
    path = make_scenario(
        fleet={"agents": 5}, tasks={"source": "static", "count": 5, "ground_fraction": 1.0},
        dispatch={"allocator": allocator},
        extra="[comms]\nrange = 0.1\nlatency = 0.5\nloss = 0.5\n",
    )
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    s = r.summary
    assert s["tasks_completed"] == s["n_tasks"] == 5
    dec = r.tables["decisions"].to_pandas()
    assert (dec.comm_delay == dec.hops * 0.5).all()
    assert s["comm_delay"] == pytest.approx(dec.comm_delay.sum())
    assert (dec.comm_components == dec.n_idle).all()  # nobody linked
    tasks = r.tables["tasks"].to_pandas()
    events = r.tables["events"].to_pandas()
    first = dec.iloc[0]
    if allocator == "hungarian":
        assert first.hops == 0 and s["comm_delay"] == 0.0
    else:
        assert first.hops > 0
        # the first hand-out waits for the deliberation
        first_assign = events[events.event == "assign"].t.min()
        assert first_assign == pytest.approx(first.t + first.comm_delay)
    assert dec.n_assigned.sum() == (tasks.agent_id >= 0).sum()


def test_tasks_that_expire_while_agents_deliberate_are_not_handed_out(make_scenario):
    path = make_scenario(
        fleet={"agents": 3}, tasks={"source": "static", "count": 3, "ttl": 1.0,
                                    "ground_fraction": 1.0},
        dispatch={"allocator": "greedy"},
        extra="[comms]\nlatency = 2.0\n",
    )
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    tasks = r.tables["tasks"].to_pandas()
    assert (tasks.state == "expired").all()
    assert (tasks.agent_id == -1).all()
    events = r.tables["events"].to_pandas()
    assert not (events.event == "assign").any()
    # the run ended (every task expired) before the hand-out: no decision was completed, and
    # the summary counts only completed decisions
    assert r.summary["decisions"] == r.tables["decisions"].num_rows == 0
    assert r.summary["rounds"] == r.summary["messages"] == 0


def test_same_seed_same_run_under_loss(make_scenario):
    path = make_scenario(
        fleet={"agents": 4}, tasks={"source": "periodic", "interval": 1.5, "count": 8},
        dispatch={"allocator": "auction"}, extra="[comms]\nrange = 6.0\nloss = 0.3\n",
    )
    [spec] = load_scenario(path).runs()
    a, b = run_one(spec), run_one(spec)
    for name in ("tasks", "assignments", "events"):
        ta = a.tables[name].drop_columns(["alloc_seconds"]) if name == "assignments" \
            else a.tables[name]
        tb = b.tables[name].drop_columns(["alloc_seconds"]) if name == "assignments" \
            else b.tables[name]
        # bit for bit: Table.equals never finds NaN equal to NaN (tasks.dropoff_* are NaN)
        assert bitwise(ta).equals(bitwise(tb)), name


class _Cheapest(DecentralizedAllocator):
    """Each agent requests its cheapest task it believes open; ``steps`` claim exchanges."""

    def __init__(self, steps: int) -> None:
        self.steps = steps

    def claim_steps(self, problem):
        return self.steps

    def choose(self, problem, agents, open_tasks, round_):
        c = np.where(open_tasks[None, :], problem.cost[agents], np.inf)
        return np.where(np.isfinite(c).any(1), c.argmin(1), -1)


def test_claims_travel_one_hop_per_exchange_and_the_dearer_claim_yields():
    """Line 0-1-2; agents 0 and 2 both want task 0 (costs 5 and 3), agent 1 wants task 1.
    One exchange: 0 and 2 do not hear each other, both request task 0 (a conflict, 0 asks
    again in round 1). Two exchanges: agent 1 passes 2's cheaper claim on, 0 yields and, with
    tasks 0 and 1 claimed cheaper, takes task 2: one round, no conflict, 3 + 3 claim
    broadcasts, 3 requests, hops 2 + 2 (by hand)."""
    cost = np.array([[5.0, 8.0, 9.0], [9.0, 1.0, 9.0], [3.0, 9.0, 9.0]])
    comm = np.eye(3, dtype=bool) | np.eye(3, k=1, dtype=bool) | np.eye(3, k=-1, dtype=bool)
    p = dataclasses.replace(make_problem(cost), comm=comm)
    one = _Cheapest(1).allocate(p)
    assert one.conflicted_tasks() == {500} and one.rounds == 2
    two = _Cheapest(2).allocate(p)
    assert sorted(two.pairs) == [(100, 502), (101, 501), (102, 500)]
    assert two.conflicted_tasks() == set() and two.rounds == 1
    assert two.messages == 3 + 3 + 3 and two.hops == 2 + 2
    none = _Cheapest(0).allocate(p)
    assert none == run_rounds(p, _Cheapest(0).choose)


@pytest.mark.parametrize("steps", [1, 2, 3])
@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_a_claim_reaches_exactly_as_many_hops_as_there_are_exchanges(steps, d):
    """Line 0-1-...-d: agent 0 claims task 0 at cost 3, agent d at cost 5 (the agents between
    claim their own cheap tasks). Agent d yields in round 0 exactly when d <= steps, in both
    directions of the line (news never travels two hops in one exchange)."""
    n = d + 1
    cost = np.full((n, n), 9.0)
    for k in range(1, d):
        cost[k, k] = 1.0
    cost[0, 0], cost[d, 0], cost[d, d] = 3.0, 5.0, 6.0
    line = np.eye(n, dtype=bool) | np.eye(n, k=1, dtype=bool) | np.eye(n, k=-1, dtype=bool)
    for flip in (False, True):
        order = np.arange(n)[::-1] if flip else np.arange(n)
        p = dataclasses.replace(make_problem(cost[np.ix_(order, np.arange(n))]), comm=line)
        a = _Cheapest(steps).allocate(p)
        far = 100 + int(np.flatnonzero(order == d)[0])
        first = {q.agent_id: q.task_id for q in a.requests if q.round == 0}
        assert (first[far] == 500) == (d > steps)
