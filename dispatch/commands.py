"""Commands that other packages add to the ``dispatch`` command line, found by entry point.

``dispatch report`` and ``dispatch render`` are the :mod:`analysis` package's, registered in the
entry-point group ``dispatch.commands`` as allocators are in ``dispatch.allocators``: the kernel
names no module of theirs (the registry's fallback table aside, which holds names as strings),
and they import nothing of ``dispatch``.

A command is a class. Its docstring's first paragraph is what ``dispatch plugins`` shows; it
has:

* ``help``: the line ``dispatch --help`` shows for it;
* ``add_arguments(parser)``: adds its arguments to its ``argparse`` sub-parser;
* ``run(args, out) -> int``: runs with the parsed arguments and returns the exit status;
  ``out.print(text)`` writes a line of output, ``out.warn(text)`` a warning on stderr;
* ``user_errors() -> tuple``: the exception types that mean the input was wrong (a folder
  without results, an unknown run id), asked only when the command raised: the CLI prints
  their message as one ``error:`` line, as it does for its own errors; anything else is a
  failure of the command and keeps its traceback.

Every ``dispatch`` call loads the commands to build its parser: a command's module should
import its work when it runs, not when it is loaded.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import dataclass

from dispatch.errors import DispatchError, PluginError
from dispatch.registry import available, load

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Command:
    """An installed command: its name, entry-point target and the loaded class (None where
    it failed to load; ``error`` then says why)."""

    name: str
    target: str
    cls: type | None
    error: PluginError | None = None

    def add_parser(self, sub) -> None:
        """Add this command's sub-parser to ``sub`` (an argparse sub-parsers action); a
        command that failed to load takes any arguments and says why when run."""
        if self.cls is None:
            p = sub.add_parser(self.name, help=f"(failed to load: {self.target})",
                               add_help=False)
            p.add_argument("rest", nargs=argparse.REMAINDER)
            return
        p = sub.add_parser(self.name, help=getattr(self.cls, "help", None))
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
            known = getattr(self.cls, "user_errors", None)
            if known is not None and isinstance(e, tuple(known())):
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
            out[name] = Command(name, target, load("command", name))
        except PluginError as e:
            out[name] = Command(name, target, None, e)
    return out
