"""The ``dispatch`` command line: run, validate, plugins."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from dispatch import __version__
from dispatch.errors import DispatchError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dispatch", description=__doc__)
    p.add_argument("--version", action="version", version=f"dispatch {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress of every run")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run a scenario (every combination of its sweep)")
    r.add_argument("scenario", type=Path)
    r.add_argument("--out", type=Path, help="output folder (default: runs/<scenario name>/)")
    r.add_argument("--allocator", help="allocator name (overrides the file and its sweep)")
    r.add_argument("--planner", help="planner name (overrides the file and its sweep)")
    r.add_argument("--agents", type=int, help="fleet size N (overrides the file and its sweep)")
    r.add_argument("--seed", type=int, help="seed (overrides the file and its sweep)")

    v = sub.add_parser("validate", help="check a scenario file and list the runs it expands to")
    v.add_argument("scenario", type=Path)

    sub.add_parser("plugins", help="list installed allocators and planners")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    from rich.console import Console

    console = Console()
    err = Console(stderr=True)
    try:
        return {"run": _run, "validate": _validate, "plugins": _plugins}[args.command](args, console)
    except DispatchError as e:
        err.print(f"[bold red]error:[/] {e}", highlight=False)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted")
        return 130


def _specs(args):
    from dispatch.scenario import load_scenario
    from dispatch.registry import load

    sc = load_scenario(args.scenario)
    specs = sc.runs(allocator=getattr(args, "allocator", None), planner=getattr(args, "planner", None),
                    agents=getattr(args, "agents", None), seed=getattr(args, "seed", None))
    for name in sorted({s.allocator for s in specs}):
        load("allocator", name)
    for name in sorted({s.planner for s in specs}):
        load("planner", name)
    return sc, specs


def _run(args, console) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from dispatch.runner import default_out, execute
    from dispatch.tables import render

    sc, specs = _specs(args)
    out = args.out or default_out(specs[0])
    started = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True,
                  disable=len(specs) == 1) as progress:
        bar = progress.add_task(f"{sc.name}", total=len(specs))

        def done(result):
            progress.update(bar, advance=1, description=result.spec.run_id)

        summaries = execute(specs, out, on_done=done)
    render(summaries, console)
    console.print(f"{len(specs)} run(s) in {time.perf_counter() - started:.1f} s; "
                  f"Parquet written to {out}/")
    return 0


def _validate(args, console) -> int:
    sc, specs = _specs(args)
    console.print(f"[green]ok[/]: {args.scenario} ({sc.name}): {len(specs)} run(s); "
                  f"source {sc.tasks.source}, world {sc.world.shape}, "
                  f"{sc.world.obstacles.count} obstacles")
    return 0


def _plugins(args, console) -> int:
    from rich.table import Table

    from dispatch.registry import describe

    for kind in ("allocator", "planner"):
        t = Table(title=f"{kind}s (entry-point group dispatch.{kind}s)")
        for col in ("name", "target", "description"):
            t.add_column(col)
        for row in describe(kind):
            t.add_row(*row)
        console.print(t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
