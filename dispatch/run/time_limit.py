"""A wall-clock limit for one run of a sweep (``sweep(time_limit=...)``, ``dispatch bench
--time-limit``): :func:`time_limit_of` stops the run with :class:`PastTimeLimit` once its time
is up, by a timer where one can run, else at the simulation's next progress tick."""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


class PastTimeLimit(BaseException):
    """A run of a sweep stopped at its wall-clock limit (``sweep(time_limit=...)``); its
    failure row in the errors table has this type and the seconds it ran. A BaseException,
    as KeyboardInterrupt is: the timer may fire inside a plugin, whose ``except Exception``
    must not turn it into an error of its own."""


@contextmanager
def time_limit_of(seconds: float) -> Iterator[Callable[[float, float, int, int], None]]:
    """While in the block, a run stops with :class:`PastTimeLimit` once ``seconds`` of wall
    time have passed: by ``SIGALRM`` in whatever it is doing (in the main thread, on POSIX:
    one decision may take minutes), else at its next progress tick. Yields the progress
    callback (:class:`dispatch.run.sim.Simulation`'s, called every ``duration / PROGRESS_TICKS``
    simulated seconds), which also keeps where the run was for the message."""
    started = time.perf_counter()
    at = [math.nan, math.nan, 0, 0]  # simulated time, duration, released, closed

    def past() -> PastTimeLimit:
        now, duration, released, closed = at
        where = (f" at {now:,.0f} of {duration:,.0f} simulated s ({released:,} requests "
                 f"released, {closed:,} closed)" if now == now else "")
        return PastTimeLimit(f"past its limit of {seconds:.0f} s of wall time{where}")

    def check(now: float, duration: float, released: int, closed: int) -> None:
        at[:] = [now, duration, released, closed]
        if time.perf_counter() - started > seconds:
            raise past()

    if sys.platform == "win32" or threading.current_thread() is not threading.main_thread():
        yield check
        return

    def alarm(signum, frame):
        raise past()

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, max(seconds, 1e-3))
    try:
        yield check
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
