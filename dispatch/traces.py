"""Task traces: a CSV or Parquet file of release times and positions, validated row by row."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from dispatch.errors import ScenarioError

TIME_COLUMNS = ("release_time", "t")


def read_trace(path: Path, size: tuple[float, float, float]) -> tuple[tuple[float, ...], ...]:
    """Rows ``(release_time, x, y, z)`` sorted by time (stable), positions in metres.

    Columns: ``release_time`` (or ``t``), ``x``, ``y``, ``z``; other columns are ignored. A bad
    row (missing or non-numeric value, negative time, position outside the world) raises a
    ScenarioError naming the file and the 1-based data row number.
    """
    if not path.is_file():
        raise ScenarioError(path, "<file>", "trace file not found")
    suffix = path.suffix.lower()
    try:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            columns = pq.read_table(path).to_pydict()
        elif suffix == ".csv":
            with path.open(newline="", encoding="utf-8-sig") as fh:
                reader = csv.DictReader(fh)
                data = list(reader)
                names = reader.fieldnames or []
            columns = {n: [r.get(n) for r in data] for n in names}
        else:
            raise ScenarioError(path, "<file>", "trace must be a .csv or .parquet file")
    except ScenarioError:
        raise
    except Exception as e:  # pyarrow raises several kinds for a malformed file
        raise ScenarioError(path, "<file>", f"cannot be read as a trace: {e}") from None
    tcol = next((c for c in TIME_COLUMNS if c in columns), None)
    missing = [c for c in ("x", "y", "z") if c not in columns] + ([] if tcol else ["release_time"])
    if missing:
        raise ScenarioError(path, "<header>", f"missing column(s): {', '.join(missing)}")
    rows = []
    for i, values in enumerate(zip(columns[tcol], columns["x"], columns["y"], columns["z"]), 1):
        row = []
        for name, v in zip((tcol, "x", "y", "z"), values):
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ScenarioError(path, f"row {i}", f"{name} is not a number ({v!r})") from None
            if not math.isfinite(f):
                raise ScenarioError(path, f"row {i}", f"{name} is not finite ({v!r})")
            row.append(f)
        if row[0] < 0:
            raise ScenarioError(path, f"row {i}", f"release time {row[0]} is negative")
        for name, v, s in zip("xyz", row[1:], size):
            if not 0 <= v < s:
                raise ScenarioError(path, f"row {i}", f"{name} = {v} is outside the world [0, {s})")
        rows.append(tuple(row))
    rows.sort(key=lambda r: r[0])
    return tuple(rows)
