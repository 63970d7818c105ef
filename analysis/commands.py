"""``dispatch report`` and ``dispatch render``: the analysis package's commands on the
``dispatch`` command line, registered in the entry-point group ``dispatch.commands`` (see
``pyproject.toml``; the protocol: ``dispatch.run.commands.Command``). Nothing here imports
``dispatch``;
the work is imported when a command runs."""

from __future__ import annotations

from pathlib import Path


def user_errors() -> tuple[type[Exception], ...]:
    """What a wrong input raises (no results, an unknown run id or series, a bad option
    value): the CLI prints the message as one error line. Imported when asked, so that the
    command line's start imports nothing of the analysis but this module."""
    from analysis.io import NoResultsError

    return (NoResultsError, KeyError, ValueError)


class Report:
    """Tables and plots (Markdown or HTML) of run or sweep folders; a run found in two folders
    is counted once, with a warning."""

    help = "tables and plots (Markdown or HTML) of run or sweep folders"
    user_errors = staticmethod(user_errors)

    @staticmethod
    def add_arguments(r) -> None:
        r.add_argument("runs", type=Path, nargs="+", metavar="RUNS",
                       help="results folders (of dispatch run or sweep), or folders holding them")
        r.add_argument("--out", type=Path, help="report folder (default: RUNS/report/)")
        r.add_argument("--format", choices=("md", "html"), default="md",
                       help="report.md (default) or report.html")
        r.add_argument("--run", metavar="RUN_ID", help="the run shown in detail (timeline, 3D)")
        r.add_argument("--series", action="append", metavar="PATTERN",
                       help="taxi figures: draw only the series whose label matches this glob "
                            "(e.g. 'hungarian*', '* 30s*', '*+ demand'); repeat for more; the "
                            "tables keep every series")

    def run(self, args, out) -> int:
        from analysis.io import open_results
        from analysis.report import duplicates_note, write_report

        folder = args.out or args.runs[0] / "report"
        res = open_results(*args.runs)
        if res.duplicates:  # the same run in two folders: counted once, and said so
            out.warn(duplicates_note(res))
        files = write_report(res, folder, fmt=args.format, run_id=args.run, series=args.series)
        out.print(f"report: {files[0]}")
        out.print("files: " + ", ".join(f.name for f in files[1:]))
        return 0


class Render:
    """Draws a run as an animated GIF (or MP4): PyBullet camera images of a voxel run, the map
    of a road run."""

    help = ("draw a run as an animated GIF or MP4: PyBullet images of a voxel run, the map of "
            "a road run")
    user_errors = staticmethod(user_errors)

    @staticmethod
    def add_arguments(g) -> None:
        g.add_argument("run", type=Path, metavar="RUN",
                       help="a results folder (of dispatch run or sweep)")
        g.add_argument("--run-id", help="which run of a sweep folder (default: as the report)")
        g.add_argument("--out", type=Path,
                       help="output .gif (or .mp4; default: RUN/<run id>.gif)")
        g.add_argument("--fps", type=int, default=10, help="frames per second (default: 10)")
        g.add_argument("--seconds", type=float, help="length of the animation (default: the "
                       "run's simulated time, at most 12 s)")
        g.add_argument("--size", default="480x360", help="frame size WIDTHxHEIGHT")

    def run(self, args, out) -> int:
        from analysis.render import render_run

        try:
            w, h = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise ValueError(f"--size must be WIDTHxHEIGHT, got {args.size!r}") from None
        if args.fps < 1 or w < 16 or h < 16:
            raise ValueError("--fps must be >= 1 and --size at least 16x16")
        path = render_run(args.run, args.out, run_id=args.run_id, fps=args.fps,
                          seconds=args.seconds, size=(w, h))
        out.print(f"animation: {path}")
        return 0


class Replay:
    """One self-contained HTML page that plays a run (or two side by side) in the browser,
    offline; ``--kepler``: the vehicles' trips as kepler.gl GeoJSON."""

    help = "an interactive replay of a run in one offline HTML page"

    @staticmethod
    def user_errors() -> tuple[type[Exception], ...]:
        from analysis.replay_data import ReplayInputError

        return (ReplayInputError, *user_errors())

    @staticmethod
    def add_arguments(r) -> None:
        r.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                       help="a results folder (of dispatch run or sweep)")
        r.add_argument("--run", metavar="RUN_ID",
                       help="which run of the folder (needed where it holds several)")
        r.add_argument("--out", type=Path,
                       help="output page (default: RUN_DIR/replay.html; with --kepler "
                            "RUN_DIR/<run id>.trips.geojson)")
        r.add_argument("--compare", type=Path, metavar="OTHER_RUN_DIR",
                       help="a second results folder, shown beside the first on one clock")
        r.add_argument("--compare-run", metavar="RUN_ID",
                       help="which run of the --compare folder (needed where it holds several)")
        r.add_argument("--kepler", action="store_true",
                       help="write kepler.gl trips (GeoJSON, [lon, lat, 0, epoch]) of a road "
                            "run instead of the page")
        r.add_argument("--epoch", type=float, default=0.0,
                       help="--kepler: the Unix time of simulated second 0 (default 0)")

    def run(self, args, out) -> int:
        if args.kepler:
            from analysis.replay_kepler import write_trips

            path = write_trips(args.run_dir, args.out, run_id=args.run, epoch=args.epoch)
            out.print(f"kepler.gl trips: {path}")
            return 0
        from analysis.replay import write_replay

        path = write_replay(args.run_dir, args.out, run_id=args.run, compare=args.compare,
                            compare_run=args.compare_run)
        out.print(f"replay: {path}")
        return 0
