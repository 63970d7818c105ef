"""``dispatch soak``: the soak on the ``dispatch`` command line (entry-point group
``dispatch.commands``; the protocol: :mod:`dispatch.run.commands`). The work is imported when the
command runs."""

from __future__ import annotations

import logging
from pathlib import Path


class SoakError(ValueError):
    """A bad option of ``dispatch soak``."""


def user_errors() -> tuple[type[Exception], ...]:
    return (SoakError,)


def table_lines(tally, width: int = 80) -> list[str]:
    """The soak's table of runs and of violations by invariant, as text lines of at most
    ``width`` characters (rich lays it out; no colour)."""
    from rich.console import Console
    from rich.table import Table

    s = tally.status
    head = (f"{tally.runs} runs ({tally.worlds['road']} road, {tally.worlds['voxel']} voxel): "
            f"{s['ok']} ok, {s['refused']} refused, {s['violations']} with violations, "
            f"{s['crash']} crashes, {s['hang']} hangs")
    t = Table(title=None, width=min(width, 80))
    t.add_column("invariant")
    t.add_column("runs", justify="right")
    t.add_column("known", justify="right")
    t.add_column("new", justify="right")
    for name, n, k in tally.rows():
        t.add_row(name, str(n), str(k), str(n - k))
    import io

    console = Console(width=min(width, 80), record=True, file=io.StringIO(), color_system=None)
    console.print(t)
    lines = [head, *console.export_text().rstrip("\n").splitlines()]
    lines += [f"  {run}: {msg[:70]}" for run, msg in tally.failures[:10]]
    if tally.refusals:
        lines.append("refused (by design):")
        lines += [f"  {n:5d}  {m[:70]}" for m, n in tally.refusals.most_common(8)]
    return lines


class Soak:
    """Draws valid scenarios at random over the whole configuration space (both worlds, every
    feature), runs each and checks every promise of its Parquet tables; prints a table of
    violations by invariant."""

    help = "random valid scenarios over every feature, checked from their tables alone"
    user_errors = staticmethod(user_errors)

    @staticmethod
    def add_arguments(p) -> None:
        p.add_argument("--runs", type=int, default=100, metavar="N", help="runs (default 100)")
        p.add_argument("--seed", type=int, default=0, metavar="S",
                       help="the soak's seed: run i draws its scenario from (S, i)")
        p.add_argument("--world", choices=("road", "voxel"),
                       help="only this world (default: either, at random)")
        p.add_argument("--out", type=Path, metavar="DIR",
                       help="results folder (default: runs/soak_<seed>/); rerunning resumes")
        p.add_argument("--limit", type=float, default=60.0, metavar="SECONDS",
                       help="wall seconds one run may take before it counts as a hang")
        p.add_argument("--twice-every", type=int, default=10, metavar="K",
                       help="run every K-th scenario twice: same seed, same tables (0: never)")

    def run(self, args, out) -> int:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        from soak.sweep import soak

        if args.runs < 1:
            raise SoakError(f"--runs must be >= 1, got {args.runs}")
        if not args.limit > 0:
            raise SoakError(f"--limit must be > 0 seconds, got {args.limit}")
        folder = args.out or Path("runs") / f"soak_{args.seed}"
        if not (args.verbose or args.debug):  # a drawn scenario's warnings are not the soak's
            logging.getLogger("dispatch").setLevel(logging.ERROR)
        bad = [0]
        with Progress(TextColumn("soak"), BarColumn(), MofNCompleteColumn(),
                      TextColumn("{task.fields[bad]} failing"), transient=True) as bar:
            task = bar.add_task("soak", total=args.runs, bad=0)

            def step(row: dict) -> None:
                if row["status"] in ("crash", "hang") or set(row["broken"]) - set(row["known"]):
                    bad[0] += 1
                bar.update(task, advance=1, bad=bad[0])

            tally = soak(args.runs, args.seed, folder, world=args.world, limit=args.limit,
                         twice_every=args.twice_every, on_run=step)
        for line in table_lines(tally):
            out.print(line)
        out.print(f"scenarios and results in {folder}/ (results.jsonl)")
        return 1 if tally.unexplained else 0
