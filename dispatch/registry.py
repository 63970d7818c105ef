"""Plugin registry: allocators, planners, repositioners, chargers and command-line commands
found by name through entry points.

Built-ins are registered in ``pyproject.toml`` under the same entry-point groups as third-party
plugins (``dispatch.allocators``, ``dispatch.planners``, ``dispatch.repositioners``,
``dispatch.chargers``; ``dispatch.commands`` for commands such as the :mod:`analysis`
package's ``report`` and ``render``, see :mod:`dispatch.commands`), so both are first-class.
The table
below is only a fallback for a source tree that was never installed; it names modules as
strings, so the kernel still imports no concrete plugin.
"""

from __future__ import annotations

import difflib
import importlib
import logging
import re
from functools import cache
from importlib.metadata import entry_points

from dispatch.errors import PluginError

log = logging.getLogger(__name__)

GROUPS = {"allocator": "dispatch.allocators", "planner": "dispatch.planners",
          "repositioner": "dispatch.repositioners", "charger": "dispatch.chargers",
          "command": "dispatch.commands"}
_FALLBACK = {
    "allocator": {
        "hungarian": "allocators.hungarian:HungarianAllocator",
        "greedy": "allocators.greedy:GreedyAllocator",
        "fcfs": "allocators.fcfs:FcfsAllocator",
        "random": "allocators.randomized:RandomAllocator",
        "auction": "allocators.auction:AuctionAllocator",
        "magnnet": "allocators.magnnet.allocator:MagnnetAllocator",
        "local_hungarian": "allocators.local_hungarian:LocalHungarianAllocator",
        "rtv": "allocators.rtv:RtvAllocator",
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
    "command": {
        "report": "analysis.commands:Report",
        "render": "analysis.commands:Render",
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


def base_name(name: str) -> str:
    """The plugin of a named variant: ``magnnet`` for ``magnnet:paper`` (a variant is the
    plugin with its own parameters, ``[dispatch.allocator_params."magnnet:paper"]``)."""
    return name.partition(":")[0]


def unknown(kind: str, name: str) -> str:
    """``unknown allocator 'hungrian' (did you mean 'hungarian'?); installed allocators: ...``"""
    plugins = available(kind)
    close = difflib.get_close_matches(base_name(name), list(plugins), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return (f"unknown {kind} {name!r}{hint}; installed {kind}s: "
            f"{', '.join(plugins) or 'none'}")


def load(kind: str, name: str) -> type:
    """The plugin class registered as ``name`` (a named variant ``name:variant`` loads
    ``name``); PluginError lists what is installed and suggests a close name."""
    plugins = available(kind)
    name = base_name(name)
    if name not in plugins:
        raise PluginError(unknown(kind, name))
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


_ROLE = re.compile(r":(?:[\w-]+:)*[\w-]+:`~?([^`<]*?)(?:\s*<[^>]*>)?`")
_LITERAL = re.compile(r"``([^`]*)``|`([^`]*)`")


def plain(text: str) -> str:
    """``text`` without reStructuredText / Sphinx markup: roles (``:func:`x```, ``:class:`~a.B```
    -> ``x``, ``B``) and literals (````x````) become their text; whitespace runs one space."""
    def role(m: re.Match) -> str:
        target = m.group(1).strip()
        return target.rpartition(".")[2] if m.group(0).count("`~") else target

    text = _ROLE.sub(role, text)
    text = _LITERAL.sub(lambda m: m.group(1) if m.group(1) is not None else m.group(2), text)
    return " ".join(text.split())


def summary_line(cls, kind: str) -> str:
    """A plugin's one-line description, plain text, never empty: the first paragraph of its
    class docstring (cut after its first sentence when long), else of its module's, else what
    it is (``allocator GreedyAllocator from my_pkg.greedy, no docstring``)."""
    import sys

    for doc in (cls.__dict__.get("__doc__"), getattr(sys.modules.get(cls.__module__), "__doc__",
                                                      None)):
        para = plain((doc or "").strip().split("\n\n")[0])
        if para:
            if len(para) > 160:
                head, dot, _ = para.partition(". ")
                para = head + "." if dot and len(head) < 160 else para[:157] + "..."
            return para
    return f"{kind} {cls.__qualname__} from {cls.__module__}, no docstring"


def describe(kind: str) -> list[tuple[str, str, str, str]]:
    """``(name, target, spaces, description or load error)`` for each installed plugin
    (``spaces``: the spaces a planner or repositioner serves; empty for allocators;
    the description: :func:`summary_line`)."""
    rows = []
    for name, target in available(kind).items():
        try:
            cls = load(kind, name)
            spaces = ", ".join(getattr(cls, "spaces", ())) if kind != "allocator" else ""
            rows.append((name, target, spaces, summary_line(cls, kind)))
        except PluginError as e:
            rows.append((name, target, "", f"BROKEN: {e.__cause__}"))
    return rows
