"""A command's runs, checked before the first of them starts: the scenario file with the command
line's overrides, the resource limits, the plugins each run names (built once with the
scenario's parameters) and the space they serve, so that a mistake stops with one line naming
the file and the key, not in the middle of a sweep."""

from __future__ import annotations

from dispatch.api.registry import load
from dispatch.errors import PluginError, ScenarioError


def checked_specs(args):
    """Parse the scenario and expand its runs, checking all that can be checked before a run:
    the file, the resource limits (unless ``--ignore-limits``), the plugins (each distinct allocator
    and planner is built once with the scenario's parameters) and the space they serve."""
    from dispatch.scenario.load import check_limits, load_scenario

    ignore = args.ignore_limits
    sc = load_scenario(args.scenario, ignore_limits=ignore, overrides=overrides(args))
    specs = sc.runs(allocator=args.allocator, planner=args.planner, agents=args.agents,
                    seed=args.seed, batch_window=args.batch_window)
    if not ignore:
        check_limits(sc, specs)
    allocators = sorted({s.allocator for s in specs})
    planners = sorted({s.planner for s in specs})
    repositioners = sorted({s.reposition for s in specs})
    for kind, names, given, swept, default in (
            ("allocator", allocators, args.allocator, sc.sweep.allocator, sc.dispatch.allocator),
            ("planner", planners, args.planner, sc.sweep.planner, sc.dispatch.planner),
            ("repositioner", repositioners, None, sc.sweep.reposition, sc.reposition.policy)):
        for name in names:
            try:
                load(kind, name)
            except PluginError as e:  # name the file and the key that names the plugin
                key = _key_of(kind, name, given, swept, default)
                raise PluginError(f"{sc.path}: {key}: {e}") from e
    from dispatch.run.plugins import check_runs

    check_runs(sc, planners, repositioners, allocators)
    build_plugins(sc, specs, ignore_limits=ignore)
    return sc, specs


def overrides(args) -> list[tuple[str, str, str]]:
    """The scenario keys the command line sets, as :func:`dispatch.scenario.load.load_scenario`
    takes them: ``--duration``, ``--capacity``, ``--batch-window``, then each ``--set`` in
    order (a later one wins)."""
    import math

    from dispatch.scenario.overrides import parse_set

    out = []
    duration = args.duration
    if duration is not None:
        if not math.isfinite(duration) or duration <= 0:
            raise ScenarioError(args.scenario, "--duration", f"must be a number of seconds > 0, "
                                                             f"got {duration!r}")
        out.append(("duration", repr(float(duration)), "run --duration"))
    if args.capacity is not None:
        out.append(("fleet.capacity", str(args.capacity), "--capacity"))
    window = args.batch_window
    if window is not None:
        if not math.isfinite(window):  # TOML has inf; the file's own check says >= 0
            raise ScenarioError(args.scenario, "--batch-window", f"must be a number of seconds "
                                                                 f">= 0, got {window!r}")
        out.append(("dispatch.batch_window", repr(float(window)), "--batch-window"))
    for item in args.overrides:
        out.append((*parse_set(item, args.scenario), "--set"))
    return out


def _key_of(kind: str, name: str, given: str | None, swept: tuple[str, ...],
            default: str) -> str:
    """Where plugin ``name`` of ``kind`` came from: its command-line option (``given``), the
    sweep's list (``swept``) or the file's key (whose value is ``default``)."""
    if given == name:
        return f"--{kind}"
    if name in swept:
        return f"sweep.{kind if kind != 'repositioner' else 'reposition'}"
    if kind == "repositioner":
        return "reposition.policy"
    return f"dispatch.{kind}" if name == default else kind


def build_plugins(sc, specs, *, ignore_limits: bool = False) -> None:
    """Build every distinct allocator and planner of ``specs`` once (constructors are cheap;
    a planner is built on the space of the first run's seed), so that a parameter the plugin
    rejects stops here with one line, not in the middle of a sweep; place the first run's fleet
    when a start file places it (its rows are checked against the space)."""
    from dispatch.api.space import space_for
    from dispatch.run.plugins import UnknownParameter, make_plugin, make_repositioner, make_sizer

    def build(kind, name, params, *args):
        try:
            return make_plugin(kind, name, params, *args)
        except PluginError as e:  # name the file too: "file: key: reason"
            tables = dict(sc.dispatch.allocator_tables) if kind == "allocator" else {}
            own = [k for k in (name, name.partition(":")[0]) if k in tables
                   and (not isinstance(e, UnknownParameter) or e.param in dict(tables[k]))]
            key = f"dispatch.{kind}_params" + ("" if not own else f'."{own[0]}"'
                                               if ":" in own[0] else f".{own[0]}")
            if isinstance(e, UnknownParameter):  # (a typo: the key is the parameter's)
                raise PluginError(f"{sc.path}: {key}.{e.param}: {e.reason}") from e
            raise PluginError(f"{sc.path}: {key}: {e}") from e

    for name in sorted({s.allocator for s in specs}):
        build("allocator", name, sc.dispatch.params_for(name))
    for name in sorted({s.reposition for s in specs}):
        try:
            make_repositioner(sc, name)
        except PluginError as e:
            raise PluginError(f"{sc.path}: {e}") from e
    if sc.fleet.sizing is not None:  # [fleet] sizing: the strategy and its parameters
        try:
            make_sizer(sc)
        except PluginError as e:
            raise PluginError(f"{sc.path}: {e}") from e
    if sc.charging is not None:  # [fleet.energy]: the charging strategy
        from dispatch.run.plugins import make_charger

        try:
            make_charger(sc, sc.charging.strategy)
        except PluginError as e:
            raise PluginError(f"{sc.path}: {e}") from e
    planners = sorted({s.planner for s in specs})
    if planners:
        space = space_for(sc.world, specs[0].seed, sc.path)
        for name in planners:
            planner = build("planner", name, sc.dispatch.planner_params, space)
            # its own work bound (dispatch.scenario.budget), e.g. rrt_star's iterations
            if not ignore_limits:
                from dispatch.scenario.budget import check_planner_budget

                check_planner_budget(sc, specs, planner, name)
        if sc.fleet.start:  # a start file's rows: known nodes, inside the world, one per cell
            from dispatch.fleet.placement import place_fleet
            from dispatch.streams import STREAM_FLEET, rng_for

            place_fleet(space, specs[0], rng_for(specs[0].seed, STREAM_FLEET))
