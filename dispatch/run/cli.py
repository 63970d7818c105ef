"""The dispatch command line: run, validate, check, plugins, new, train, sweep; and the
commands other packages add through the entry-point group dispatch.commands (report and render,
from the analysis package)."""

from __future__ import annotations

import logging
import os
import sys
import time

from dispatch.api.registry import available, describe, entry_point_group, load
from dispatch.errors import DispatchError, PluginError
from dispatch.run.commands import installed
from dispatch.run.held import hold_root, release_root
from dispatch.run.parser import CHECKED_KINDS, OWN_COMMANDS, parser
from dispatch.run.prepare import checked_specs
from dispatch.run.progress import Heartbeat


class _Output:
    """What a registered command writes through: ``print`` a line of output, ``warn`` a
    warning on stderr (one line each, as the CLI's own), ``show`` a rich renderable (a table,
    laid out to the terminal's width)."""

    def __init__(self, console, err) -> None:
        self.console, self.err = console, err

    def print(self, text: str) -> None:
        self.console.print(text, highlight=False, soft_wrap=True, markup=False, emoji=False)

    def show(self, renderable) -> None:
        self.console.print(renderable)

    def warn(self, text: str) -> None:
        from rich.markup import escape

        self.err.print(f"[yellow]warning[/]: {escape(text)}", highlight=False, soft_wrap=True,
                       emoji=False)


#: Commands whose warnings are not held back: they run for long and report as they go.
LONG = frozenset({"sweep", "train"})


def main(argv: list[str] | None = None) -> int:
    commands = installed(reserved=OWN_COMMANDS)
    args = parser(commands).parse_args(argv)
    level = logging.DEBUG if args.debug else logging.INFO if args.verbose else logging.WARNING
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    # warnings wait until the set-up is over: a refusal part-way through it reads as one line
    held = hold_root() if level == logging.WARNING and args.command not in LONG else None
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
        if held is not None:
            held.forget()
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
    finally:
        if held is not None:  # (after a refusal: dropped already, nothing left to write)
            held.pass_on()


def _run(args, console) -> int:
    """Run the scenario's runs into ``--out``. A run the folder already holds whole, made from
    the same scenario settings, is not run again: its stored summary is shown and a line says
    where it is (``--overwrite`` runs it again); a partition holding anything else (another
    text's run of the same id, a run cut short) is refused, not silently replaced."""
    from dispatch.run.resume import holds_results, is_complete, read_summary
    from dispatch.run.runner import default_out, execute

    sc, specs = checked_specs(args)
    out = args.out or default_out(specs[0])
    stored: dict[int, dict] = {}
    if not args.overwrite:
        other = []
        for i, s in enumerate(specs):
            if holds_results(out, s):
                if is_complete(out, s):
                    stored[i] = {**read_summary(out, s), **s.keys}
                else:
                    other.append(s.run_id)
        if other:
            more = f" and {len(other) - 1} more" if len(other) > 1 else ""
            raise DispatchError(f"{out}/ already holds other results of {other[0]}{more} (another "
                                f"version of the scenario, or a run cut short); use --overwrite "
                                f"to replace them, or another --out")
    todo = [s for i, s in enumerate(specs) if i not in stored]
    started = time.perf_counter()
    if len(todo) == 1:  # one long run: simulated time, wall time, requests released and closed
        with _run_progress(console, todo[0]) as report:
            fresh = execute(todo, out, progress=_releasing(report))
    elif todo:  # (rich.progress imported here: a single run off a terminal does without it)
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                   TimeElapsedColumn)

        finished = []
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=console, transient=True) as progress, \
                Heartbeat(console, lambda: f"{sc.name}: {len(finished)} of {len(todo)} "
                           "runs done" + (f" (last: {finished[-1]})" if finished else "")):
            bar = progress.add_task(f"{sc.name}", total=len(todo))

            def done(result):
                release_root()  # (the first run's set-up went through)
                finished.append(result.spec.run_id)
                progress.update(bar, advance=1, description=result.spec.run_id)

            fresh = execute(todo, out, on_done=done)
    else:
        fresh = []
    ran = iter(fresh)
    summaries = [stored[i] if i in stored else next(ran) for i in range(len(specs))]
    _tables(summaries, console, sc)
    if stored:
        first = specs[min(stored)].run_id
        more = f" and {len(stored) - 1} more" if len(stored) > 1 else ""
        console.print(f"[yellow]note[/]: {len(stored)} run(s) already in {out}/ ({first}{more}) "
                      "shown from there, not run again; --overwrite runs them again",
                      highlight=False, soft_wrap=True)
    if todo:
        # (no highlighting: the status lines' style, and rich's highlighter compiles its
        # patterns at first use, 10 ms of a short run)
        console.print(f"{len(todo)} run(s) in {time.perf_counter() - started:.1f} s; "
                      f"Parquet written to {out}/", highlight=False, soft_wrap=True)
    return 0


def _releasing(report):
    """``report``, releasing the held warnings at its first call: the run's set-up is over."""
    def first(*a) -> None:
        release_root()
        report(*a)
    return first


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
    sc, specs = checked_specs(args)
    from dispatch.api.space import space_class

    world = space_class(sc.world.space).label(sc.world)
    release_root()  # (the scenario went through: its warnings come before the ok)
    console.print(f"[green]ok[/]: {args.scenario} ({sc.name}): {len(specs)} run(s); "
                  f"source {sc.tasks.source}, {world}", soft_wrap=True)
    return 0


def _train(args, console) -> int:
    """Hand the arguments to a trainer module (``main(argv)``) found by entry point."""
    import importlib

    found = {ep.name: ep.value for ep in entry_point_group("dispatch.trainers")}
    if args.trainer not in found:
        raise PluginError(f"unknown trainer {args.trainer!r}; installed: {', '.join(found)}")
    try:
        module = importlib.import_module(found[args.trainer].partition(":")[0])
    except ImportError as e:
        raise PluginError(f"trainer {args.trainer!r} failed to load: {e}") from e
    return int(module.main(args.trainer_args) or 0)


def _plugins(args, console) -> int:
    """One table per kind (allocators, planners, repositioners, chargers, acceptors, fleet
    sizers, mode choices and the commands
    other packages add to this command line): name, spaces served (planners, repositioners,
    chargers) and the description
    (plain text, never empty) with the entry point's target on a line of its own below it, so
    that neither is cut in an 80-column terminal."""
    from rich.table import Table
    from rich.text import Text

    for kind in ("allocator", "planner", "repositioner", "charger", "acceptor", "sizer",
                 "mode_choice", "command"):
        t = Table(title=f"{kind}s (entry-point group dispatch.{kind}s)", title_justify="left")
        t.add_column("name", no_wrap=True)
        # plugins that serve some spaces
        spaced = kind not in ("allocator", "acceptor", "sizer", "mode_choice", "command")
        if spaced:
            t.add_column("spaces")
        t.add_column("description; target (module:object)", overflow="fold")
        for name, target, spaces, doc in describe(kind):
            cell = Text(doc)
            cell.append("\n" + target, style="dim")
            t.add_row(Text(name), *([Text(spaces)] if spaced else []), cell)
        console.print(t)
    return 0


def _sweep(args, console) -> int:
    from collections import Counter

    from rich.markup import escape
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from dispatch.run.resume import foreign_runs
    from dispatch.run.runner import default_out, sweep

    if args.workers is not None and args.workers < 1:
        raise DispatchError(f"--workers must be >= 1, got {args.workers}")
    sc, specs = checked_specs(args)
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
                         address=args.ray or None, overwrite=args.overwrite, on_done=done)
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
    from dispatch.checks.acceptors import check_acceptor
    from dispatch.checks.allocators import check_allocator
    from dispatch.checks.chargers import check_charger
    from dispatch.checks.mode_choices import check_mode_choice
    from dispatch.checks.planners import check_planner
    from dispatch.checks.repositioners import check_repositioner
    from dispatch.checks.sizers import check_sizer

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
    elif kinds[0] == "mode_choice":
        report = check_mode_choice(cls, seed=args.seed, **params)
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

    root = new_allocator(args.name, args.out, overwrite=args.overwrite)
    console.print(f"wrote {root}/ (pyproject.toml, dispatch_{args.name}/allocator.py, tests, "
                  f"README.md); next: pip install -e {root} && dispatch check {args.name}",
                  highlight=False, soft_wrap=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
