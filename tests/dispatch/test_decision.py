"""The decision's pipeline (dispatch.decide.pipeline) step by step, and the run's wiring: the
wake-up
call made first and shared, a problem built on a small road run checked against the planner's
costs with the deadline applied by hand, the late and unreachable requests closed, the columns
renumbered, the allocator's generator untouched by building, and clear errors for a planner's
bad answer."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import simpy

from dispatch.api.comms import Hearing, comm_graph
from dispatch.api.problem import AgentViews
from dispatch.decide.dispatcher import Wakeup
from dispatch.decide.pipeline import keep_servable
from dispatch.decide.planner_costs import PlannerCosts, deadlines, lazy_costs, reject_late
from dispatch.decide.tally import Blame, Tally
from dispatch.errors import PluginError
from dispatch.plan.tasks import TaskState
from dispatch.run.sim import Simulation
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv


class _Book:
    """A task book's ``open`` and ``close``: what the steps read and call."""

    def __init__(self, tasks=()) -> None:
        self.open = {t.id: t for t in tasks}
        self.closed: list[tuple[int, TaskState]] = []

    def close(self, task, state) -> None:
        self.closed.append((task.id, state))
        self.open.pop(task.id, None)


def _task(i: int, *, offered: bool = False, deadline: float = math.inf):
    return SimpleNamespace(id=i, offered=offered, deadline=deadline, view=lambda: ("view", i))


# ----------------------------------------------------------------------------- wake-up


def test_wakeup_asks_once_until_rearmed_and_only_with_an_open_task_when_deciding_at_once():
    env = simpy.Environment()
    book = _Book()
    wake = Wakeup(env, book, always=False)
    wake()
    assert not wake.event.triggered  # nothing open: the call is dropped
    book.open[1] = _task(1)
    wake()
    first = wake.event
    assert first.triggered
    wake()  # idempotent until the dispatcher wakes
    assert wake.event is first
    wake.rearm()
    assert wake.event is not first and not wake.event.triggered
    batched = Wakeup(env, _Book(), always=True)  # a batching window or re-assignment
    batched()
    assert batched.event.triggered


# ----------------------------------------------------------------------------- steps


def test_deadlines_make_late_pairs_inf_with_the_slack_of_the_rule():
    cost = np.array([[5.0, 10.0], [20.0, 1.0]])
    got = deadlines(cost, np.array([105.0, 110.0 - 5e-10]), 100.0)
    assert got.tolist() == [[5.0, 10.0], [math.inf, 1.0]]  # 100 + 10 <= 110 - 5e-10 + 1e-9


def test_reject_late_closes_first_offers_only_and_leaves_late_columns_out():
    tasks = [_task(0), _task(1), _task(2, offered=True), _task(3)]
    book = _Book(tasks)
    cost = np.array([[1.0, np.inf, np.inf, np.inf], [np.inf, np.inf, np.inf, 2.0]])
    servable = np.array([True, True, True, False])  # task 3: unreachable, closed before
    got = reject_late(book, tasks, cost, servable)
    assert got.tolist() == [True, False, False, False]
    assert book.closed == [(1, TaskState.REJECTED)]  # task 2 was offered: it waits
    book = _Book(tasks)  # out_of_reach = "wait": the same columns left out, none closed
    assert reject_late(book, tasks, cost, servable, reject=False).tolist() == got.tolist()
    assert book.closed == []


def test_keep_servable_drops_columns_and_renumbers_insertions():
    class Kept:
        def __bool__(self):
            return True

        def kept(self, servable):
            return ("kept", servable.tolist())

    tasks = [_task(i) for i in range(3)]
    cost = np.arange(6.0).reshape(2, 3)
    exact = np.array([[True, False, True], [False, True, False]])
    servable = np.array([True, False, True])
    requests, views, c, e, ins = keep_servable(servable, tasks, cost, exact, Kept())
    assert [t.id for t in requests] == [0, 2] and views == (("view", 0), ("view", 2))
    assert c.tolist() == [[0.0, 2.0], [3.0, 5.0]] and e.tolist() == [[True, True], [False, False]]
    assert ins == ("kept", [True, False, True])
    assert keep_servable(servable, tasks, cost, None, {})[3:] == (None, {})


def _blame() -> Blame:
    env = simpy.Environment()
    tally = Tally(decisions=7)
    return Blame(env, "run-1", tally)


def test_planner_costs_name_the_planner_run_and_decision_for_a_bad_answer():
    class Wrong:
        name = "wrong"

        def costs(self, agents, tasks):
            return np.zeros((len(agents), len(tasks) + 1))

    class Broken:
        name = "broken"

        def costs(self, agents, tasks):
            raise KeyError("no such node")

    with pytest.raises(PluginError, match=r"planner 'wrong', run run-1, decision 7, t = 0 s: "
                                          r"costs\(\) must return a float array of shape \(2, 3\)"):
        PlannerCosts(Wrong(), False, _blame())([0, 1], [0, 1, 2])
    with pytest.raises(PluginError, match="planner 'broken'.*raised KeyError: 'no such node'"):
        PlannerCosts(Broken(), False, _blame())([0], [0])


def test_reachable_is_none_for_a_finite_matrix_and_refuses_nan():
    costs = PlannerCosts(SimpleNamespace(name="p"), False, _blame())
    assert costs.reachable(np.ones((2, 3))) is None
    got = costs.reachable(np.array([[1.0, np.inf, np.inf], [np.inf, np.inf, 2.0]]))
    assert got.tolist() == [True, False, True]
    with pytest.raises(PluginError, match="without nan"):
        costs.reachable(np.array([[1.0, np.nan]]))


def test_lazy_costs_need_bounds_a_total_cost_minimizer_and_no_plans(caplog):
    cfg = SimpleNamespace(lazy_costs=True)
    bounds = SimpleNamespace(name="p", lower_bounds=True)
    total = SimpleNamespace(name="a", minimizes_total_cost=True)
    assert lazy_costs(cfg, bounds, total, plans=False)
    assert not lazy_costs(SimpleNamespace(lazy_costs=False), bounds, total, plans=False)
    with caplog.at_level("WARNING", logger="dispatch.decide.planner_costs"):
        assert not lazy_costs(cfg, SimpleNamespace(name="p", lower_bounds=False), total, plans=False)
        assert not lazy_costs(cfg, bounds, total, plans=True)
    assert "computes no lower bounds" in caplog.text and "insertions exactly" in caplog.text


def test_hearing_broadcasts_without_a_range_and_builds_the_graph_with_one():
    class Space:
        read = 0

        def positions(self, locs):
            Space.read += 1
            return np.array([[float(x), 0.0, 0.0] for x in locs])

    agents = AgentViews.of(SimpleNamespace(id=k, loc=x) for k, x in enumerate((0.0, 5.0, 30.0)))
    comm, apos = Hearing(Space(), SimpleNamespace(range=None))(agents, 0.0)
    assert comm.shape == (3, 3) and comm.all() and comm.strides == (0, 0)
    assert Space.read == 0 and apos()[:, 0].tolist() == [0.0, 5.0, 30.0]  # read when asked
    comm, apos = Hearing(Space(), SimpleNamespace(range=10.0))(agents, 0.0)
    assert np.array_equal(comm, comm_graph(apos, 10.0)) and comm[0, 1] and not comm[1, 2]

    def blackout(comm, pos, now):
        return np.eye(len(pos), dtype=bool)

    comm, _ = Hearing(Space(), SimpleNamespace(range=None), blackout)(agents, 0.0)
    assert np.array_equal(comm, np.eye(3, dtype=bool))


# ----------------------------------------------------------------------------- a run


def _batched_run(tmp_path):
    """Two vehicles at the corners of a 5 x 2 block grid (100 m, 10 m/s), three requests at
    t = 0 (one with a deadline nobody makes), decided at t = 10 (batching window)."""
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node", "max_wait"],
              [(0.0, 1, 4, 300.0), (0.0, 8, 3, 300.0), (0.0, 5, 0, 8.0)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0), (1, 9)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"', allocator="hungarian",
                         network='network = "manhattan"\nblocks = [5, 2]\nblock = 100.0\n'
                                 'speed = 10.0', extra="batch_window = 10.0")
    [spec] = load_scenario(path).runs()
    from dispatch.run.runner import make_recorder

    return Simulation(spec, make_recorder(spec, tmp_path / "out"))


def test_the_run_is_wired_once_around_one_wakeup(tmp_path):
    sim = _batched_run(tmp_path)
    wake = sim.dispatcher.wakeup
    assert sim.operator.notify is wake and sim.source.notify is wake
    assert sim.dispatcher.tally is sim.tally and sim.dispatcher.pipeline.tally is sim.tally


def test_a_built_problem_is_the_planners_costs_with_the_deadlines_and_draws_nothing(tmp_path):
    sim = _batched_run(tmp_path)
    sim.env.run(until=5.0)  # released at 0, the decision waits for t = 10
    pipeline, book = sim.dispatcher.pipeline, sim.book
    assert len(book.open) == 3
    rng = sim.dispatcher.pipeline.problems.rng
    state = rng.bit_generator.state
    open_tasks = list(book.open.values())
    agents = sim.fleet.views(sim.fleet.idle_index(), 5.0)
    raw = sim.planner.costs(agents, tuple(t.view() for t in open_tasks))
    d = pipeline.build(5.0)
    assert rng.bit_generator.state == state  # the allocator's stream: drawn by allocators only
    late = [t for t in open_tasks if t.deadline == 8.0]
    assert [t.state for t in late] == [TaskState.REJECTED]  # first offer, nobody in time
    keep = [k for k, t in enumerate(open_tasks) if t.deadline != 8.0]
    assert [t.id for t in d.requests] == [open_tasks[k].id for k in keep]
    want = np.where(5.0 + raw <= np.array([t.deadline for t in open_tasks]) + 1e-9, raw, np.inf)
    assert np.array_equal(d.cost, want[:, keep])
    assert d.slots.tolist() == [0, 1] and d.holder == {} and not d.inserts
    problem = d.make(d.cost)
    assert problem.cost is not d.cost and np.array_equal(problem.cost, d.cost)
    assert problem.time == 5.0 and problem.rng is rng and problem.comm.all()
    assert sim.tally.cost_seconds > 0 and sim.tally.decisions == 0
