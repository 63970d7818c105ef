"""Intervals over seeds and paired differences against the reference allocator, on the rows of
``bench.csv`` (dicts with :data:`bench.metrics.COLUMNS`).

* :func:`intervals`: per (instance, allocator, metric) the mean over the seeds whose run is
  ``ok`` and finite, and the half-width of its 95 % Student-t interval
  (:func:`paired.stats.mean_ci`; NaN with one seed).
* :func:`paired_differences`: per (instance, allocator, metric) the mean of ``allocator's value
  - reference's value`` over the seeds where both ran, with the same interval: the seeds pair
  the runs (same instance, same draws), so the interval is that of the differences, narrower
  than the two intervals side by side.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

from bench.metrics import METRICS
from bench.suite import REFERENCE
from paired.stats import mean_ci


@dataclass(frozen=True)
class Interval:
    mean: float
    half: float  # half-width of the 95 % interval (NaN: fewer than two values)
    n: int


def _ok(row) -> bool:
    return row.get("status") == "ok"


def _finite(v) -> bool:
    try:
        return v is not None and math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def fill_gaps(rows: list[dict], reference: str = REFERENCE) -> None:
    """Set each row's ``gap``: its ``cost_per_assignment`` relative to the reference's run of
    the same instance and seed, ``(c - c_ref) / c_ref`` (NaN without one, or where it is not
    positive). In place."""
    ref = {(r["instance"], int(r["seed"])): r.get("cost_per_assignment")
           for r in rows if r["allocator"] == reference and _ok(r)}
    for r in rows:
        c, c0 = r.get("cost_per_assignment"), ref.get((r["instance"], int(r["seed"])))
        r["gap"] = ((float(c) - float(c0)) / float(c0)
                    if _ok(r) and _finite(c) and _finite(c0) and float(c0) > 0 else math.nan)


def intervals(rows: list[dict], metrics=METRICS) -> dict[tuple[str, str, str], Interval]:
    """``(instance, allocator, metric) -> Interval`` over the seeds (ok runs, finite values)."""
    values: dict[tuple, list[float]] = defaultdict(list)
    seen = set()
    for r in rows:
        seen.add((r["instance"], r["allocator"]))
        if not _ok(r):
            continue
        for m in metrics:
            if _finite(r.get(m)):
                values[(r["instance"], r["allocator"], m)].append(float(r[m]))
    out = {}
    for inst, alloc in seen:
        for m in metrics:
            out[(inst, alloc, m)] = Interval(*mean_ci(values.get((inst, alloc, m), [])))
    return out


def paired_differences(rows: list[dict], reference: str = REFERENCE,
                       metrics=METRICS) -> dict[tuple[str, str, str], Interval]:
    """``(instance, allocator, metric) -> Interval`` of ``value - reference's value`` over the
    seeds where both runs are ok and finite (the reference itself is left out)."""
    ref = {(r["instance"], int(r["seed"])): r for r in rows
           if r["allocator"] == reference and _ok(r)}
    diffs: dict[tuple, list[float]] = defaultdict(list)
    seen = set()
    for r in rows:
        if r["allocator"] == reference:
            continue
        seen.add((r["instance"], r["allocator"]))
        base = ref.get((r["instance"], int(r["seed"])))
        if base is None or not _ok(r):
            continue
        for m in metrics:
            if _finite(r.get(m)) and _finite(base.get(m)):
                diffs[(r["instance"], r["allocator"], m)].append(float(r[m]) - float(base[m]))
    return {(i, a, m): Interval(*mean_ci(diffs.get((i, a, m), [])))
            for i, a in seen for m in metrics}
