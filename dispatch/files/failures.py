"""Breakdown files (``[faults] file``): rows ``t, vehicle_id, duration`` (CSV)."""

from __future__ import annotations

import csv
import io
import math

from dispatch.errors import ScenarioError
from dispatch.files.tables import decode_text, read_bytes

MAX_FILE_BYTES = 64 * 2**20  # a breakdown file is a few lines per vehicle


def read_failures(path) -> tuple[tuple[float, int, float], ...]:
    """Rows ``(t, vehicle_id, duration)`` of a breakdown file (CSV), sorted by time."""
    text = decode_text(path, read_bytes(path, MAX_FILE_BYTES, "breakdown file"))
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        rows = list(reader)
        names = reader.fieldnames or []
    except csv.Error as e:
        raise ScenarioError(path, "<file>", f"cannot be read as CSV: {e}") from None
    missing = [c for c in ("t", "vehicle_id", "duration") if c not in names]
    if missing:
        raise ScenarioError(path, "<header>", f"missing column(s): {', '.join(missing)}")
    out = []
    for i, r in enumerate(rows, 1):
        try:
            t, vid, dur = float(r["t"]), float(r["vehicle_id"]), float(r["duration"])
        except (TypeError, ValueError):
            raise ScenarioError(path, f"row {i}", "t, vehicle_id and duration must be numbers "
                                                  "(duration may be inf)") from None
        if not (math.isfinite(t) and t >= 0):
            raise ScenarioError(path, f"row {i}", f"t = {r['t']} is not a time >= 0")
        if vid != int(vid) or vid < 0:
            raise ScenarioError(path, f"row {i}", f"vehicle_id {r['vehicle_id']} is not an id")
        if math.isnan(dur) or dur <= 0:
            raise ScenarioError(path, f"row {i}", f"duration {r['duration']} is not > 0")
        out.append((t, int(vid), dur))
    return tuple(sorted(out, key=lambda x: x[0]))
