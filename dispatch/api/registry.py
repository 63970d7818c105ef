"""Plugin registry: allocators, planners, repositioners, chargers, fleet sizers and
command-line commands found by name through entry points, and what each plugin declares it
can do.

The entry points are the only list of plugins: built-ins are registered in ``pyproject.toml``
under the same groups as third-party plugins (``dispatch.allocators``, ``dispatch.planners``,
``dispatch.repositioners``, ``dispatch.chargers``, ``dispatch.acceptors``,
``dispatch.sizers``, ``dispatch.mode_choices``; ``dispatch.commands`` for commands such as
the :mod:`analysis` package's ``report`` and ``render``, see :mod:`dispatch.run.commands`), so both
are first-class and the kernel names no module of theirs.

Capabilities are declared, never probed. A plugin of the four kinds subclasses its contract's
base class (:data:`BASES`) and says what it can do with the boolean class attributes that base
class declares (``lower_bounds``, ``travel_times``, ``multi_request``, ...); what a capability
needs of it is a method of the base class it then defines (:data:`NEEDS`). :func:`load` reads
the declaration once into a :class:`Capabilities` record and refuses a plugin that declares a
capability without the method it needs; the kernel asks the record (:func:`capabilities`),
never the plugin object, what the plugin can do. What a scenario needs of its plugins is
checked against the records at validate time (:func:`dispatch.run.plugins.check_runs`).
"""

from __future__ import annotations

import difflib
import importlib
import logging
import re
from dataclasses import dataclass
from functools import cache
from importlib.metadata import EntryPoint, EntryPoints, entry_points

from dispatch.errors import PluginError

log = logging.getLogger(__name__)

GROUPS = {"allocator": "dispatch.allocators", "planner": "dispatch.planners",
          "repositioner": "dispatch.repositioners", "charger": "dispatch.chargers",
          "command": "dispatch.commands", "acceptor": "dispatch.acceptors",
          "sizer": "dispatch.sizers", "mode_choice": "dispatch.mode_choices"}

#: The base class a plugin of each kind subclasses (``"module:Class"``, imported when a plugin
#: of the kind is first loaded). Commands have none: they are plain classes of packages that
#: import nothing of ``dispatch`` (:mod:`dispatch.run.commands` reads them).
BASES = {"allocator": "dispatch.api.contracts:Allocator",
         "planner": "dispatch.api.contracts:Planner",
         "repositioner": "dispatch.api.repositioner:Repositioner",
         "charger": "dispatch.api.charger:ChargingStrategy",
         "acceptor": "dispatch.api.acceptor:Acceptor",
         "sizer": "dispatch.api.sizer:Sizer",
         "mode_choice": "dispatch.api.mode_choice:ModeChoice"}

#: The methods of its contract a plugin declaring a capability must define itself (the base
#: class's are there to document them; the kernel calls them only on plugins that declare it).
NEEDS: dict[str, tuple[str, ...]] = {
    "lower_bounds": ("bounds", "exact"),
    "travel_times": ("between",),
    "reservation_aware": ("plan_timed",),
}
#: The spaces a reservation-aware planner may serve: timed execution reserves their cells
#: (:class:`dispatch.plan.traffic.Traffic`)
TIMED_SPACES = ("voxel",)


@dataclass(frozen=True)
class Capabilities:
    """What one plugin declares it can do, read once from its class attributes.

    ``spaces``: the kinds of space a planner or repositioner serves (empty for the kinds that
    serve any). Allocators: ``decentralized`` (agents decide from local information),
    ``minimizes_total_cost`` (a maximum-cardinality, minimum-total-cost answer, no rng: lazy
    exact costs may certify it), ``multi_request`` (several requests to one agent, with
    routes), ``variants`` (the variants it runs by name, ``magnnet:paper``). Planners:
    ``lower_bounds`` (``bounds`` and ``exact``), ``travel_times`` (``between``: shared rides,
    drop-off limits, the added_time objective, energy and multi-request allocators need it),
    ``reservation_aware`` (``plan_timed``: execution with reservations). Repositioners:
    ``passive`` (never moves a vehicle; the kernel never calls it). Acceptors: ``declines``
    (may decline an offer; ``always`` does not, and the kernel then skips the offer step).
    Fleet sizers (``dispatch.sizers``, :mod:`dispatch.api.sizer`): ``passive`` (never changes the
    fleet). The flags of other kinds are False."""

    kind: str
    name: str
    spaces: tuple[str, ...] = ()
    decentralized: bool = False
    minimizes_total_cost: bool = False
    multi_request: bool = False
    lower_bounds: bool = False
    travel_times: bool = False
    reservation_aware: bool = False
    passive: bool = False
    declines: bool = False
    variants: tuple[str, ...] = ()

    def declared(self) -> frozenset[str]:
        """The names of the capabilities it declares."""
        flags = {"decentralized": self.decentralized,
                 "minimizes_total_cost": self.minimizes_total_cost,
                 "multi_request": self.multi_request, "lower_bounds": self.lower_bounds,
                 "travel_times": self.travel_times, "reservation_aware": self.reservation_aware,
                 "passive": self.passive, "declines": self.declines}
        return frozenset(k for k, on in flags.items() if on)

    def serves(self, space: str) -> bool:
        """Whether the plugin works in a space of kind ``space``."""
        return not self.spaces or space in self.spaces


@cache
def _installed() -> EntryPoints:
    """Every installed entry point, read once per process: each reading of the installed
    distributions' entry points parses all of them, whichever group is asked for (several
    milliseconds with a hundred distributions), and a run asks for several groups."""
    return entry_points()


def entry_point_group(group: str) -> EntryPoints:
    """The installed entry points of ``group`` (``importlib.metadata.entry_points(group=...)``,
    from the one reading of :func:`_installed`)."""
    return _installed().select(group=group)


@cache
def _entry_points(kind: str) -> dict[str, EntryPoint]:
    """The entry points of a kind's group by name, sorted (of two with one name, the last
    found wins)."""
    found = {ep.name: ep for ep in entry_point_group(GROUPS[kind])}
    return dict(sorted(found.items()))


def available(kind: str) -> dict[str, str]:
    """Installed plugins of a kind (``"allocator"``, ``"planner"``, ``"repositioner"``,
    ``"charger"`` or ``"command"``): name -> ``module:attr``."""
    return {name: ep.value for name, ep in _entry_points(kind).items()}


def base_name(name: str) -> str:
    """The plugin of a named variant: ``magnnet`` for ``magnnet:paper`` (a variant is the
    plugin with its own parameters, ``[dispatch.allocator_params."magnnet:paper"]``)."""
    return name.partition(":")[0]


def undeclared_variant(name: str) -> str | None:
    """None when the allocator name ``name`` is plain or a variant its plugin declares (it runs
    by name, :attr:`dispatch.api.contracts.Allocator.variants`); else what the plugin does declare,
    in words for an error (``'magnnet' declares the variants match, paper, …``, ``'hungarian'
    declares no variants``): such a variant needs its own parameter table."""
    base, _, variant = name.partition(":")
    if not variant:
        return None
    declared = declaration("allocator", base).variants
    if variant in declared:
        return None
    return f"{base!r} declares " + (f"the variants {', '.join(declared)}" if declared else
                                    "no variants")


def unknown_parameter(cls, params) -> tuple[str, str] | None:
    """The first name of ``params`` (a mapping or pairs) that the constructor of ``cls`` does
    not take, and why in words (``takes no parameter 'x' (did you mean 'y'?); its parameters:
    ...``, to follow the plugin's name); None where it takes them all, takes ``**kwargs``, or
    has no signature to read."""
    import inspect

    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        return None
    ps = list(sig.parameters.values())
    if any(p.kind is p.VAR_KEYWORD for p in ps):
        return None
    names = [p.name for p in ps if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    for k in dict(params):
        if k not in names:
            close = difflib.get_close_matches(str(k), names, n=1, cutoff=0.6)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            return str(k), (f"takes no parameter {str(k)!r}{hint}; its parameters: "
                            f"{', '.join(names) or 'none'}")
    return None


def unknown(kind: str, name: str) -> str:
    """``unknown allocator 'hungrian' (did you mean 'hungarian'?); installed allocators: ...``"""
    plugins = available(kind)
    close = difflib.get_close_matches(base_name(name), list(plugins), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    # every kind ships plugins of its own: none at all means the install's metadata is older
    # than the kind (an editable install made before it), not a misspelt name
    stale = "" if plugins else " (reinstall the project, e.g. `pip install -e .`, to register them)"
    return (f"unknown {kind} {name!r}{hint}; installed {kind}s: "
            f"{', '.join(plugins) or 'none'}{stale}")


def load(kind: str, name: str) -> type:
    """The plugin class registered as ``name`` (a named variant ``name:variant`` loads
    ``name``), its declaration checked (:func:`capabilities`); PluginError lists what is
    installed and suggests a close name, or says why the plugin cannot be used."""
    plugins = _entry_points(kind)
    name = base_name(name)
    if name not in plugins:
        raise PluginError(unknown(kind, name))
    ep = plugins[name]
    try:
        cls = ep.load()
    except Exception as e:  # a broken plugin must not take the others down with it
        log.warning("%s plugin %r (%s) failed to load: %s", kind, name, ep.value, e)
        raise PluginError(f"{kind} plugin {name!r} ({ep.value}) failed to load: {e}") from e
    if kind in BASES:
        _declared(kind, name, cls)
    return cls


def capabilities(kind: str, plugin) -> Capabilities:
    """What ``plugin`` (a plugin class of ``kind``, or one built: its constructor may withdraw
    a capability its parameters do not allow, as ``hungarian`` with a learned value does
    ``minimizes_total_cost``) declares it can do. PluginError, naming the plugin and the
    capability, when it does not subclass its kind's base class or declares a capability
    without defining the method it needs."""
    cls = plugin if isinstance(plugin, type) else type(plugin)
    base = _base(kind)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise PluginError(f"{kind} {cls.__qualname__} from {cls.__module__} does not subclass "
                          f"{base.__module__}.{base.__qualname__}: a plugin declares what it "
                          f"can do there")
    p = plugin
    if kind == "allocator":
        caps = Capabilities(kind, p.name, decentralized=bool(p.decentralized),
                            minimizes_total_cost=bool(p.minimizes_total_cost),
                            multi_request=bool(p.multi_request),
                            variants=tuple(str(v) for v in p.variants))
    elif kind == "planner":
        caps = Capabilities(kind, p.name, tuple(p.spaces), lower_bounds=bool(p.lower_bounds),
                            travel_times=bool(p.travel_times),
                            reservation_aware=bool(p.reservation_aware))
    elif kind == "repositioner":
        caps = Capabilities(kind, p.name, tuple(p.spaces), passive=bool(p.passive))
    elif kind == "acceptor":
        caps = Capabilities(kind, p.name, declines=bool(p.declines))
    elif kind == "sizer":
        caps = Capabilities(kind, p.name, passive=bool(p.passive))
    else:
        caps = Capabilities(kind, p.name)
    if caps.reservation_aware and set(caps.spaces) - set(TIMED_SPACES):
        raise PluginError(f"{kind} {caps.name or cls.__qualname__!r} declares reservation_aware"
                          f" but serves {', '.join(caps.spaces)}: reservations are kept in the "
                          f"cells of a space of {', '.join(TIMED_SPACES)}")
    mro = cls.__mro__
    own = mro[:mro.index(base)]  # the classes whose definitions win over the base class's
    for flag, methods in NEEDS.items():
        if flag not in caps.declared():
            continue
        for method in methods:
            if not any(method in vars(k) for k in own):
                raise PluginError(f"{kind} {caps.name or cls.__qualname__!r} declares {flag} "
                                  f"but does not define {method}() (what {flag} needs)")
    return caps


def declaration(kind: str, name: str) -> Capabilities:
    """What the plugin registered as ``name`` declares (:func:`load` loads and checks it)."""
    return _declared(kind, base_name(name), load(kind, name))


@cache
def _declared(kind: str, name: str, cls: type) -> Capabilities:
    """:func:`capabilities` of a loaded class, once per class; its errors name the plugin as
    the registry knows it."""
    try:
        return capabilities(kind, cls)
    except PluginError as e:
        raise PluginError(f"{kind} plugin {name!r} ({available(kind)[name]}) is refused: {e}") \
            from None


@cache
def _base(kind: str) -> type:
    module, _, name = BASES[kind].partition(":")
    return vars(importlib.import_module(module))[name]


def serving(space: str) -> list[str]:
    """Names of the installed planners that serve ``space`` (``"voxel"`` or ``"road"``)."""
    names = []
    for name in available("planner"):
        try:
            if declaration("planner", name).serves(space):
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

    module = sys.modules.get(cls.__module__)
    for doc in (cls.__dict__.get("__doc__"), module.__doc__ if module is not None else None):
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
            spaces = ", ".join(declaration(kind, name).spaces) if kind in BASES else ""
            rows.append((name, target, spaces, summary_line(cls, kind)))
        except PluginError as e:
            # a load error: what the import raised; a refused declaration: the refusal
            rows.append((name, target, "", f"BROKEN: {e.__cause__ or e}"))
    return rows
