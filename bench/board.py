"""The board ``dispatch bench`` prints: per group of the suite (robots, fleets) a table of three
columns that fits 80 characters, each cell the mean over the seeds ± the half-width of its 95 %
interval, ``*`` where the paired difference to hungarian (same seeds) excludes 0. Every column
of every instance is in ``bench.md``; this is its summary."""

from __future__ import annotations

import math

from bench.report import _fmt, _group, _ordered
from bench.stats import intervals, paired_differences
from bench.suite import REFERENCE

#: group -> the columns printed: (metric, heading, scale)
PRINTED = {"robots": (("gap", "gap to hungarian %", 100.0),
                      ("conflict_free_share", "conflict-free %", 100.0),
                      ("ms_per_decision", "ms per decision", 1.0)),
           "fleets": (("served_share", "served %", 100.0),
                      ("wait_mean", "wait s", 1.0),
                      ("ms_per_decision", "ms per decision", 1.0))}


def _cell(iv, scale: float, star: bool) -> str:
    if math.isnan(iv.mean):
        return "–"
    half = "" if math.isnan(iv.half) else f" ± {_fmt(iv.half * scale)}"
    return f"{_fmt(iv.mean * scale)}{half}{'*' if star else ''}"


def board_tables(rows: list[dict]) -> list:
    """The printed board of ``rows`` (``bench.csv``'s): per group present a title line and a
    :class:`rich.table.Table` (no edge: a box's edges are lines of spaces), instances in the
    suite's order, each instance's allocators below its name."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    ivs, diffs = intervals(rows), paired_differences(rows)
    tables = []
    for group, columns in PRINTED.items():
        order = [(i, a) for i, a in _ordered(rows) if _group(i, rows) == group]
        if not order:
            continue
        t = Table(box=box.SIMPLE_HEAD, pad_edge=False, show_edge=False)
        t.add_column("instance / allocator", no_wrap=True)
        for _, heading, _ in columns:
            t.add_column(heading, justify="right", no_wrap=True)
        for instance, allocs in order:
            seeds = sorted({r["seed"] for r in rows if r["instance"] == instance})
            t.add_row(Text(f"{instance} ({len(seeds)} seed{'s' * (len(seeds) != 1)})",
                           style="bold"), *[""] * len(columns))
            for a in allocs:
                status = {r["status"] for r in rows if r["instance"] == instance
                          and r["allocator"] == a}
                if status and "ok" not in status:  # unsupported, failed, past the time limit
                    why = sorted(status)[0].split(":")[0]
                    t.add_row(f"  {a}", Text(why, style="dim"), *[""] * (len(columns) - 1))
                    continue
                cells = []
                for metric, _, scale in columns:
                    d = diffs.get((instance, a, metric))
                    star = (a != REFERENCE and d is not None and not math.isnan(d.half)
                            and abs(d.mean) > d.half)
                    cells.append(_cell(ivs[(instance, a, metric)], scale, star))
                t.add_row(f"  {a}", *cells)
        tables.append((f"{group}: mean ± 95 % half-width over the seeds", t))
    return tables


def interval_note(rows: list[dict]) -> str:
    """What the intervals rest on: the seeds per instance, and how wide an interval of so few
    seeds is (the Student-t factor of the half-width over the standard error)."""
    from scipy.stats import t as student

    counts = sorted({len({r["seed"] for r in rows if r["instance"] == i})
                     for i, _ in _ordered(rows)})
    low = counts[0] if counts else 0
    seeds = f"{low}" if len(counts) <= 1 else f"{low} to {counts[-1]}"
    factor = (f": ± is {student.ppf(0.975, low - 1):.1f} standard errors" if low >= 2
              else ": one seed gives no interval")
    return (f"{seeds} seed(s) per instance{factor} (--seeds K: more seeds)\n"
            f"* : differs from {REFERENCE} beyond the paired interval (same seeds)")
