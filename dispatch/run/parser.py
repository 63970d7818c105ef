"""The argument parser of the dispatch command line (:mod:`dispatch.run.cli`): its own commands
(run, validate, check, plugins, new, train, sweep) and those other packages register."""

from __future__ import annotations

import argparse
from pathlib import Path

from dispatch import __version__
from dispatch.api.registry import entry_point_group

#: what ``dispatch --help`` says the command line is
DESCRIPTION = ("The dispatch command line: run, validate, check, plugins, new, train, sweep; and "
               "the commands other packages add through the entry-point group dispatch.commands "
               "(report and render, from the analysis package).")
#: the commands of :mod:`dispatch.run.cli`; a registered command of one of these names is not added
OWN_COMMANDS = ("run", "validate", "check", "plugins", "new", "train", "sweep")
#: the plugin kinds ``dispatch check`` checks
CHECKED_KINDS = ("allocator", "planner", "repositioner", "charger", "acceptor", "sizer",
                 "mode_choice")


def _logging_options(p: argparse.ArgumentParser, default) -> None:
    """``-v`` and ``--debug``, on the top parser (``default`` False) and again on each
    subcommand (``default`` SUPPRESS, so that a flag given before the subcommand is kept)."""
    p.add_argument("-v", "--verbose", action="store_true", default=default,
                   help="log progress of every run; an error prints its traceback too")
    p.add_argument("--debug", action="store_true", default=default,
                   help="debug logging; an error (a plugin's included) prints its whole "
                        "traceback, the plugin's own frames among them")


class _SplitFlag(argparse.Action):
    """``--force``, which once meant both ``--overwrite`` and ``--ignore-limits``: refused with
    a line naming the two, so that an old script says which it meant (``--help`` says so too:
    every option there says what it is)."""

    def __init__(self, option_strings, dest, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0,
                         help="no longer accepted: say --overwrite or --ignore-limits")

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        parser.error("--force is now two flags: --overwrite (replace results the output folder "
                     "already holds) and --ignore-limits (run past the resource limits)")


def _limits_option(p: argparse.ArgumentParser) -> None:
    """``--ignore-limits`` (run, validate, sweep), and the old ``--force`` pointing at it."""
    p.add_argument("--ignore-limits", action="store_true",
                   help="run past the resource limits (world cells, releases, tasks, vehicles, "
                        "runs, file sizes, a planner's work bound)")
    p.add_argument("--force", action=_SplitFlag)


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


def parser(commands=None) -> argparse.ArgumentParser:
    """The parser of the command line: this module's commands, then each of ``commands``
    (name -> :class:`dispatch.run.commands.Command`)."""
    p = argparse.ArgumentParser(prog="dispatch", description=DESCRIPTION)
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
    r.add_argument("--overwrite", action="store_true",
                   help="run again runs whose results the output folder already holds, replacing "
                        "them (without it, complete runs are shown from the folder, not rerun)")
    _limits_option(r)
    _override_options(r)

    v = sub.add_parser("validate", help="check a scenario file and list the runs it expands to")
    v.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    _limits_option(v)
    _override_options(v)
    # (run's and sweep's plugin, size and seed options: validate lists the file's runs)
    v.set_defaults(allocator=None, planner=None, agents=None, seed=None, duration=None)

    c = sub.add_parser("check", help="check an installed allocator, planner, repositioner, "
                       "charger, acceptor, fleet sizer or mode choice plugin on sample "
                       "problems (valid "
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
    n.add_argument("--overwrite", action="store_true", help="overwrite the files of an "
                   "existing dispatch-NAME/")
    n.add_argument("--force", action=_SplitFlag)
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
    return sorted(ep.name for ep in entry_point_group("dispatch.trainers"))


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
    s.add_argument("--overwrite", action="store_true", help="run again runs that are already "
                   "complete, replacing their results")
    _limits_option(s)
    s.add_argument("--allocator", help="allocator name (overrides the file and its sweep)")
    s.add_argument("--planner", help="planner name (overrides the file and its sweep)")
    s.add_argument("--agents", type=int, help="fleet size N (overrides the file and its sweep)")
    s.add_argument("--seed", type=int, help="seed (overrides the file and its sweep)")
    s.add_argument("--duration", type=float, metavar="SECONDS",
                   help="simulated seconds before each run stops (overrides the file's "
                        "duration; the scenario text stored with the results says so)")
    _override_options(s)
