"""The plugin checks (dispatch.checks): every built-in plugin passes the checks; deliberately
broken plugins are caught by the check that names their bug; the documented allocator passes;
``dispatch check``;
a misbehaving plugin inside a run stops it with one line naming the plugin, run and decision."""

from __future__ import annotations

import random
import re

import numpy as np
import pytest

from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem
from dispatch.api.registry import load
from dispatch.checks.allocators import check_allocator
from dispatch.checks.planners import check_planner
from dispatch.errors import AllocationError, PluginError
from dispatch.run import cli
from tests.conftest import ROOT

BUILTIN_ALLOCATORS = ["hungarian", "fcfs", "greedy", "random", "auction", "magnnet",
                      "local_hungarian"]
BUILTIN_PLANNERS = ["astar", "rrt_star", "rstar", "reservation", "dijkstra"]


@pytest.mark.parametrize("name", BUILTIN_ALLOCATORS)
def test_every_builtin_allocator_passes(name):
    report = check_allocator(load("allocator", name))
    assert report.ok, str(report)
    assert {r.name for r in report.results} == {"construct", "valid", "progress", "no-mutation",
                                                "deterministic", "rng"}


@pytest.mark.parametrize("name,params", [
    ("auction", {"bundle_size": 2}),  # found by the checker: CBBA bundles crashed on 0 tasks
    ("auction", {"bundle_size": 3, "time_scale": 5.0}),
    ("magnnet", {"partial": "match"}),
    ("magnnet", {"confidence": 0.0, "patience": 0}),
    ("local_hungarian", {"view": "component", "patience": 0}),
])
def test_builtin_allocators_with_parameters_pass(name, params):
    report = check_allocator(load("allocator", name), **params)
    assert report.ok, str(report)


@pytest.mark.parametrize("variant", ["paper", "paper_nb"])
def test_a_variant_that_serves_only_some_sizes_is_reported(variant):
    """The paper's variants ship checkpoints for N = M in (4, 8, 12, 20) only: the checker
    says so (an error, never a fallback to another model)."""
    report = check_allocator(load("allocator", "magnnet"), variant=variant)
    failed = {r.name: r.detail for r in report.failed()}
    assert set(failed) == {"valid"} and "no checkpoint" in failed["valid"]


@pytest.mark.parametrize("name", BUILTIN_PLANNERS)
def test_every_builtin_planner_passes(name):
    report = check_planner(load("planner", name))
    assert report.ok, str(report)


# ----------------------------------------------------------------------------- broken plugins


def _cheapest(problem):
    cost = problem.cost.copy()
    pairs = []
    while np.isfinite(cost).any():
        a, t = np.unravel_index(np.argmin(cost), cost.shape)
        pairs.append((int(a), int(t)))
        cost[a, :] = np.inf
        cost[:, t] = np.inf
    return pairs


class IndexPairs(Allocator):
    name = "index_pairs"

    def allocate(self, problem):
        return Allocation(pairs=tuple(_cheapest(problem)))  # indices, not ids


class DuplicateTask(Allocator):
    name = "duplicate_task"

    def allocate(self, problem):
        if problem.n_tasks == 0:
            return Allocation(pairs=())
        t = problem.tasks[0].id
        return Allocation(pairs=tuple((a.id, t) for a in problem.agents))


class InfPair(Allocator):
    name = "inf_pair"

    def allocate(self, problem):
        n = min(problem.n_agents, problem.n_tasks)
        return Allocation.centralized(problem, [(i, i) for i in range(n)])  # ignores inf


class GlobalRng(Allocator):
    name = "global_rng"

    def allocate(self, problem):
        pairs = _cheapest(problem)
        random.shuffle(pairs)  # the global state: harmless here, but the order ...
        keep = [p for p in pairs if np.random.random() < 0.7]  # ... and this is not
        return Allocation.centralized(problem, keep or pairs[:1])


class Unseeded(Allocator):
    name = "unseeded"

    def allocate(self, problem):
        rng = np.random.default_rng()
        pairs = _cheapest(problem)
        keep = [p for p in pairs if rng.random() < 0.5]
        return Allocation.centralized(problem, keep or pairs[:1])


class MakesWritable(Allocator):
    """Turns the read-only cost matrix writable again and crosses pairs out in it."""

    name = "makes_writable"

    def allocate(self, problem):
        cost = problem.cost
        cost.setflags(write=True)
        pairs = []
        while np.isfinite(cost).any():
            a, t = np.unravel_index(np.argmin(cost), cost.shape)
            pairs.append((int(a), int(t)))
            cost[a, :] = np.inf
            cost[:, t] = np.inf
        return Allocation.centralized(problem, pairs)


class SwapsCost(Allocator):
    """Mutates a copy and puts it in the (frozen) problem in place of the original."""

    name = "swaps_cost"

    def allocate(self, problem):
        cost = problem.cost.copy()
        cost[np.isfinite(cost)] = 0.0
        object.__setattr__(problem, "cost", cost)
        return Allocation.centralized(problem, _cheapest(problem))


class Raises(Allocator):
    name = "raises"

    def allocate(self, problem):
        if problem.n_agents == 0:
            raise ZeroDivisionError("no agents")
        return Allocation.centralized(problem, _cheapest(problem))


class Lazy(Allocator):
    name = "lazy"

    def allocate(self, problem):
        return Allocation(pairs=())


class WrongType(Allocator):
    name = "wrong_type"

    def allocate(self, problem):
        return [(a.id, t.id) for a, t in zip(problem.agents, problem.tasks)]


class Stateful(Allocator):
    """Answers differently on its second call (class-level state)."""

    name = "stateful"
    calls = 0

    def allocate(self, problem):
        Stateful.calls += 1
        pairs = _cheapest(problem)
        return Allocation.centralized(problem, pairs if Stateful.calls % 2 else pairs[:-1])


BROKEN = {
    IndexPairs: "valid", DuplicateTask: "valid", InfPair: "valid", GlobalRng: "rng",
    Unseeded: "deterministic", MakesWritable: "no-mutation", SwapsCost: "no-mutation",
    Raises: "valid", Lazy: "progress", WrongType: "valid", Stateful: "deterministic",
}


@pytest.mark.parametrize("cls,check", BROKEN.items(), ids=[c.__name__ for c in BROKEN])
def test_broken_allocator_is_caught(cls, check):
    report = check_allocator(cls)
    assert not report.ok
    failed = {r.name: r.detail for r in report.failed()}
    assert check in failed, str(report)
    assert "\n" not in failed[check]


def test_index_pairs_failure_says_ids_not_indices():
    detail = {r.name: r.detail for r in check_allocator(IndexPairs).failed()}["valid"]
    assert "not by index" in detail


def test_constructor_that_rejects_its_parameters():
    class Picky(Allocator):
        def __init__(self, k: int = 1) -> None:
            if k < 1:
                raise ValueError("k must be >= 1")

        def allocate(self, problem):
            return Allocation(pairs=())

    report = check_allocator(Picky, k=0)
    assert [r.name for r in report.results] == ["construct"] and not report.ok
    assert "k must be >= 1" in report.results[0].detail


def test_broken_planners_are_caught():
    from planners.astar import AStarPlanner

    class Negative(AStarPlanner):
        name = "negative"

        def costs(self, agents, tasks):
            return -super().costs(agents, tasks)

    class Noisy(AStarPlanner):
        name = "noisy"

        def costs(self, agents, tasks):
            return super().costs(agents, tasks) + np.random.random()

    class Transposed(AStarPlanner):
        name = "transposed"

        def costs(self, agents, tasks):
            return super().costs(agents, tasks).T

    for cls, check in ((Negative, "costs"), (Noisy, "rng"), (Transposed, "costs")):
        failed = {r.name for r in check_planner(cls).failed()}
        assert check in failed, (cls.__name__, failed)


# ------------------------------------------------------------------------- the documented example

#: The pages that show the whole ``CheapestFirst`` allocator: the plugin explanation (the old
#: README section) and the tutorial (a MyST-NB code cell).
PLUGIN_PAGES = ("docs/explanation/plugins.md", "docs/tutorials/plugin.md")


def documented_allocator(page):
    text = (ROOT / page).read_text(encoding="utf-8")
    (code,) = [b for b in re.findall(r"```(?:python|\{code-cell\} python)\n(.*?)```", text,
                                     re.DOTALL) if "class CheapestFirst" in b]
    scope: dict = {}
    exec(compile(code, page, "exec"), scope)  # noqa: S102 - the page's own code
    return code, scope["CheapestFirst"]


@pytest.mark.parametrize("page", PLUGIN_PAGES)
def test_documented_allocator_passes_the_checker(page):
    code, cls = documented_allocator(page)
    assert len(code.strip().splitlines()) <= 30
    report = check_allocator(cls)
    assert report.ok, str(report)
    assert not check_allocator(cls, max_pairs=0).ok  # its constructor rejects a bad value
    assert check_allocator(cls, max_pairs=2).ok


# ----------------------------------------------------------------------------- the CLI


def test_cli_check_builtin_allocator(capsys):
    assert cli.main(["check", "greedy"]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 7  # one line per check, then the verdict
    assert all(line.startswith("pass") for line in lines[:6])
    assert "passes every check" in lines[-1]


def test_cli_check_planner_with_param(capsys):
    assert cli.main(["check", "rstar", "--param", "w=2.0"]) == 0
    assert "passes every check" in capsys.readouterr().out


def test_cli_check_bad_param_and_unknown_name(capsys):
    assert cli.main(["check", "rstar", "--param", "w=0.5"]) == 1
    out = capsys.readouterr().out
    assert "FAIL construct" in out and "w (the suboptimality bound)" in out
    assert cli.main(["check", "no_such_plugin"]) == 2
    err = capsys.readouterr().err
    assert "no plugin named 'no_such_plugin'" in err and "(acceptors)" in err and "(sizers)" in err


@pytest.mark.parametrize("name,kind", [("always", "acceptor"), ("threshold", "acceptor"),
                                       ("logit", "acceptor"), ("fixed", "sizer"),
                                       ("utilization", "sizer")])
def test_cli_check_shipped_acceptors_and_sizers(capsys, name, kind):
    assert cli.main(["check", name, "--kind", kind]) == 0
    assert f"{kind} {name!r}" in capsys.readouterr().out


def test_broken_acceptors_and_sizers_are_caught():
    """Each check catches its failure: a non-bool answer, an acceptor declaring it never
    declines that declines, one reading the global random state; a sizer answering beyond its
    fleet, one that raises (the utilization sizer divided by zero when every request went
    unserved), a bad interval."""
    import random

    from dispatch.api.acceptor import Acceptor
    from dispatch.api.sizer import Sizer
    from dispatch.checks.acceptors import check_acceptor
    from dispatch.checks.sizers import check_sizer

    class Maybe(Acceptor):
        name = "maybe"

        def accept(self, offer, rng):
            return "yes"

    class Liar(Acceptor):
        name = "liar"
        declines = False

        def accept(self, offer, rng):
            return offer.wait < 600

    class Global(Acceptor):
        name = "global"

        def accept(self, offer, rng):
            return random.random() < 0.5

    class Greedy(Sizer):
        name = "greedy_sizer"

        def size(self, view):
            return view.on_duty + view.pool + 1

    class Divides(Sizer):
        name = "divides"

        def size(self, view):
            miss = view.unserved if view.unserved == view.unserved else 0.0
            return int(view.on_duty / (1.0 - miss))

    class Never(Sizer):
        name = "never"
        interval = 0.0

        def size(self, view):
            return view.on_duty

    def failed(report):
        return {r.name for r in report.results if not r.ok and not r.skipped}

    assert failed(check_acceptor(Maybe)) == {"valid"}
    assert failed(check_acceptor(Liar)) == {"declines"}
    assert failed(check_acceptor(Global)) >= {"rng"}
    assert failed(check_sizer(Greedy)) == {"valid"}
    assert failed(check_sizer(Divides)) == {"valid"}
    assert "ZeroDivisionError" in str(check_sizer(Divides).results)
    assert failed(check_sizer(Never)) == {"interval"}


# ----------------------------------------------------------------------------- inside a run


@pytest.mark.parametrize("allocator,error,words", [
    (IndexPairs(), AllocationError, "not by index"),
    (DuplicateTask(), AllocationError, "more than one agent"),
    (WrongType(), AllocationError, "not an Allocation"),
    (MakesWritable(), AllocationError, "made writable problem.cost"),
    (SwapsCost(), AllocationError, "replaced or made writable problem.cost"),
])
def test_misbehaving_allocator_in_a_run_is_one_line_naming_it(tiny_scenario, allocator, error,
                                                              words, monkeypatch):
    import dispatch.run.sim as sim_module
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    spec = load_scenario(tiny_scenario).runs()[0]
    real = sim_module.make_plugin
    monkeypatch.setattr(sim_module, "make_plugin", lambda kind, name, params, *args: allocator
                        if kind == "allocator" else real(kind, name, params, *args))
    with pytest.raises(error) as info:
        run_one(spec)
    msg = str(info.value)
    assert "\n" not in msg and words in msg
    assert f"allocator {allocator.name!r}" in msg
    assert re.search(rf"run {spec.run_id}, decision \d+, t = [0-9.e+-]+ s: ", msg), msg


def test_plugin_exception_in_the_loop_is_a_plugin_error(tiny_scenario, monkeypatch):
    """Not a traceback through simpy: the exception becomes a PluginError with the context."""
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario

    class Boom(Allocator):
        name = "boom"

        def allocate(self, problem: AllocationProblem):
            raise KeyError("lost")

    import dispatch.run.sim as sim_module

    real = sim_module.make_plugin
    monkeypatch.setattr(sim_module, "make_plugin", lambda kind, name, params, *args: Boom()
                        if kind == "allocator" else real(kind, name, params, *args))
    spec = load_scenario(tiny_scenario).runs()[0]
    with pytest.raises(PluginError, match=r"allocator 'boom', run tiny__hungarian__astar__n3__s0, "
                                          r"decision 0, t = 0 s: allocator raised KeyError"):
        run_one(spec)


@pytest.mark.parametrize("bug,words", [
    ("transposed", "costs() must return a float array of shape (3, 3)"),
    ("raises", "planner raised RuntimeError: no map"),
])
def test_misbehaving_planner_in_a_run_is_one_line_naming_it(make_scenario, monkeypatch, bug,
                                                            words):
    import dispatch.run.sim as sim_module
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario
    from planners.astar import AStarPlanner

    class Bad(AStarPlanner):
        name = "bad"

        def costs(self, agents, tasks):
            if bug == "raises":
                raise RuntimeError("no map")
            return np.zeros((len(tasks), len(agents) + 1))

    spec = load_scenario(make_scenario()).runs()[0]
    real = sim_module.make_plugin
    monkeypatch.setattr(sim_module, "make_plugin", lambda kind, name, params, *args:
                        Bad(*args) if kind == "planner" else real(kind, name, params, *args))
    with pytest.raises(PluginError) as info:
        run_one(spec)
    msg = str(info.value)
    assert "\n" not in msg and words in msg
    assert msg.startswith(f"planner 'bad', run {spec.run_id}, decision 0, t = 0 s: ")


@pytest.mark.parametrize("bug,words", [
    ("raises", "plan() for vehicle 0 -> (2, 2, 0) raised ValueError: no path today"),
    ("none", "gave no path from the vehicle's cell to the goal"),
    ("wrong start", "gave no path from the vehicle's cell to the goal"),
])
def test_misbehaving_plan_in_a_run_is_one_line_naming_it(make_scenario, monkeypatch, bug,
                                                         words, tmp_path):
    """plan() runs inside a vehicle's process: its failure is one PluginError line naming the
    planner, the run, the vehicle and the time (not a traceback through simpy)."""
    import dispatch.run.sim as sim_module
    from dispatch.run.runner import run_one
    from dispatch.scenario.load import load_scenario
    from planners.astar import AStarPlanner

    class Bad(AStarPlanner):
        name = "bad"

        def plan(self, agent, goal):
            if bug == "raises":
                raise ValueError("no path\ntoday")
            if bug == "none":
                return None
            return [(9, 9, 9), goal]

    (tmp_path / "t.csv").write_text("t,x,y,z\n0,2.5,2.5,0.5\n")
    path = make_scenario(fleet={"agents": 1, "uav_fraction": 0.0}, obstacles={"count": 0},
                         tasks={"source": "trace", "trace": "t.csv", "ground_fraction": None})
    spec = load_scenario(path).runs()[0]
    real = sim_module.make_plugin
    monkeypatch.setattr(sim_module, "make_plugin", lambda kind, name, params, *args:
                        Bad(*args) if kind == "planner" else real(kind, name, params, *args))
    with pytest.raises(PluginError) as info:
        run_one(spec)
    msg = str(info.value)
    assert "\n" not in msg and words in msg, msg
    assert msg.startswith(f"planner 'bad', run {spec.run_id}, t = 0 s: plan() for vehicle 0")


class AlwaysRaises(Allocator):
    name = "always_raises"

    def allocate(self, problem):
        raise RuntimeError("not written yet")


def test_checks_that_could_not_run_are_skipped_not_passed():
    """An allocator whose allocate always raises fails ``valid``; the checks that need an
    answer (progress, no-mutation, deterministic, rng) had none to look at: skipped, not
    passed, and the report is not ok."""
    report = check_allocator(AlwaysRaises)
    marks = {r.name: r.mark for r in report.results}
    assert marks == {"construct": "pass", "valid": "FAIL", "progress": "skip",
                     "no-mutation": "skip", "deterministic": "skip", "rng": "skip"}
    assert not report.ok
    assert "skip rng: not run: no case got past valid" in str(report)
    # raising on some problems only: the dependent checks pass, saying on how many they ran
    partial = {r.name: r for r in check_allocator(Raises).results}
    assert partial["valid"].mark == "FAIL" and partial["rng"].ok
    assert re.search(r"on the \d+ of \d+ cases that got past valid", partial["rng"].detail)


def test_repositioner_that_always_raises_is_not_passed():
    from dispatch.api.repositioner import Repositioner
    from dispatch.checks.repositioners import check_repositioner

    class Broken(Repositioner):
        name = "broken"

        def reposition(self, view):
            raise RuntimeError("no")

    marks = {r.name: r.mark for r in check_repositioner(Broken).results}
    assert marks["valid"] == "FAIL"
    assert {marks[k] for k in ("no-mutation", "deterministic", "rng")} == {"skip"}
