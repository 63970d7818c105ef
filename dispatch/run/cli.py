"""The dispatch command line: run, validate, check, plugins, new, train, sweep; and the
commands other packages add through the entry-point group dispatch.commands (report and render,
from the analysis package)."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path

from dispatch import __version__
from dispatch.errors import DispatchError
from dispatch.run.progress import Heartbeat

#: the commands of this module; a registered command of one of these names is not added
OWN_COMMANDS = ("run", "validate", "check", "plugins", "new", "train", "sweep")
#: the plugin kinds ``dispatch check`` checks
CHECKED_KINDS = ("allocator", "planner", "repositioner", "charger", "acceptor", "sizer")


def _logging_options(p: argparse.ArgumentParser, default) -> None:
    """``-v`` and ``--debug``, on the top parser (``default`` False) and again on each
    subcommand (``default`` SUPPRESS, so that a flag given before the subcommand is kept)."""
    p.add_argument("-v", "--verbose", action="store_true", default=default,
                   help="log progress of every run; an error prints its traceback too")
    p.add_argument("--debug", action="store_true", default=default,
                   help="debug logging; an error (a plugin's included) prints its whole "
                        "traceback, the plugin's own frames among them")


def _override_options(p: argparse.ArgumentParser) -> None:
    """The scenario-key overrides of run, sweep and validate
    (:mod:`dispatch.scenario.overrides`)."""
    p.add_argument("--capacity", type=int, metavar="N",
                   help="seats per vehicle (sets fleet.capacity)")
    p.add_argument("--batch-window", type=float, metavar="SECONDS",
                   help="seconds between batched decisions, 0: each request at once (sets "
                        "dispatch.batch_window, and replaces the sweep's batch_window list)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   dest="overrides",
                   help="set any scenario key (VALUE read as TOML, else as a string; e.g. "
                        "--set tasks.max_delay=600); checked like the file; repeat")


def _parser(commands=None) -> argparse.ArgumentParser:
    """The parser of the command line: this module's commands, then each of ``commands``
    (name -> :class:`dispatch.run.commands.Command`)."""
    p = argparse.ArgumentParser(prog="dispatch", description=__doc__)
    p.add_argument("--version", action="version", version=f"dispatch {__version__}")
    _logging_options(p, False)
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run a scenario (every combination of its sweep)")
    r.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    r.add_argument("--out", type=Path, help="output folder (default: runs/<scenario name>/)")
    r.add_argument("--allocator", help="allocator name (overrides the file and its sweep)")
    r.add_argument("--planner", help="planner name (overrides the file and its sweep)")
    r.add_argument("--agents", type=int, help="fleet size N (overrides the file and its sweep)")
    r.add_argument("--seed", type=int, help="seed (overrides the file and its sweep)")
    r.add_argument("--duration", type=float, metavar="SECONDS",
                   help="simulated seconds before the run stops (overrides the file's "
                        "duration; the scenario text stored with the results says so)")
    r.add_argument("--force", action="store_true",
                   help="overwrite earlier results of these runs in the output folder, and run "
                        "past the resource limits (world cells, releases, tasks, runs, sizes)")
    _override_options(r)

    v = sub.add_parser("validate", help="check a scenario file and list the runs it expands to")
    v.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    v.add_argument("--force", action="store_true",
                   help="accept what is past the resource limits (world cells, releases, tasks, "
                        "runs, file sizes)")
    _override_options(v)
    # (run's and sweep's plugin, size and seed options: validate lists the file's runs)
    v.set_defaults(allocator=None, planner=None, agents=None, seed=None, duration=None)

    c = sub.add_parser("check", help="check an installed allocator, planner, repositioner, "
                       "charger, acceptor or fleet sizer plugin on sample problems (valid "
                       "answers, no mutation, determinism, rng use)")
    c.add_argument("name", help="plugin name (see dispatch plugins)")
    c.add_argument("--kind", choices=CHECKED_KINDS,
                   help="which kind NAME is (needed only when two kinds have that name)")
    c.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="a constructor parameter (VALUE read as TOML, else as a string); repeat")
    c.add_argument("--seed", type=int, default=0, help="seed of the random problems")

    sub.add_parser("plugins", help="list installed allocators, planners, repositioners, "
                   "chargers, acceptors and commands")
    n = sub.add_parser("new", help="write a new plugin package (`dispatch new allocator NAME`): "
                       "installs with pip and passes `dispatch check NAME`")
    n.add_argument("kind", choices=("allocator",), help="the kind of plugin to write")
    n.add_argument("name", help="the plugin's name (lower-case letters, digits, _)")
    n.add_argument("--out", type=Path, default=Path("."),
                   help="folder to write dispatch-NAME/ into (default: here)")
    n.add_argument("--force", action="store_true", help="overwrite the files of an existing "
                   "dispatch-NAME/")
    trainers = _trainers()
    t = sub.add_parser("train", help="train a learned allocator (e.g. `dispatch train magnnet "
                       "--agents 8`); options after the name go to its trainer (`dispatch "
                       "train NAME --help`)",
                       epilog="installed trainers (entry-point group dispatch.trainers): "
                              + (", ".join(trainers) or "none"))
    t.add_argument("trainer", help="trainer name: " + (", ".join(trainers) or "none installed"))
    t.add_argument("trainer_args", nargs=argparse.REMAINDER,
                   help="the trainer's own options (its --help lists them)")
    _add_sweep_parser(sub)
    for command in (commands or {}).values():
        command.add_parser(sub)
    for name, action in sub.choices.items():
        _logging_options(action, argparse.SUPPRESS)
    return p


def _trainers() -> list[str]:
    """The installed trainers' names (entry-point group dispatch.trainers), sorted."""
    from importlib.metadata import entry_points

    return sorted(ep.name for ep in entry_points(group="dispatch.trainers"))


class _Output:
    """What a registered command writes through: ``print`` a line of output, ``warn`` a
    warning on stderr (one line each, as the CLI's own)."""

    def __init__(self, console, err) -> None:
        self.console, self.err = console, err

    def print(self, text: str) -> None:
        self.console.print(text, highlight=False, soft_wrap=True, markup=False, emoji=False)

    def warn(self, text: str) -> None:
        from rich.markup import escape

        self.err.print(f"[yellow]warning[/]: {escape(text)}", highlight=False, soft_wrap=True,
                       emoji=False)


def main(argv: list[str] | None = None) -> int:
    from dispatch.run.commands import installed

    commands = installed(reserved=OWN_COMMANDS)
    args = _parser(commands).parse_args(argv)
    level = logging.DEBUG if args.debug else logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from rich.console import Console
    from rich.markup import escape

    # Status and error lines stay one line whatever the terminal width (paths are long; scripts
    # and users grep them); only tables are laid out to the width.
    console = Console()
    err = Console(stderr=True, soft_wrap=True)
    try:
        if args.command in commands:  # registered by another package (dispatch.commands)
            return commands[args.command].run(args, _Output(console, err))
        return {"run": _run, "validate": _validate, "plugins": _plugins, "sweep": _sweep,
                "train": _train, "check": _check, "new": _new}[args.command](args, console)
    except DispatchError as e:
        if args.debug or args.verbose:  # the chain: where a plugin raised, then where we caught
            import traceback

            sys.stderr.write("".join(traceback.format_exception(e)))
            sys.stderr.flush()
        # the message as written: no markup ("[dispatch]") nor emoji (":x:") read into it
        err.print(f"[bold red]error:[/] {escape(str(e))}", highlight=False, soft_wrap=True,
                  emoji=False)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted")
        return 130


def _specs(args):
    """Parse the scenario and expand its runs, checking all that can be checked before a run:
    the file, the resource limits (unless ``--force``), the plugins (each distinct allocator
    and planner is built once with the scenario's parameters) and the space they serve."""
    from dispatch.api.registry import load
    from dispatch.errors import PluginError
    from dispatch.scenario.load import check_limits, load_scenario

    force = args.force
    sc = load_scenario(args.scenario, force=force, overrides=overrides(args))
    specs = sc.runs(allocator=args.allocator, planner=args.planner, agents=args.agents,
                    seed=args.seed, batch_window=args.batch_window)
    if not force:
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
    build_plugins(sc, specs, force=force)
    return sc, specs


def overrides(args) -> list[tuple[str, str, str]]:
    """The scenario keys the command line sets, as :func:`dispatch.scenario.load.load_scenario`
    takes them: ``--duration``, ``--capacity``, ``--batch-window``, then each ``--set`` in
    order (a later one wins)."""
    import math

    from dispatch.errors import ScenarioError
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


def build_plugins(sc, specs, *, force: bool = False) -> None:
    """Build every distinct allocator and planner of ``specs`` once (constructors are cheap;
    a planner is built on the space of the first run's seed), so that a parameter the plugin
    rejects stops here with one line, not in the middle of a sweep; place the first run's fleet
    when a start file places it (its rows are checked against the space)."""
    from dispatch.api.space import space_for
    from dispatch.errors import PluginError
    from dispatch.run.plugins import make_plugin, make_repositioner

    def build(kind, name, params, *args):
        try:
            return make_plugin(kind, name, params, *args)
        except PluginError as e:  # name the file too: "file: key: reason"
            tables = dict(sc.dispatch.allocator_tables) if kind == "allocator" else {}
            own = [k for k in (name, name.partition(":")[0]) if k in tables]
            key = f"dispatch.{kind}_params" + ("" if not own else f'."{own[0]}"'
                                               if ":" in own[0] else f".{own[0]}")
            raise PluginError(f"{sc.path}: {key}: {e}") from e

    for name in sorted({s.allocator for s in specs}):
        build("allocator", name, sc.dispatch.params_for(name))
    for name in sorted({s.reposition for s in specs}):
        try:
            make_repositioner(sc, name)
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
            if not force:
                from dispatch.scenario.budget import check_planner_budget

                check_planner_budget(sc, specs, planner, name)
        if sc.fleet.start:  # a start file's rows: known nodes, inside the world, one per cell
            from dispatch.fleet.placement import place_fleet
            from dispatch.streams import STREAM_FLEET, rng_for

            place_fleet(space, specs[0], rng_for(specs[0].seed, STREAM_FLEET))


def _run(args, console) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from dispatch.run.runner import default_out, execute, holds_results

    sc, specs = _specs(args)
    out = args.out or default_out(specs[0])
    held = [s.run_id for s in specs if holds_results(out, s)]
    if held and not args.force:
        more = f" and {len(held) - 1} more" if len(held) > 1 else ""
        raise DispatchError(f"{out}/ already holds results of {held[0]}{more}; use --force to "
                            f"overwrite them, another --out, or dispatch sweep to resume")
    started = time.perf_counter()
    single = len(specs) == 1
    if single:  # one long run: simulated time, wall time, requests released and closed
        with _run_progress(console, specs[0]) as report:
            summaries = execute(specs, out, progress=report)
    else:
        finished = []
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=console, transient=True) as progress, \
                Heartbeat(console, lambda: f"{sc.name}: {len(finished)} of {len(specs)} "
                           "runs done" + (f" (last: {finished[-1]})" if finished else "")):
            bar = progress.add_task(f"{sc.name}", total=len(specs))

            def done(result):
                finished.append(result.spec.run_id)
                progress.update(bar, advance=1, description=result.spec.run_id)

            summaries = execute(specs, out, on_done=done)
    _tables(summaries, console, sc)
    console.print(f"{len(specs)} run(s) in {time.perf_counter() - started:.1f} s; "
                  f"Parquet written to {out}/", soft_wrap=True)
    return 0


class _run_progress:
    """Context manager: a progress bar of one run (simulated time out of the duration, wall
    time, requests released and closed) on a terminal, else a line a minute on stderr
    (:class:`dispatch.run.progress.Heartbeat`); yields the callback for
    :class:`dispatch.run.sim.Simulation`."""

    def __init__(self, console, spec) -> None:
        self.console, self.spec = console, spec
        self.progress = None
        self.beat = None

    def __enter__(self):
        if not self.console.is_terminal:
            import math

            state = {"now": 0.0, "duration": self.spec.scenario.duration, "released": 0,
                     "closed": 0, "reports": 0}

            def report(now: float, duration: float, released: int, closed: int) -> None:
                state.update(now=now, duration=duration, released=released, closed=closed,
                             reports=state["reports"] + 1)

            def what() -> str:
                d = state["duration"]
                share = f" ({100 * state['now'] / d:.1f} %)" if d and math.isfinite(d) else ""
                line = (f"{self.spec.run_id}: simulated {state['now']:,.1f} of {d:,.1f} s"
                        f"{share}; {state['released']:,} tasks released, {state['closed']:,} "
                        "closed")
                return line if state["reports"] else line + " (still in its first steps)"

            self.beat = Heartbeat(self.console, what).__enter__()
            return report
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(TextColumn("{task.description}"), BarColumn(),
                                 TextColumn("{task.fields[sim]}"), TimeElapsedColumn(),
                                 TextColumn("{task.fields[tasks]}"), console=self.console,
                                 transient=True)
        self.progress.__enter__()
        self.bar = self.progress.add_task(self.spec.scenario.name, total=1.0, sim="", tasks="")

        def report(now: float, duration: float, released: int, closed: int) -> None:
            self.progress.update(self.bar, completed=min(now / duration, 1.0),
                                 sim=f"sim {now / 3600:.1f}/{duration / 3600:.1f} h",
                                 tasks=f"{released:,} released, {closed:,} closed")

        return report

    def __exit__(self, *exc) -> None:
        if self.beat is not None:
            self.beat.__exit__(*exc)
        if self.progress is not None:
            self.progress.__exit__(*exc)


def _tables(summaries, console, sc) -> None:
    """One run's summary; or paper tables for voxel runs (per task for a dynamic scenario),
    the trip table for road-network runs."""
    from dispatch.output.printed import print_tables


    print_tables(summaries, console, dynamic=sc.tasks.source != "static")


def _validate(args, console) -> int:
    sc, specs = _specs(args)
    from dispatch.api.space import space_class

    world = space_class(sc.world.space).label(sc.world)
    console.print(f"[green]ok[/]: {args.scenario} ({sc.name}): {len(specs)} run(s); "
                  f"source {sc.tasks.source}, {world}", soft_wrap=True)
    return 0


def _train(args, console) -> int:
    """Hand the arguments to a trainer module (``main(argv)``) found by entry point."""
    import importlib
    from importlib.metadata import entry_points

    from dispatch.errors import PluginError

    found = {ep.name: ep.value for ep in entry_points(group="dispatch.trainers")}
    if args.trainer not in found:
        raise PluginError(f"unknown trainer {args.trainer!r}; installed: {', '.join(found)}")
    try:
        module = importlib.import_module(found[args.trainer].partition(":")[0])
    except ImportError as e:
        raise PluginError(f"trainer {args.trainer!r} failed to load: {e}") from e
    return int(module.main(args.trainer_args) or 0)


def _plugins(args, console) -> int:
    """One table per kind (allocators, planners, repositioners, chargers and the commands
    other packages add to this command line): name, spaces served (planners, repositioners,
    chargers) and the description
    (plain text, never empty) with the entry point's target on a line of its own below it, so
    that neither is cut in an 80-column terminal."""
    from rich.table import Table
    from rich.text import Text

    from dispatch.api.registry import describe

    for kind in ("allocator", "planner", "repositioner", "charger", "acceptor", "sizer",
                 "command"):
        t = Table(title=f"{kind}s (entry-point group dispatch.{kind}s)", title_justify="left")
        t.add_column("name", no_wrap=True)
        # plugins that serve some spaces
        spaced = kind not in ("allocator", "acceptor", "sizer", "command")
        if spaced:
            t.add_column("spaces")
        t.add_column("description; target (module:object)", overflow="fold")
        for name, target, spaces, doc in describe(kind):
            cell = Text(doc)
            cell.append("\n" + target, style="dim")
            t.add_row(Text(name), *([Text(spaces)] if spaced else []), cell)
        console.print(t)
    return 0


# ----------------------------------------------------------------------------- sweep (the work
# is in dispatch.run.runner)


def _add_sweep_parser(sub) -> None:
    s = sub.add_parser("sweep", help="run a scenario's sweep on a process pool or Ray; "
                       "resumable (complete runs are skipped)")
    s.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    s.add_argument("--out", type=Path, help="output folder (default: runs/<scenario name>/)")
    s.add_argument("--workers", type=int, metavar="K",
                   help="worker processes (or local Ray CPUs); default: the CPU count")
    s.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run the runs as Ray tasks: on a local Ray, or on the cluster at "
                        "ADDRESS (e.g. auto or ray://host:10001)")
    s.add_argument("--force", action="store_true", help="redo runs that are already complete, "
                   "and run past the resource limits (world cells, releases, tasks, runs, sizes)")
    s.add_argument("--allocator", help="allocator name (overrides the file and its sweep)")
    s.add_argument("--planner", help="planner name (overrides the file and its sweep)")
    s.add_argument("--agents", type=int, help="fleet size N (overrides the file and its sweep)")
    s.add_argument("--seed", type=int, help="seed (overrides the file and its sweep)")
    s.add_argument("--duration", type=float, metavar="SECONDS",
                   help="simulated seconds before each run stops (overrides the file's "
                        "duration; the scenario text stored with the results says so)")
    _override_options(s)


def _sweep(args, console) -> int:
    from collections import Counter

    from rich.markup import escape
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from dispatch.run.runner import default_out, foreign_runs, sweep

    if args.workers is not None and args.workers < 1:
        raise DispatchError(f"--workers must be >= 1, got {args.workers}")
    sc, specs = _specs(args)
    out = args.out or default_out(specs[0])
    counts: Counter = Counter()
    where = (f"Ray ({args.ray or 'local'})" if args.ray is not None
             else f"{args.workers or os.cpu_count()} worker process(es)")
    started = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TextColumn("{task.fields[tally]}"), TimeElapsedColumn(), console=console,
                  transient=True) as progress, \
            Heartbeat(console, lambda: f"{sc.name}: {sum(counts.values())} of {len(specs)} "
                       "runs finished (" + (", ".join(f"{v} {k}" for k, v in
                                                      sorted(counts.items())) or "none yet")
                       + f") on {where}"):
        bar = progress.add_task(sc.name, total=len(specs), tally="")

        def done(o):
            counts[o.status] += 1
            progress.update(bar, advance=1, tally=", ".join(f"{v} {k}" for k, v in
                                                            sorted(counts.items())))

        outcomes = sweep(specs, out, workers=args.workers, ray=args.ray is not None,
                         address=args.ray or None, force=args.force, on_done=done)
    summaries = [o.summary for o in outcomes if o.summary is not None]
    if summaries:
        _tables(summaries, console, sc)
    failed = [o for o in outcomes if o.status == "failed"]
    for o in failed:
        if (args.verbose or args.debug) and o.traceback:  # where the run (a plugin) raised
            sys.stderr.write(o.traceback)
            sys.stderr.flush()
        console.print(f"[red]failed[/]: {o.run_id}: {escape(o.error)}", highlight=False,
                      soft_wrap=True)
    console.print(f"{len(specs)} run(s): {counts['done']} run, {counts['skipped']} already "
                  f"complete, {len(failed)} failed; {time.perf_counter() - started:.1f} s on "
                  f"{where}; Parquet written to {out}/", highlight=False, soft_wrap=True)
    if failed:
        console.print(f"errors: {out}/errors/ (run the sweep again to retry the failed runs)",
                      highlight=False, soft_wrap=True)
    foreign = foreign_runs(out, specs)
    if foreign:
        console.print(f"[yellow]note[/]: {out}/ also holds {len(foreign)} run(s) of another "
                      f"scenario text (e.g. {foreign[0]}); reports of the folder include them",
                      highlight=False, soft_wrap=True)
    return 1 if failed else 0


def _check(args, console) -> int:
    """``dispatch check NAME``: run the plugin checks (:mod:`dispatch.checks.allocators`, ...) on
    an installed plugin;
    one line per check; exit 0 when all pass, 1 otherwise."""
    from dispatch.api.registry import available, load
    from dispatch.checks.acceptors import check_acceptor
    from dispatch.checks.allocators import check_allocator
    from dispatch.checks.chargers import check_charger
    from dispatch.checks.planners import check_planner
    from dispatch.checks.repositioners import check_repositioner
    from dispatch.checks.sizers import check_sizer
    from dispatch.errors import PluginError

    kinds = [k for k in CHECKED_KINDS if args.name in available(k)]
    if args.kind:
        kinds = [args.kind]
    if not kinds:
        raise PluginError(f"no plugin named {args.name!r}; installed: " + "; ".join(
            f"{', '.join(available(k)) or 'none'} ({k}s)" for k in CHECKED_KINDS))
    if len(kinds) > 1:
        raise DispatchError(f"{args.name!r} is both {' and '.join(kinds)}; say --kind")
    from dispatch.scenario.overrides import key_values

    params = key_values(args.param)
    cls = load(kinds[0], args.name)
    if kinds[0] == "allocator":
        report = check_allocator(cls, seed=args.seed, **params)
    elif kinds[0] == "planner":
        report = check_planner(cls, seed=args.seed, **params)
    elif kinds[0] == "charger":
        report = check_charger(cls, seed=args.seed, **params)
    elif kinds[0] == "acceptor":
        report = check_acceptor(cls, seed=args.seed, **params)
    elif kinds[0] == "sizer":
        report = check_sizer(cls, seed=args.seed, **params)
    else:
        report = check_repositioner(cls, seed=args.seed, **params)
    for r in report.results:
        mark = {"pass": "[green]pass[/]", "skip": "[yellow]skip[/]"}.get(r.mark, "[red]FAIL[/]")
        console.print(f"{mark} {r.name}: {r.detail}", highlight=False, soft_wrap=True)
    skipped = sum(r.skipped for r in report.results)
    verdict = "passes every check" if report.ok else \
        f"fails {sum(not r.ok and not r.skipped for r in report.results)} of " \
        f"{len(report.results)} checks" + (f" ({skipped} could not run)" if skipped else "")
    console.print(f"{kinds[0]} {args.name!r} ({cls.__module__}.{cls.__qualname__}) {verdict}",
                  highlight=False, soft_wrap=True)
    return 0 if report.ok else 1


def _new(args, console) -> int:
    """``dispatch new allocator NAME``: see :mod:`dispatch.checks.scaffold`."""
    from dispatch.checks.scaffold import new_allocator

    root = new_allocator(args.name, args.out, force=args.force)
    console.print(f"wrote {root}/ (pyproject.toml, dispatch_{args.name}/allocator.py, tests, "
                  f"README.md); next: pip install -e {root} && dispatch check {args.name}",
                  highlight=False, soft_wrap=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
