"""What of a run's space its results folder keeps once, for readers that do not rebuild the
space (the :mod:`analysis` package, which imports nothing of ``dispatch``).

A space's :meth:`~dispatch.api.space.Space.shared_tables` (a road network: ``nodes`` and ``edges``)
are written under ``_spaces/<kind>-<digest>/<name>.parquet`` (``<digest>``: of the tables'
contents, so runs on one space share the folder and a changed space gets a new one; the
leading ``_`` keeps Hive readers out), each file whole (a rename) and only where it is not
there yet; a temporary file a killed run left beside it is removed. Every file of a run names
that folder, relative to the results folder, in the ``dispatch.output.space_files`` metadata.
A road network's columns: ``nodes.parquet`` ``x``, ``y`` (float64 metres, node order);
``edges.parquet`` ``u``, ``v`` (int64 node indices), ``seconds`` (float64 free-flow),
``metres`` (float64), in CSR order (by ``u``, then ``v``).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pyarrow as pa

from dispatch.output.parquet import arrow_column, write_atomic
from dispatch.output.stale import remove_stale_temps

FOLDER = "_spaces"
METADATA_KEY = "dispatch.output.space_files"


def digest(tables: dict[str, dict[str, np.ndarray]]) -> str:
    """16 hex digits of a hash of the tables' names, columns and values."""
    h = hashlib.sha256()
    for name in sorted(tables):
        for col in sorted(tables[name]):
            a = np.ascontiguousarray(tables[name][col])
            h.update(f"{name}.{col}:{a.dtype.str}:{a.size};".encode())
            h.update(a.tobytes())
    return h.hexdigest()[:16]


def store(out: Path | None, space) -> dict[str, str]:
    """Write ``space``'s shared tables under ``out`` (see the module docstring) unless they
    are there already, and return the metadata that names their folder; ``{}`` for a space
    without any, or without a folder (``out`` None: a recorder that keeps nothing)."""
    tables = space.shared_tables()
    if out is None or not tables:
        return {}
    rel = f"{FOLDER}/{space.kind}-{digest(tables)}"
    folder = Path(out) / rel
    for name, columns in sorted(tables.items()):
        path = folder / f"{name}.parquet"
        if not path.is_file():
            # (arrow_column: the arrays pa.table would make, without its import of pandas,
            # about half a second inside a run)
            arrays = {k: np.asarray(v) for k, v in columns.items()}
            write_atomic(pa.table({k: arrow_column(a, pa.from_numpy_dtype(a.dtype))
                                   for k, a in arrays.items()}), path)
        else:  # (a run killed while it wrote the file leaves its temporary name)
            remove_stale_temps(path)
    return {METADATA_KEY: rel}
