"""``[fleet.breaks]``: drivers' breaks, as data (the rule: :mod:`dispatch.plan.breaks`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BreaksConfig:
    """A break of ``duration`` seconds falls due after ``after`` seconds on duty (from the
    shift's start, or the run's, and again from the end of each break). The defaults are the
    EU's rule for drivers (Regulation (EC) No 561/2006, art. 7): 45 minutes after 4.5 hours."""

    #: seconds on duty before a break is due
    after: float = 16200.0
    #: seconds a break lasts
    duration: float = 2700.0
