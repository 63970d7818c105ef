"""Declared capabilities: every shipped plugin loads with a consistent declaration; a plugin
that declares a capability without the method it needs, or that does not subclass its kind's
base class, is refused when the registry loads it; a planner that lacks a capability the
scenario needs is refused at validate time; every message names the plugin and the
capability."""

from __future__ import annotations

from importlib.metadata import EntryPoint

import numpy as np
import pytest

from dispatch.api import registry
from dispatch.api.contracts import Allocator, Planner
from dispatch.api.problem import Allocation
from dispatch.checks.allocators import check_allocator
from dispatch.checks.common import small_network
from dispatch.checks.planners import check_planner
from dispatch.errors import PluginError, ScenarioError
from dispatch.files.hourly import HourlyFactors
from dispatch.run.commands import Command
from dispatch.run.plugins import check_runs, travel_times_needed
from dispatch.scenario.load import load_scenario
from dispatch.space.congestion import CongestedPlanner
from planners.astar import AStarPlanner
from planners.road import RoadPlanner
from tests.dispatch.test_trips import SOURCES, road_scenario, write_csv

KINDS = ("allocator", "planner", "repositioner", "charger")


# ----------------------------------------------------------------------------- test plugins


class NoBounds(AStarPlanner):
    """Declares lower bounds; bounds and exact are A*'s (inherited: declared and defined)."""

    name = "no_bounds_ok"


class LiarBounds(Planner):
    """Declares lower bounds without computing any."""

    name = "liar_bounds"
    lower_bounds = True

    def costs(self, agents, tasks):
        return np.zeros((len(agents), len(tasks)))

    def plan(self, agent, goal):
        return [agent.loc, goal]


class HalfBounds(LiarBounds):
    """Declares lower bounds and defines ``bounds`` but not ``exact``."""

    name = "half_bounds"

    def bounds(self, agents, tasks):
        c = self.costs(agents, tasks)
        return c, np.ones(c.shape, bool)


class LiarRoutes(LiarBounds):
    """Declares travel times without ``between``."""

    name = "liar_routes"
    lower_bounds = False
    travel_times = True


class LiarTimed(LiarBounds):
    """Declares reservation-awareness without ``plan_timed``."""

    name = "liar_timed"
    lower_bounds = False
    reservation_aware = True


class NotAPlanner:
    """Has the methods but not the base class that declares what a planner can do."""

    name = "not_a_planner"
    spaces = ("road",)

    def costs(self, agents, tasks):
        return np.zeros((len(agents), len(tasks)))

    def plan(self, agent, goal):
        return [goal]


class SlowRoads(RoadPlanner):
    """A road planner that does not declare travel times (it routes agents to pickups only)."""

    name = "slow_roads"
    travel_times = False


class Withdraws(Allocator):
    """Minimizes the total cost unless built with ``adjusted``: then it withdraws the
    capability, as ``hungarian`` does with a learned value."""

    name = "withdraws"
    minimizes_total_cost = True

    def __init__(self, adjusted: bool = False) -> None:
        if adjusted:
            self.minimizes_total_cost = False

    def allocate(self, problem):
        return Allocation(pairs=())


TEST_PLUGINS = {"planner": (NoBounds, LiarBounds, HalfBounds, LiarRoutes, LiarTimed,
                            NotAPlanner, SlowRoads)}


@pytest.fixture
def installed(monkeypatch):
    """The registry with the test plugins above installed as entry points of their kind."""
    real = registry._entry_points

    def with_tests(kind: str) -> dict[str, EntryPoint]:
        found = dict(real(kind))
        for cls in TEST_PLUGINS.get(kind, ()):
            found[cls.name] = EntryPoint(cls.name, f"{__name__}:{cls.__name__}",
                                         registry.GROUPS[kind])
        return dict(sorted(found.items()))

    monkeypatch.setattr(registry, "_entry_points", with_tests)


# ----------------------------------------------------------------------------- shipped plugins


@pytest.mark.parametrize("kind", [*KINDS, "command"])
def test_every_shipped_plugin_loads(kind):
    names = registry.available(kind)
    assert names, f"no {kind} installed"
    for name in names:
        cls = registry.load(kind, name)
        if kind in registry.BASES:
            caps = registry.declaration(kind, name)
            assert caps.kind == kind and caps.name == name
            assert caps == registry.capabilities(kind, cls)


def test_the_shipped_plugins_declare_what_they_can_do():
    def declared(kind, name):
        return registry.declaration(kind, name).declared()

    assert declared("allocator", "hungarian") == {"minimizes_total_cost"}
    assert declared("allocator", "rtv") == {"multi_request"}
    assert declared("allocator", "fcfs") == set()
    for name in ("greedy", "random", "auction", "local_hungarian", "magnnet"):
        assert declared("allocator", name) == {"decentralized"}
    assert declared("planner", "astar") == {"lower_bounds"}
    assert declared("planner", "reservation") == {"lower_bounds", "reservation_aware"}
    assert declared("planner", "dijkstra") == {"travel_times"}
    assert declared("planner", "rrt_star") == declared("planner", "rstar") == set()
    assert declared("repositioner", "stay") == {"passive"}
    assert declared("repositioner", "demand") == set()
    assert registry.declaration("planner", "dijkstra").spaces == ("road",)
    assert registry.declaration("repositioner", "stay").serves("voxel")
    assert not registry.declaration("planner", "astar").serves("road")
    assert registry.declaration("allocator", "fcfs").serves("road")  # allocators: any space


def test_the_plugin_list_is_the_entry_points_only():
    """No second list of the built-in plugins in the kernel: what is installed is what the
    entry points say (pyproject.toml's for the built-ins)."""
    from importlib.metadata import entry_points

    for kind, group in registry.GROUPS.items():
        assert registry.available(kind) == {ep.name: ep.value
                                            for ep in sorted(entry_points(group=group),
                                                             key=lambda ep: ep.name)}


# ----------------------------------------------------------------------------- refused at load


@pytest.mark.parametrize("cls, capability, method", [
    (LiarBounds, "lower_bounds", "bounds"),
    (HalfBounds, "lower_bounds", "exact"),
    (LiarRoutes, "travel_times", "between"),
    (LiarTimed, "reservation_aware", "plan_timed"),
])
def test_a_declared_capability_without_its_method_is_refused_at_load(installed, cls,
                                                                      capability, method):
    with pytest.raises(PluginError) as info:
        registry.load("planner", cls.name)
    msg = str(info.value)
    assert f"planner plugin {cls.name!r}" in msg and "is refused" in msg
    assert f"declares {capability} but does not define {method}()" in msg
    assert "\n" not in msg
    # and the plugin checks say so, without running the planner
    report = check_planner(cls)
    assert [r.name for r in report.failed()] == ["construct"]
    assert capability in str(report)


def test_an_inherited_method_serves_the_declaration(installed):
    assert registry.load("planner", "no_bounds_ok") is NoBounds
    assert registry.declaration("planner", "no_bounds_ok").lower_bounds


def test_a_plugin_that_does_not_subclass_its_base_is_refused_at_load(installed):
    with pytest.raises(PluginError, match=r"planner plugin 'not_a_planner'.*is refused.*does "
                                          r"not subclass dispatch\.api\.contracts\.Planner"):
        registry.load("planner", "not_a_planner")
    report = check_allocator(NotAPlanner)  # as an allocator: not an Allocator either
    assert not report.ok and "dispatch.api.contracts.Allocator" in str(report)


def test_a_refused_plugin_is_listed_as_broken_with_its_reason(installed):
    rows = {name: doc for name, _, _, doc in registry.describe("planner")}
    assert rows["liar_routes"].startswith("BROKEN") and "travel_times" in rows["liar_routes"]
    assert not rows["dijkstra"].startswith("BROKEN")


def test_a_constructor_may_withdraw_a_capability():
    assert registry.capabilities("allocator", Withdraws).minimizes_total_cost
    assert registry.capabilities("allocator", Withdraws()).minimizes_total_cost
    assert not registry.capabilities("allocator", Withdraws(adjusted=True)).minimizes_total_cost


def test_a_congested_planner_declares_what_it_wraps():
    net = small_network()
    congested = CongestedPlanner(RoadPlanner(net), HourlyFactors((2.0,) * 24), lambda: 0.0)
    caps = registry.capabilities("planner", congested)
    assert caps.declared() == {"travel_times"} and caps.name == "dijkstra"
    assert congested.free_flow is congested.inner and congested.inner.free_flow is congested.inner


def test_a_command_without_its_parts_fails_to_load_and_says_what_it_lacks():
    class NoHelp:
        @staticmethod
        def add_arguments(p):
            pass

        def run(self, args, out):
            return 0

        @staticmethod
        def user_errors():
            return ()

    c = Command.loaded("nohelp", "my_pkg:NoHelp", NoHelp)
    assert c.cls is None and "'help'" in str(c.error) and "nohelp" in str(c.error)


# ----------------------------------------------------------------------------- scenario needs


@pytest.mark.parametrize("tasks, fleet, extra, key, what", [
    (SOURCES["static"], "agents = 2\ncapacity = 2", "", "fleet.capacity", "shared rides"),
    (SOURCES["periodic"] + "\nmax_delay = 300.0", "agents = 2", "", "tasks.max_delay",
     "drop-off delay limits"),
    (SOURCES["static"], "agents = 2", 'objective = "added_time"', "dispatch.objective",
     "added_time objective"),
])
def test_a_planner_lacking_what_the_scenario_needs_is_refused(installed, tmp_path, tasks,
                                                               fleet, extra, key, what):
    path = road_scenario(tmp_path, tasks=tasks, fleet=fleet, extra=extra)
    path.write_text(path.read_text().replace('planner = "dijkstra"', 'planner = "slow_roads"'))
    sc = load_scenario(path)
    assert [k for k, _ in travel_times_needed(sc)] == [key]
    with pytest.raises(ScenarioError) as info:
        check_runs(sc, ["slow_roads"])
    msg = str(info.value)
    assert key in msg and what in msg and "'slow_roads'" in msg and "travel_times" in msg
    check_runs(sc, ["dijkstra"])  # the planner that declares it serves the same scenario


def test_a_multi_request_allocator_needs_a_planner_with_travel_times(installed, tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(0.0, 1, 4)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         allocator="rtv")
    sc = load_scenario(path)
    need = travel_times_needed(sc, ["rtv"])
    assert [k for k, _ in need] == ["dispatch.allocator"] and "'rtv'" in need[0][1]
    assert travel_times_needed(sc, ["hungarian"]) == []
    with pytest.raises(ScenarioError, match=r"dispatch\.allocator.*'rtv'.*multi_request.*"
                                            r"travel_times; planner 'slow_roads' does not"):
        check_runs(sc, ["slow_roads"], allocators=["rtv"])
    check_runs(sc, ["slow_roads"], allocators=["hungarian"])


def test_dispatch_validate_refuses_it_in_one_line(installed, tmp_path, capsys):
    from dispatch.run.cli import main

    path = road_scenario(tmp_path, tasks=SOURCES["static"], fleet="agents = 2\ncapacity = 3")
    path.write_text(path.read_text().replace('planner = "dijkstra"', 'planner = "slow_roads"'))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "fleet.capacity" in err and "'slow_roads'" in err and "travel_times" in err


def test_batteries_need_a_planner_with_travel_times(installed, tmp_path):
    """The reserve counts a request's drive to its drop-off: the planner must time it."""
    from tests.dispatch.test_energy import grid

    sc = load_scenario(grid(tmp_path, "battery_kwh = 20.0", [(0.0, 2, 8)]))
    assert [k for k, _ in travel_times_needed(sc)] == ["fleet.energy"]
    with pytest.raises(ScenarioError, match=r"fleet\.energy.*batteries.*'slow_roads' does not"):
        check_runs(sc, ["slow_roads"])
    check_runs(sc, ["dijkstra"])


def test_a_declared_variant_runs_by_name_and_an_undeclared_one_needs_its_table(tmp_path):
    """``magnnet:paper`` builds magnnet with variant = "paper" (it was the default match model
    under the variant's name); a variant the plugin does not declare and the scenario does
    not make with its table is refused at validate time, naming what is declared."""
    from pathlib import Path

    from dispatch.run.plugins import check_variant, variant_params
    from dispatch.run.runner import run_one

    assert registry.declaration("allocator", "magnnet").variants == (
        "match", "paper", "paper_nb", "ppo")
    assert registry.declaration("allocator", "hungarian").variants == ()
    assert variant_params("magnnet:paper", ()) == (("variant", "paper"),)
    assert variant_params("magnnet:paper", (("variant", "match"),)) == (("variant", "match"),)
    assert variant_params("hungarian", (("x", 1),)) == (("x", 1),)
    paper = Path(__file__).resolve().parents[2] / "scenarios" / "paper_static.toml"
    sc = load_scenario(paper)
    spec, = sc.runs(allocator="magnnet:paper", agents=4, seed=0)
    info = run_one(spec, tmp_path / "out").summary["allocator_info"]
    assert '"variant": "paper"' in info and "paper_n4.pt" in info
    check_variant(sc, "magnnet:ppo")
    check_variant(sc, "hungarian")
    with pytest.raises(ScenarioError, match=r"'magnnet:nope'.*declares the variants match, "
                                            r"paper, paper_nb, ppo.*no \[dispatch\.allocator_"
                                            r"params\.\"magnnet:nope\"\] table"):
        check_variant(sc, "magnnet:nope")
    with pytest.raises(ScenarioError, match="'hungarian' declares no variants"):
        check_variant(sc, "hungarian:fast")
