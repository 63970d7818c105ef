"""Plugins built from a scenario, and the validate-time checks that they serve its space.

Allocators, planners, repositioners and charging strategies are found by name in the registry
(:mod:`dispatch.api.registry`) and built with their scenario parameters here; whatever a plugin's
constructor raises becomes one PluginError naming the plugin, its parameters and the reason.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from dispatch.api import registry
from dispatch.api.space import space_class
from dispatch.config.offers import AcceptorConfig
from dispatch.config.scenario import Scenario, _short
from dispatch.decide.offer_step import Offering
from dispatch.errors import PluginError, ScenarioError

if TYPE_CHECKING:
    import numpy as np

    from dispatch.api.repositioner import Repositioner
    from dispatch.decide.tally import Blame
    from dispatch.plan.tasks import TaskBook

__all__ = ["UnknownParameter", "check_repositioner", "check_runs", "describe", "make_acceptor",
           "make_charger", "make_mode_choice", "make_plugin", "make_repositioner", "make_sizer", "offering_for",
           "travel_times_needed"]


def make_plugin(kind: str, name: str, params, *args):
    """Build an allocator or planner from its scenario parameters (an allocator's declared
    variant named ``name:variant`` with ``variant`` set: :func:`variant_params`). Whatever
    its constructor raises (TypeError, ValueError, an error of a library it calls) becomes
    one PluginError naming the plugin, its parameters and the reason."""
    if kind == "allocator":
        params = variant_params(name, params)
    return _construct(kind, name, params, args, f"dispatch.{kind}_params")


def variant_params(name: str, params) -> tuple[tuple[str, Any], ...]:
    """An allocator's constructor parameters: ``params``, and for a name ``base:variant``
    whose plugin declares ``variant`` (:attr:`dispatch.api.contracts.Allocator.variants`)
    ``variant = "<variant>"`` unless ``params`` set it."""
    params = tuple(dict(params).items())
    variant = name.partition(":")[2]
    if variant and registry.undeclared_variant(name) is None and "variant" not in dict(params):
        params = (*params, ("variant", variant))
    return params


def check_variant(sc: Scenario, name: str, key: str = "dispatch.allocator") -> None:
    """ScenarioError unless a named variant ``base:variant`` means something: its plugin
    declares the variant, or the scenario has its table
    (``[dispatch.allocator_params."base:variant"]``). Plain names pass."""
    why = registry.undeclared_variant(name)
    if why is None or name in dict(sc.dispatch.allocator_tables):
        return
    raise ScenarioError(sc.path, key, f"allocator {name!r}: {why}, and the scenario has no "
                                      f"[dispatch.allocator_params.\"{name}\"] table to make one")


class UnknownParameter(PluginError):
    """A scenario parameter the plugin's constructor does not take (a typo): ``key.param:
    reason``, one line (``key``: the table it was read from)."""

    def __init__(self, key: str, param: str, reason: str) -> None:
        super().__init__(f"{key}.{param}: {reason}")
        self.param, self.reason = param, reason


def _construct(kind: str, name: str, params, args, key: str):
    """``make_plugin`` for any kind, the parameters read from the scenario table ``key``; a
    parameter its constructor does not take is an :class:`UnknownParameter`."""
    cls = registry.load(kind, name)
    params = dict(params)
    bad = registry.unknown_parameter(cls, params)
    if bad is not None:
        raise UnknownParameter(key, bad[0], f"{kind} {name!r} {bad[1]}")
    try:
        return cls(*args, **params)
    except Exception as e:  # a plugin's constructor may raise anything
        shown = ", ".join(f"{k} = {_short(v)}" for k, v in params.items()) or "none"
        reason = " ".join(str(e).split()) or type(e).__name__
        raise PluginError(f"{kind} {name!r} rejected its parameters ({key}: {shown}): "
                          f"{type(e).__name__}: {reason}") from e


def describe(allocator) -> str:
    """What an allocator says it ran (:meth:`dispatch.api.contracts.Allocator.describe`), as a
    JSON object of strings (``"{}"`` if it says nothing). It goes into the summary's
    ``allocator_info`` column and the ``dispatch.allocator_info`` Parquet metadata."""
    info = allocator.describe()
    return json.dumps({str(k): str(v) for k, v in dict(info).items()}, sort_keys=True)


def make_repositioner(sc: Scenario, name: str) -> Repositioner:
    """The repositioner ``name`` built from its ``[reposition.<name>]`` table."""
    return _construct("repositioner", name, sc.reposition.params_of(name), (),
                      f"reposition.{name}")


def make_charger(sc: Scenario, name: str):
    """The charging strategy ``name`` built from its ``[charging.<name>]`` table."""
    return _construct("charger", name, sc.charging.params_of(name), (), f"charging.{name}")


def make_acceptor(sc: Scenario):
    """The acceptor of ``[acceptor]`` built from its ``[acceptor.<name>]`` table."""
    a = sc.acceptor
    return _construct("acceptor", a.name, a.params, (), f"acceptor.{a.name}")


def make_sizer(sc: Scenario):
    """The fleet-sizing strategy of ``[fleet] sizing`` (given) built from
    ``[fleet.sizing_params]``."""
    return _construct("sizer", sc.fleet.sizing, sc.fleet.sizing_params, (),
                      "fleet.sizing_params")


def make_mode_choice(sc: Scenario):
    """The mode choice of ``[transit]`` built from its ``[transit.<mode_choice>]`` table."""
    t = sc.transit
    return _construct("mode_choice", t.mode_choice, t.params, (), f"transit.{t.mode_choice}")


def check_transit(sc: Scenario) -> None:
    """ScenarioError for ``[transit]`` with requests booked ahead: a rider's legs are timed
    from the moment they ask, so a trip booked for later is not planned by train."""
    if sc.transit is not None and sc.tasks.prebooked:
        raise ScenarioError(sc.path, "transit", "riders who book ahead ([tasks] "
                            "prebook_share, a trace's booked_at) are not combined with [transit]"
                            "; leave one of them out")


def check_repositioner(sc: Scenario, name: str) -> None:
    """ScenarioError unless repositioner ``name`` serves the scenario's space (the kernel moves
    idle vehicles only in a space with the ``reposition`` feature, road networks: a voxel world
    takes passive ones, such as ``stay``)."""
    caps = registry.declaration("repositioner", name)
    space = sc.world.space
    moves = "reposition" in space_class(space).features  # the kernel drives idle vehicles
    if not caps.serves(space) or (not moves and not caps.passive):
        key = "sweep.reposition" if sc.sweep.reposition else "reposition.policy"
        raise ScenarioError(sc.path, key, f"repositioner {name!r} moves vehicles on "
                                          f"{' and '.join(caps.spaces)} spaces, not this "
                                          f"scenario's {space} world (use 'stay' there)")


def travel_times_needed(sc: Scenario, allocators=()) -> list[tuple[str, str]]:
    """What in the scenario needs a planner that routes between any two locations
    (``travel_times``: the kernel times the stops of a plan with it): ``(key, what)`` pairs,
    empty when nothing does. ``allocators``: the names of the allocators that run."""
    t, need = sc.tasks, []
    if sc.fleet.pooled:
        key = "fleet.capacity" if sc.fleet.capacity > 1 else "fleet.start"
        need.append((key, "shared rides (a capacity above 1)"))
    if t.delay_limited:
        need.append(("tasks.max_delay", "drop-off delay limits"))
    if sc.dispatch.objective != "pickup_time":
        need.append(("dispatch.objective", f"the {sc.dispatch.objective} objective"))
    if sc.fleet.energy is not None:
        need.append(("fleet.energy", "batteries (a request's drive counts in the reserve)"))
    for name in allocators:
        if registry.declaration("allocator", name).multi_request:
            need.append(("dispatch.allocator", f"allocator {name!r} (multi_request: it routes "
                                               f"several requests per vehicle)"))
    return need


def check_runs(sc: Scenario, planners, repositioners=(), allocators=()) -> None:
    """Validate-time checks that need plugins or the space: every planner and repositioner
    serves the scenario's space, every planner declares what the scenario needs of it
    (:func:`travel_times_needed`), and the space's own
    (:meth:`dispatch.api.space.Space.check_runs`: a road network loads, a trace names only nodes
    it has). ``allocators``: the names of the allocators that run (their declarations may
    need more of the planner)."""
    space = sc.world.space
    for name in allocators:
        check_variant(sc, name)
    for name in repositioners:
        check_repositioner(sc, name)
    _check_breaks(sc, allocators)
    for name in allocators if sc.dispatch.reassign else ():
        if registry.declaration("allocator", name).multi_request:
            # (its routes are handed out only where no vehicle holds a task: with one that
            # does, every decision was dropped and came back at the same instant, forever)
            raise ScenarioError(sc.path, "dispatch.reassign",
                                f"re-assignment before pickup gives single tasks up; "
                                f"allocator {name!r} routes several requests per vehicle "
                                f"(multi_request): they do not go together")
    need = travel_times_needed(sc, allocators)
    for name in planners:
        caps = registry.declaration("planner", name)
        if not caps.serves(space):
            raise ScenarioError(sc.path, "dispatch.planner",
                                f"planner {name!r} serves {' and '.join(caps.spaces)} spaces, "
                                f"not this scenario's {space} world; {space} planners: "
                                f"{', '.join(registry.serving(space)) or 'none installed'}")
        if need and not caps.travel_times:
            key, what = need[0]
            raise ScenarioError(sc.path, key, f"{what}: the kernel routes between the stops "
                                              f"of plans, which needs a planner that declares "
                                              f"travel_times; planner {name!r} does not")
    space_class(space).check_runs(sc, planners)


def _check_breaks(sc: Scenario, allocators) -> None:
    """``[fleet.breaks]`` are planned into plans by the kernel's insertion: an allocator that
    routes several requests per vehicle would plan around them blind, and giving a task up
    (``[dispatch] reassign``) would drop a planned break with the plan."""
    if sc.fleet.breaks is None:
        return
    for name in allocators:
        if registry.declaration("allocator", name).multi_request:
            raise ScenarioError(sc.path, "fleet.breaks",
                                f"drivers' breaks are planned by the kernel's insertion; "
                                f"allocator {name!r} routes several requests per vehicle "
                                f"(multi_request) and cannot plan around them")
    if sc.dispatch.reassign:
        raise ScenarioError(sc.path, "fleet.breaks", "drivers' breaks and [dispatch] reassign "
                                                     "do not go together: giving a task up "
                                                     "drops the plan and its break")


def offering_for(sc, book: TaskBook, space, rng: np.random.Generator, blame: Blame
                 ) -> Offering | None:
    """``[acceptor]`` / ``[pricing]``: the run's offer step, or None where there is nothing
    to offer: the default configuration (no section), or an acceptor that declares it never
    declines without fares to record. ``rng``: the riders' answers' stream."""
    acc = sc.acceptor
    if sc.pricing is None and acc == AcceptorConfig():
        return None
    acceptor = make_acceptor(sc)
    if sc.pricing is None and not registry.capabilities("acceptor", acceptor).declines:
        return None
    # fares are of rides on a road network (the parser refuses [pricing] elsewhere)
    metres = space.path_metres if sc.pricing is not None else None
    return Offering(book, acceptor, rng, retries=acc.retries, pricing=sc.pricing, metres=metres,
                    blame=blame)
