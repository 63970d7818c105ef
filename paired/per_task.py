"""The per-task figures of a run, from its summary: one definition for the CLI's tables
(:mod:`dispatch.output.printed`, on summary dicts) and :mod:`analysis.metrics` (on a DataFrame's
rows).

Planned costs summed over a dynamic run are not comparable between allocators that drive
different trajectories and serve different numbers of tasks, so the tables of dynamic runs
compare these instead: ``served_share`` (completed / released), ``wait_mean`` (release to
pickup, seconds, the summary's ``wait_time_mean``), ``cost_per_assignment`` (planned cost per
assigned task) and ``decision_ms`` (wall milliseconds of allocation per decision). Each is NaN
where its inputs are missing or not numbers, or its denominator is not positive. Standard
library only (see :mod:`paired`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

#: the figures :func:`per_task` gives, in the tables' order
PER_TASK = ("served_share", "wait_mean", "cost_per_assignment", "decision_ms")


def number(v: Any) -> float:
    """``v`` as a float; NaN for None or anything that is not a number."""
    try:
        return math.nan if v is None else float(v)
    except (TypeError, ValueError):
        return math.nan


def ratio(num: Any, den: Any) -> float:
    """``num / den`` as floats; NaN where either is not a number or ``den`` is not positive."""
    n, d = number(num), number(den)
    return n / d if d > 0 and not math.isnan(n) else math.nan


def per_task(summary: Mapping[str, Any]) -> dict[str, float]:
    """The :data:`PER_TASK` figures of one run's summary row (a missing key reads as NaN)."""
    s = summary.get
    return {"served_share": ratio(s("tasks_completed"), s("n_tasks")),
            "wait_mean": number(s("wait_time_mean")),
            "cost_per_assignment": ratio(s("total_cost"), s("tasks_assigned")),
            "decision_ms": ratio(1000 * number(s("alloc_seconds")), s("decisions"))}
