"""Commands that other packages add to the ``dispatch`` command line, found by entry point.

``dispatch report`` and ``dispatch render`` are the :mod:`analysis` package's, registered in the
entry-point group ``dispatch.commands`` as allocators are in ``dispatch.allocators``: the kernel
names no module of theirs, and they import nothing of ``dispatch``.

A command is a class. Its docstring's first paragraph is what ``dispatch plugins`` shows; it
has:

* ``help``: the line ``dispatch --help`` shows for it;
* ``add_arguments(parser)``: adds its arguments to its ``argparse`` sub-parser;
* ``run(args, out) -> int``: runs with the parsed arguments and returns the exit status;
  ``out.print(text)`` writes a line of output, ``out.warn(text)`` a warning on stderr,
  ``out.show(renderable)`` a ``rich`` renderable (a table) laid out to the terminal's width;
* ``user_errors() -> tuple``: the exception types that mean the input was wrong (a folder
  without results, an unknown run id), asked only when the command raised: the CLI prints
  their message as one ``error:`` line, as it does for its own errors; anything else is a
  failure of the command and keeps its traceback.

All four are required: they are read when the command is loaded, and a class without one of
them is kept as a command that failed to load (running it says what it lacks).

Every ``dispatch`` call loads the commands to build its parser: a command's module should
import its work when it runs, not when it is loaded.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from dataclasses import dataclass

from dispatch.api.registry import available, load
from dispatch.errors import DispatchError, PluginError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Command:
    """An installed command: its name, entry-point target, the loaded class (None where
    it failed to load; ``error`` then says why), its help line and its ``user_errors``."""

    name: str
    target: str
    cls: type | None
    error: PluginError | None = None
    help: str | None = None
    user_errors: Callable[[], tuple] | None = None

    @classmethod
    def loaded(cls, name: str, target: str, command: type) -> Command:
        """The command of a loaded class, its parts read once; one that lacks a part is
        kept as failed to load, the error naming it."""
        try:
            parts = (command.help, command.user_errors, command.add_arguments, command.run)
        except AttributeError as e:
            return cls(name, target, None, PluginError(
                f"command plugin {name!r} ({target}) lacks {e.name!r} (a command has help, "
                f"add_arguments, run and user_errors)"))
        return cls(name, target, command, help=parts[0], user_errors=parts[1])

    def add_parser(self, sub) -> None:
        """Add this command's sub-parser to ``sub`` (an argparse sub-parsers action); a
        command that failed to load takes any arguments and says why when run."""
        if self.cls is None:
            p = sub.add_parser(self.name, help=f"(failed to load: {self.target})",
                               add_help=False)
            p.add_argument("rest", nargs=argparse.REMAINDER)
            return
        p = sub.add_parser(self.name, help=self.help)
        self.cls.add_arguments(p)

    def run(self, args, out) -> int:
        """Run the command; its ``user_errors`` become one DispatchError line."""
        if self.cls is None:
            raise self.error
        try:
            return int(self.cls().run(args, out) or 0)
        except DispatchError:
            raise
        except Exception as e:
            if isinstance(e, tuple(self.user_errors())):
                raise DispatchError(e.args[0] if e.args else str(e)) from e
            raise


def installed(reserved=()) -> dict[str, Command]:
    """The commands of the ``dispatch.commands`` group by name, loaded; a name in ``reserved``
    (the CLI's own commands) is skipped with a warning, a command that fails to load is kept
    with its error (running it raises that error)."""
    out = {}
    for name, target in available("command").items():
        if name in reserved:
            log.warning("command %r (%s) is not added: dispatch has a command of that name",
                        name, target)
            continue
        try:
            out[name] = Command.loaded(name, target, load("command", name))
        except PluginError as e:
            out[name] = Command(name, target, None, e)
    return out
