"""The fleet-sizer checks (``dispatch check NAME`` of a sizer, :mod:`dispatch.api.sizer`), on
fixed views of a fleet (quiet and busy, without a look yet, every vehicle on duty, none in
the pool): ``construct`` (and its ``interval`` a positive number of seconds), ``valid``
(``initial`` and ``size`` an int from 0 to the vehicles on duty plus the pool),
``deterministic`` and ``rng`` (:func:`dispatch.checks.common.replay`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dispatch.api.sizer import SizingView
from dispatch.checks.common import Report, add_replayed, constructed, first_answer

#: (label, on_duty, busy, pool, utilization, unserved)
VIEWS = [("no look yet", 10, 0, 5, math.nan, math.nan), ("quiet", 10, 1, 5, 0.1, 0.0),
         ("busy, riders unserved", 10, 10, 5, 0.97, 0.3), ("no pool", 8, 8, 0, 1.0, 0.5),
         ("all in the pool", 0, 0, 12, math.nan, 1.0)]


def check_sizer(cls, *, seed: int = 0, **params: Any) -> Report:
    """Run every sizer check (see the module docstring) on ``cls(**params)``."""
    report, _ = constructed("sizer", cls, params)
    if not report.ok:
        return report
    every = cls(**params).interval
    if not (isinstance(every, (int, float)) and math.isfinite(every) and every > 0):
        report.add("interval", [f"interval is {every!r}, not a positive number of seconds"], "")
        return report

    def answers():
        s = cls(**params)
        out = []
        for label, on, busy, pool, util, unserved in VIEWS:
            view = SizingView(3600.0, on, busy, pool, util, np.random.default_rng(seed),
                              unserved)
            out.append((s.initial(view), s.size(view)))
        return out

    ok, first = first_answer(report, answers, "initial or size")
    if not ok:
        return report
    bad = []
    for (label, on, _, pool, _, _), pair in zip(VIEWS, first):
        for what, n in zip(("initial", "size"), pair):
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)) \
                    or not 0 <= n <= on + pool:
                bad.append(f"{label}: {what} answered {n!r}, not an int from 0 to {on + pool}")
    report.add("valid", bad, f"{len(VIEWS)} views, initial and size within the fleet")
    add_replayed(report, lambda: [tuple(int(x) for x in p) for p in answers()],
                 [tuple(int(x) for x in p) for p in first], "views and seed", "sizes")
    return report
