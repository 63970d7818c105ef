"""Plugin registry: allocators, planners and repositioners found by name through entry points.

Built-ins are registered in ``pyproject.toml`` under the same entry-point groups as third-party
plugins (``dispatch.allocators``, ``dispatch.planners``, ``dispatch.repositioners``), so both
are first-class. The table
below is only a fallback for a source tree that was never installed; it names modules as
strings, so the kernel still imports no concrete plugin.
"""

from __future__ import annotations

import importlib
import logging
from functools import cache
from importlib.metadata import entry_points

from dispatch.errors import PluginError

log = logging.getLogger(__name__)

GROUPS = {"allocator": "dispatch.allocators", "planner": "dispatch.planners",
          "repositioner": "dispatch.repositioners", "charger": "dispatch.chargers"}
_FALLBACK = {
    "allocator": {
        "hungarian": "allocators.hungarian:HungarianAllocator",
        "greedy": "allocators.greedy:GreedyAllocator",
        "fcfs": "allocators.fcfs:FcfsAllocator",
        "random": "allocators.randomized:RandomAllocator",
        "auction": "allocators.auction:AuctionAllocator",
        "magnnet": "allocators.magnnet.allocator:MagnnetAllocator",
        "local_hungarian": "allocators.local_hungarian:LocalHungarianAllocator",
    },
    "planner": {
        "astar": "planners.astar:AStarPlanner",
        "rrt_star": "planners.rrt_star:RRTStarPlanner",
        "rstar": "planners.rstar:RStarPlanner",
        "reservation": "planners.reservation:ReservationPlanner",
        "dijkstra": "planners.road:RoadPlanner",
    },
    "repositioner": {
        "stay": "repositioners.stay:StayRepositioner",
        "demand": "repositioners.demand:DemandRepositioner",
    },
    "charger": {
        "threshold": "chargers.threshold:ThresholdCharging",
        "idle": "chargers.idle:IdleCharging",
        "valley": "chargers.valley:ValleyCharging",
    },
}


@cache
def available(kind: str) -> dict[str, str]:
    """Installed plugins of a kind (``"allocator"``, ``"planner"`` or ``"repositioner"``):
    name -> ``module:attr``."""
    found = dict(_FALLBACK[kind])
    for ep in entry_points(group=GROUPS[kind]):
        found[ep.name] = ep.value
    return dict(sorted(found.items()))


def load(kind: str, name: str) -> type:
    """The plugin class registered as ``name``; PluginError lists what is installed."""
    plugins = available(kind)
    if name not in plugins:
        raise PluginError(
            f"unknown {kind} {name!r}; installed {kind}s: {', '.join(plugins) or 'none'}"
        )
    module, _, attr = plugins[name].partition(":")
    try:
        obj = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except Exception as e:  # a broken plugin must not take the others down with it
        log.warning("%s plugin %r (%s) failed to load: %s", kind, name, plugins[name], e)
        raise PluginError(f"{kind} plugin {name!r} ({plugins[name]}) failed to load: {e}") from e
    return obj


def serving(space: str) -> list[str]:
    """Names of the installed planners that serve ``space`` (``"voxel"`` or ``"road"``)."""
    names = []
    for name in available("planner"):
        try:
            if space in getattr(load("planner", name), "spaces", ("voxel",)):
                names.append(name)
        except PluginError:
            continue
    return names


def describe(kind: str) -> list[tuple[str, str, str, str]]:
    """``(name, target, spaces, first docstring line or load error)`` for each installed
    plugin (``spaces``: the spaces a planner or repositioner serves; empty for allocators)."""
    rows = []
    for name, target in available(kind).items():
        try:
            cls = load(kind, name)
            doc = (cls.__doc__ or "").strip().splitlines()
            spaces = ", ".join(getattr(cls, "spaces", ())) if kind != "allocator" else ""
            rows.append((name, target, spaces, doc[0] if doc else ""))
        except PluginError as e:
            rows.append((name, target, "", f"BROKEN: {e.__cause__}"))
    return rows
