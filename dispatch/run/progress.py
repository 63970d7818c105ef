"""Progress of a long command when its output is not a terminal: a line a minute on stderr.

On a terminal the CLI draws rich progress bars; in a log file, a pipe or a batch job those
draw nothing, and a long run would be silent. :class:`Heartbeat` prints one line every
:func:`heartbeat_seconds` wall seconds from a daemon thread while the command runs (a run stuck
in one long decision still gets its lines). Only the CLI uses it: library code prints nothing.
"""

from __future__ import annotations

import os
import sys
import time


def heartbeat_seconds() -> float:
    """Wall seconds between two progress lines when the output is not a terminal: 60, or
    ``DISPATCH_HEARTBEAT_S``."""
    try:
        v = float(os.environ.get("DISPATCH_HEARTBEAT_S", "60"))
    except ValueError:
        return 60.0
    return v if v > 0 else 60.0


class Heartbeat:
    """While a command runs with its output not on a terminal (a log file, a pipe, a batch
    job), a line on stderr every :func:`heartbeat_seconds` wall seconds saying where it is
    (``what()``), so that a long run is never silent; nothing on a terminal, where the
    progress bar says it."""

    def __init__(self, console, what) -> None:
        self.on = not console.is_terminal
        self.what = what
        self.started = time.perf_counter()

    def __enter__(self):
        if self.on:
            import threading

            self.stop = threading.Event()
            self.thread = threading.Thread(target=self._beat, name="dispatch-heartbeat",
                                           daemon=True)
            self.thread.start()
        return self

    def _beat(self) -> None:
        every = heartbeat_seconds()
        while not self.stop.wait(every):
            wall = time.perf_counter() - self.started
            try:
                line = self.what()
            except Exception as e:  # noqa: BLE001 - a progress line must never stop a run
                line = f"({type(e).__name__})"
            sys.stderr.write(f"[{wall:6.0f} s] {line}\n")
            sys.stderr.flush()

    def __exit__(self, *exc) -> None:
        if self.on:
            self.stop.set()
            self.thread.join()
