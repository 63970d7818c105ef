"""``--against``: this board next to a previous ``bench.csv`` (the published board, or an
earlier run), flagging the differences beyond the intervals.

A metric of an (instance, allocator) present in both is *flagged* when the two means differ by
more than the two 95 % half-widths added (the intervals do not overlap); a half-width that is
NaN (one seed) counts as 0, so with one seed any difference beyond rounding is flagged. Timing
columns (:data:`bench.metrics.TIMING`) measure the machine and are not flagged."""

from __future__ import annotations

import math
from dataclasses import dataclass

from bench.metrics import METRICS, NOT_RANKED, TIMING
from bench.stats import intervals

#: differences below this (relative to the larger magnitude) are rounding, never flagged
RTOL = 1e-9


@dataclass(frozen=True)
class Difference:
    instance: str
    allocator: str
    metric: str
    before: float
    after: float
    before_half: float
    after_half: float

    def line(self) -> str:
        def iv(m, h):
            return f"{m:.4g}" + ("" if math.isnan(h) else f" ± {h:.2g}")
        return (f"{self.instance} / {self.allocator} / {self.metric}: "
                f"{iv(self.before, self.before_half)} -> {iv(self.after, self.after_half)}")


def compare(before: list[dict], after: list[dict]) -> list[Difference]:
    """The flagged differences between two boards' rows (see the module docstring), in the
    order of ``after``'s instances and allocators."""
    metrics = [m for m in METRICS if m not in TIMING and m not in NOT_RANKED]
    a, b = intervals(after, metrics), intervals(before, metrics)
    out = []
    for key in sorted(a, key=lambda k: (_order(after, k[0], k[1]), metrics.index(k[2]))):
        if key not in b:
            continue
        x, y = b[key], a[key]
        if math.isnan(x.mean) and math.isnan(y.mean):
            continue
        if math.isnan(x.mean) != math.isnan(y.mean):
            out.append(Difference(*key, x.mean, y.mean, x.half, y.half))
            continue
        hx = 0.0 if math.isnan(x.half) else x.half
        hy = 0.0 if math.isnan(y.half) else y.half
        diff = abs(y.mean - x.mean)
        if diff > hx + hy and diff > RTOL * max(abs(x.mean), abs(y.mean)):
            out.append(Difference(*key, x.mean, y.mean, x.half, y.half))
    return out


def _order(rows, instance, allocator) -> int:
    for i, r in enumerate(rows):
        if r["instance"] == instance and r["allocator"] == allocator:
            return i
    return len(rows)
