"""Warnings held back while a command sets up, so that a refusal reads as one line.

A scenario that is refused part-way through its set-up (a shift file's depot off the network,
found after the trips were read) would otherwise print the warnings of the steps before it (trips
left out) and then the error: two kinds of line for one mistake, and the warnings describe a
run that never happens. The CLI routes log records through :class:`HeldRecords`: they wait
until the command's set-up is over (:meth:`pass_on`: the run's first progress report, its first
finished run, or the command's end) and are forgotten if it is refused (:meth:`forget`)."""

from __future__ import annotations

import logging


class HeldRecords(logging.Handler):
    """A handler that passes records to ``target`` once released, holding them until then.
    After :meth:`pass_on` or :meth:`forget` records pass straight through."""

    def __init__(self, target: logging.Handler) -> None:
        super().__init__(level=target.level)
        self.target = target
        self.held: list[logging.LogRecord] | None = []

    def emit(self, record: logging.LogRecord) -> None:
        if self.held is None:
            self.target.handle(record)
        else:
            self.held.append(record)

    def pass_on(self) -> None:
        """Write the records held so far, in order; from now on records are not held."""
        held, self.held = self.held, None
        for record in held or ():
            self.target.handle(record)

    def forget(self) -> int:
        """Forget the records held so far (the command was refused); returns how many."""
        held, self.held = self.held, None
        return len(held or ())


def hold_root() -> HeldRecords | None:
    """Route the root logger's handlers through one :class:`HeldRecords` (after
    ``logging.basicConfig``); None when the root logger has no handler to hold for."""
    root = logging.getLogger()
    if len(root.handlers) != 1:
        return None
    if isinstance(root.handlers[0], HeldRecords):  # a second command in this process
        root.handlers[0].held = []
        return root.handlers[0]
    held = HeldRecords(root.handlers[0])
    root.handlers[:] = [held]
    return held


def release_root() -> None:
    """Release the root logger's held records, if it holds any (see :func:`hold_root`)."""
    for handler in logging.getLogger().handlers:
        if isinstance(handler, HeldRecords):
            handler.pass_on()
