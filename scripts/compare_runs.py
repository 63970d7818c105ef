"""Are two result folders the same run? Table by table, row by row, value by value.

Compares every ``part-0.parquet`` under folder A with the file at the same relative path under
folder B (``dispatch run --out A`` before a change, ``--out B`` after it): same files, same
columns, same rows in the same order, every value exactly equal (NaN equal to NaN), leaving out
only the wall-clock figures, which differ between identical runs: the timing columns
(:data:`dispatch.output.parquet.TIMING_COLUMNS`) and the solver seconds an allocator writes into
``allocator_info`` (:data:`TIMING_KEYS`). Prints one line per file and exits 1 at the first
difference it describes.

With ``--common`` the columns only B has (a version that added columns) and the files only B
has (a version that added tables) are listed and left out; every column both have must still
hold the same values.

Run: ``PYTHONPATH=. .venv/bin/python scripts/compare_runs.py [--common] runs/before runs/after``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.output.parquet import TIMING_COLUMNS  # noqa: E402


def files(folder: Path) -> dict[Path, Path]:
    return {p.relative_to(folder): p for p in sorted(folder.rglob("part-0.parquet"))}


#: keys of the summary's ``allocator_info`` JSON that an allocator fills from its own clock
#: (``rtv``'s solver seconds): wall-clock figures, which differ between identical runs
TIMING_KEYS = {"seconds", "seconds_max"}


def _without_timing(info):
    """``allocator_info`` text with its wall-clock keys left out (other text as it is)."""
    try:
        d = json.loads(info)
    except (TypeError, ValueError):
        return info
    if not isinstance(d, dict):
        return info
    return json.dumps({k: v for k, v in d.items() if k not in TIMING_KEYS}, sort_keys=True)


def differ(a: Path, b: Path, common: bool = False) -> str | None:
    """None if the two files hold the same rows (timing columns aside), else what differs;
    ``common``: only the columns of A, which B must all have (B may have more)."""
    ta, tb = pq.read_table(a), pq.read_table(b)
    if common and set(ta.column_names) <= set(tb.column_names):
        tb = tb.select(ta.column_names)
    if ta.column_names != tb.column_names:
        return f"columns {ta.column_names} != {tb.column_names}"
    if ta.num_rows != tb.num_rows:
        return f"{ta.num_rows} rows != {tb.num_rows} rows"
    for name in ta.column_names:
        if name in TIMING_COLUMNS:
            continue
        x = ta.column(name).to_numpy(zero_copy_only=False)
        y = tb.column(name).to_numpy(zero_copy_only=False)
        if name == "allocator_info":
            x = np.array([_without_timing(v) for v in x], dtype=object)
            y = np.array([_without_timing(v) for v in y], dtype=object)
        if x.dtype.kind == "f":
            same = (x == y) | (np.isnan(x) & np.isnan(y))
        else:
            same = x == y
        if not np.all(same):
            k = int(np.flatnonzero(~same)[0])
            return (f"column {name!r}: {int((~same).sum())} value(s) differ, first at row {k}: "
                    f"{x[k]!r} != {y[k]!r}")
    return None


def main() -> int:
    args = sys.argv[1:]
    common = "--common" in args
    args = [x for x in args if x != "--common"]
    if len(args) != 2:
        print(__doc__.strip().splitlines()[-1])
        return 2
    a, b = Path(args[0]), Path(args[1])
    fa, fb = files(a), files(b)
    if not fa:
        print(f"no part-0.parquet under {a}")
        return 1
    if common and fa.keys() < fb.keys():
        for rel in sorted(fb.keys() - fa.keys()):
            print(f"      new in B, left out: {rel}")
        fb = {k: fb[k] for k in fa}
    if fa.keys() != fb.keys():
        print(f"different files: only in A {sorted(map(str, fa.keys() - fb.keys()))}, "
              f"only in B {sorted(map(str, fb.keys() - fa.keys()))}")
        return 1
    for rel in fa:
        why = differ(fa[rel], fb[rel], common)
        if common and why is None:
            new = sorted(set(pq.read_schema(fb[rel]).names) - set(pq.read_schema(fa[rel]).names))
            if new:
                print(f"      new in B, left out: {', '.join(new)}")
        rows = pq.ParquetFile(fa[rel]).metadata.num_rows
        print(f"{'same' if why is None else 'DIFFERENT'}  {rel}  ({rows} rows)"
              + ("" if why is None else f": {why}"))
        if why is not None:
            return 1
    print(f"{len(fa)} files, all the same (wall-clock columns and allocator_info's solver seconds left out)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
