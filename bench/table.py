"""``bench.csv``: writing it, and reading one back (ours, or a published board for
``--against``) with one clear error where it is not a bench table."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from bench.metrics import COLUMNS, KEYS, METRICS


class BenchFileError(ValueError):
    """A ``bench.csv`` that cannot be read as one (the CLI prints its message as one line)."""


def _cell(v) -> str:
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    return str(v)


def write_csv(rows: list[dict], path: Path) -> None:
    """The rows with exactly :data:`COLUMNS`, in order (NaN as an empty cell)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([_cell(r.get(c, math.nan)) for c in COLUMNS])
    tmp.replace(path)


def read_csv(path: Path) -> list[dict]:
    """The rows of a ``bench.csv`` (metrics as floats, NaN for empty cells, seeds as ints);
    :class:`BenchFileError` naming the file and what is wrong otherwise."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            missing = [c for c in (*KEYS, "status") if c not in header]
            if missing:
                raise BenchFileError(f"{path}: not a bench.csv (no column "
                                     f"{', '.join(missing)})")
            rows = []
            for line, r in enumerate(reader, start=2):
                try:
                    row = {k: r[k] for k in (*KEYS, "status")}
                    row["seed"] = int(row["seed"])
                    for m in METRICS:
                        v = r.get(m)
                        row[m] = math.nan if v in (None, "") else float(v)
                except (TypeError, ValueError) as e:
                    raise BenchFileError(f"{path}: line {line}: {e}") from None
                rows.append(row)
    except OSError as e:
        raise BenchFileError(f"{path}: cannot read: {e.strerror or e}") from None
    except (UnicodeDecodeError, csv.Error) as e:
        raise BenchFileError(f"{path}: not a CSV file: {e}") from None
    return rows
