"""Reading a sweep folder by hand (file by file, partition values parsed from the path), to
check the analysis package against an independent computation."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq


def read_hive_rows(table_dir: Path) -> list[dict]:
    """Every row of every ``part-*.parquet`` below ``table_dir``, with the ``key=value`` folders
    of its path added (integers where they parse)."""
    rows = []
    for f in sorted(Path(table_dir).rglob("part-*.parquet")):
        keys = {}
        for part in f.relative_to(table_dir).parent.parts:
            k, _, v = part.partition("=")
            keys[k] = int(v) if v.lstrip("-").isdigit() else v
        rows += [{**r, **keys} for r in pq.read_table(f).to_pylist()]
    return rows
