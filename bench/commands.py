"""``dispatch bench``: the bench's command on the ``dispatch`` command line (entry-point group
``dispatch.commands``; the protocol: :mod:`dispatch.run.commands`). The work is imported when the
command runs."""

from __future__ import annotations

import json
from pathlib import Path


def user_errors() -> tuple[type[Exception], ...]:
    """An unknown allocator or instance, a bad option, a corrupt ``--against`` file."""
    from bench.run import BenchError
    from bench.table import BenchFileError

    return (BenchError, BenchFileError, ValueError)


class Bench:
    """Runs allocators on the fixed, versioned bench suite (robot teams and city fleets) next
    to the shipped baselines and writes a leaderboard: bench.csv, bench.md, bench.png."""

    help = "leaderboard: allocators on the fixed bench suite next to the baselines"
    user_errors = staticmethod(user_errors)

    @staticmethod
    def add_arguments(p) -> None:
        p.add_argument("allocators", nargs="+", metavar="ALLOCATOR",
                       help="installed allocators (or variants, magnnet:paper) to bench")
        p.add_argument("--suite", choices=("robots", "fleets", "all"), default="all")
        p.add_argument("--quick", action="store_true",
                       help="the quick suite: fewer instances, 2 seeds, shorter days (wide "
                            "intervals: the board says how wide; --seeds K for more)")
        p.add_argument("--seeds", type=int, metavar="K",
                       help="the first K seeds of each instance (default: the suite's)")
        p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help="a constructor parameter of the named allocators (VALUE read as "
                            "TOML, else as a string); repeat")
        p.add_argument("--out", type=Path, default=Path("bench_out"),
                       help="output folder (default: bench_out/); rerunning reuses its runs")
        p.add_argument("--against", type=Path, metavar="FILE.csv",
                       help="a previous bench.csv: flag differences beyond the intervals")
        p.add_argument("--workers", type=int, help="processes (default: the CPU count)")
        p.add_argument("--ray", action="store_true", help="run the runs as Ray tasks")
        p.add_argument("--instance", action="append", metavar="NAME",
                       help="only this instance of the suite (repeat)")
        p.add_argument("--time-limit", type=float, metavar="MINUTES",
                       help="wall minutes one run may take; a run past it is stopped and its "
                            "rows say timeout (default: 20)")

    def run(self, args, out) -> int:
        from bench.against import compare
        from bench.board import board_tables, interval_note
        from bench.report import write_figure, write_markdown
        from bench.run import TIME_LIMIT_MIN, BenchError, parse_params, run_bench
        from bench.table import read_csv, write_csv

        if args.workers is not None and args.workers < 1:
            raise BenchError(f"--workers must be >= 1, got {args.workers}")
        limit = TIME_LIMIT_MIN if args.time_limit is None else args.time_limit
        if not limit > 0:
            raise BenchError(f"--time-limit must be > 0 minutes, got {args.time_limit}")
        before = read_csv(args.against) if args.against else None  # a bad file: before work
        params = parse_params(args.param)
        res = run_bench(args.allocators, args.out, suite=args.suite, quick=args.quick,
                        seeds=args.seeds, params=params, workers=args.workers, ray=args.ray,
                        only=args.instance, time_limit=limit * 60.0)
        folder = Path(args.out)
        write_csv(res.rows, folder / "bench.csv")
        write_markdown(res.rows, folder / "bench.md", res.machine, res.seconds)
        (folder / "machine.json").write_text(json.dumps(res.machine, indent=1),
                                             encoding="utf-8")
        drew = write_figure(res.rows, folder / "bench.png")
        c = res.counts
        out.print(f"{len(res.rows)} row(s): {c['done']} run, {c['skipped']} reused, "
                  f"{c['failed']} failed, {c['timeout']} past the time limit, "
                  f"{c['unsupported']} unsupported; {res.seconds:.1f} s")
        for title, table in board_tables(res.rows):
            out.print(title)
            out.show(table)
        if res.rows:
            out.print(interval_note(res.rows))
        out.print(f"every column: {folder / 'bench.md'}; rows: {folder / 'bench.csv'}"
                  + (f"; picture: {folder / 'bench.png'}" if drew else ""))
        for r in res.rows:
            if r["status"].startswith("failed"):
                out.warn(f"{r['instance']} / {r['allocator']} / seed {r['seed']}: {r['status']}")
        status = 1 if c["failed"] else 0
        if before is not None:
            flagged = compare(before, res.rows)
            for d in flagged:
                out.warn(f"differs: {d.line()}")
            out.print(f"against {args.against}: {len(flagged)} difference(s) beyond the "
                      "intervals")
            if flagged:
                status = 1
        return status
