"""A road run's network, written beside its results for readers that do not rebuild it.

A results folder of road runs holds each network its runs drove on once, under
``_networks/<digest>/`` (``<digest>``: of the network's arrays, so runs on one network share
it and a changed network gets a new folder; the leading ``_`` keeps Hive readers out):

* ``nodes.parquet``: ``x``, ``y`` (float64, metres), one row per node, in node order;
* ``edges.parquet``: ``u``, ``v`` (int64 node indices), ``seconds`` (float64, free-flow),
  ``metres`` (float64), one row per directed edge in CSR order (by ``u``, then ``v``).

Every file of a run names its network's folder, relative to the results folder, in the
``dispatch.network_file`` metadata. The :mod:`analysis` package reads it (the map's streets,
the trips' direct free-flow times) with pyarrow and scipy, without importing ``dispatch``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pyarrow as pa

from dispatch.recorder import write_atomic
from dispatch.roads import RoadNetwork

FOLDER = "_networks"
METADATA_KEY = "dispatch.network_file"


def digest(net: RoadNetwork) -> str:
    """16 hex digits of a hash of the network's positions, edges, times and lengths."""
    h = hashlib.sha256()
    for a in (net.xy, net.time.indptr, net.time.indices, net.time.data, net.length.data):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def store(out: Path | None, space) -> dict[str, str]:
    """Write ``space``'s network under ``out`` (see the module docstring) unless it is there
    already, and return the metadata that names it; ``{}`` for a space without a network, or
    without a folder (``out`` None: a recorder that keeps nothing)."""
    if out is None or not isinstance(space, RoadNetwork):
        return {}
    rel = f"{FOLDER}/{digest(space)}"
    folder = Path(out) / rel
    nodes, edges = folder / "nodes.parquet", folder / "edges.parquet"
    if not (nodes.is_file() and edges.is_file()):  # each written whole (a rename), edges first
        t = space.time
        u = np.repeat(np.arange(space.n, dtype=np.int64), np.diff(t.indptr))
        write_atomic(pa.table({"u": u, "v": t.indices.astype(np.int64),
                               "seconds": np.asarray(t.data, np.float64),
                               "metres": np.asarray(space.length.data, np.float64)}), edges)
        xy = np.asarray(space.xy, np.float64)
        write_atomic(pa.table({"x": xy[:, 0], "y": xy[:, 1]}), nodes)
    return {METADATA_KEY: rel}
