"""Plugins built from a scenario, and the validate-time checks that they serve its space.

Allocators, planners, repositioners and charging strategies are found by name in the registry
(:mod:`dispatch.registry`) and built with their scenario parameters here; whatever a plugin's
constructor raises becomes one PluginError naming the plugin, its parameters and the reason.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from dispatch import registry
from dispatch.errors import PluginError, ScenarioError
from dispatch.config import Scenario, _short
from dispatch.space import space_class

if TYPE_CHECKING:
    from dispatch.reposition import Repositioner

__all__ = ["check_repositioner", "check_runs", "describe", "make_charger", "make_plugin",
           "make_repositioner"]


def make_plugin(kind: str, name: str, params, *args):
    """Build an allocator or planner from its scenario parameters. Whatever its constructor
    raises (TypeError, ValueError, an error of a library it calls) becomes one PluginError
    naming the plugin, its parameters and the reason."""
    return _construct(kind, name, params, args, f"dispatch.{kind}_params")


def _construct(kind: str, name: str, params, args, key: str):
    """``make_plugin`` for any kind, the parameters read from the scenario table ``key``."""
    cls = registry.load(kind, name)
    params = dict(params)
    try:
        return cls(*args, **params)
    except Exception as e:  # a plugin's constructor may raise anything
        shown = ", ".join(f"{k} = {_short(v)}" for k, v in params.items()) or "none"
        reason = " ".join(str(e).split()) or type(e).__name__
        raise PluginError(f"{kind} {name!r} rejected its parameters ({key}: {shown}): "
                          f"{type(e).__name__}: {reason}") from e


def describe(allocator) -> str:
    """What an allocator says it ran, as a JSON object of strings (``"{}"`` if it says
    nothing): the optional ``describe() -> dict[str, str]`` method of an allocator plugin
    (e.g. a learned model's name, variant and checkpoint hash). It goes into the summary's
    ``allocator_info`` column and the ``dispatch.allocator_info`` Parquet metadata."""
    fn = getattr(allocator, "describe", None)
    info = fn() if callable(fn) else {}
    return json.dumps({str(k): str(v) for k, v in dict(info).items()}, sort_keys=True)


def make_repositioner(sc: Scenario, name: str) -> Repositioner:
    """The repositioner ``name`` built from its ``[reposition.<name>]`` table."""
    return _construct("repositioner", name, sc.reposition.params_of(name), (),
                      f"reposition.{name}")


def make_charger(sc: Scenario, name: str):
    """The charging strategy ``name`` built from its ``[charging.<name>]`` table."""
    return _construct("charger", name, sc.charging.params_of(name), (), f"charging.{name}")


def check_repositioner(sc: Scenario, name: str) -> None:
    """ScenarioError unless repositioner ``name`` serves the scenario's space (the kernel moves
    idle vehicles only in a space with the ``reposition`` feature, road networks: a voxel world
    takes passive ones, such as ``stay``)."""
    cls = registry.load("repositioner", name)
    space = sc.world.space
    serves = tuple(getattr(cls, "spaces", ("road",)))
    moves = "reposition" in space_class(space).features  # the kernel drives idle vehicles
    if space not in serves or (not moves and not getattr(cls, "passive", False)):
        key = "sweep.reposition" if sc.sweep.reposition else "reposition.policy"
        raise ScenarioError(sc.path, key, f"repositioner {name!r} moves vehicles on "
                                          f"{' and '.join(serves)} spaces, not this scenario's "
                                          f"{space} world (use 'stay' there)")


def check_runs(sc: Scenario, planners, repositioners=()) -> None:
    """Validate-time checks that need plugins or the space: every planner and repositioner
    serves the scenario's space, and the space's own (:meth:`dispatch.space.Space.check_runs`:
    a road network loads, a trace names only nodes it has)."""
    space = sc.world.space
    for name in repositioners:
        check_repositioner(sc, name)
    for name in planners:
        serves = getattr(registry.load("planner", name), "spaces", ("voxel",))
        if space not in serves:
            raise ScenarioError(sc.path, "dispatch.planner",
                                f"planner {name!r} serves {' and '.join(serves)} spaces, not "
                                f"this scenario's {space} world; {space} planners: "
                                f"{', '.join(registry.serving(space)) or 'none installed'}")
    space_class(space).check_runs(sc, planners)
