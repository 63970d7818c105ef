"""The road network of a road run, read from the results folder, for what the tables do not
hold: the map's edges and the trips' direct free-flow times.

A road run writes its network once per results folder, under ``_spaces/road-<digest>/``
(``nodes.parquet``: x, y; ``edges.parquet``: u, v, seconds, metres), and names that folder in
its files' ``dispatch.output.space_files`` metadata (the writer:
``dispatch/output/space_files.py``). This
module reads it with pyarrow and scipy and needs nothing of ``dispatch``. Where the folder
cannot be found (a folder written before networks were stored, or copied without
``_spaces/``), :func:`road_network` returns None and the callers do without (a map without
streets; the detour ratio NaN). Nothing here is imported by :mod:`analysis` at import time.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

log = logging.getLogger(__name__)

#: the metadata key that names a run's space folder, relative to its results folder
METADATA_KEY = "dispatch.output.space_files"
#: origins per Dijkstra call (bounds the ``(block, n)`` distance array)
BLOCK = 256


@dataclass(frozen=True)
class Network:
    """What the analysis needs of a road network: node positions (metres), the directed edges
    as index pairs, and their free-flow seconds (for shortest-path times between nodes)."""

    name: str
    xy: np.ndarray  # (n, 2) metres
    edges: np.ndarray  # (e, 2) node indices
    seconds: np.ndarray  # (e,) free-flow seconds of each edge

    @cached_property
    def _time(self) -> csr_matrix:
        n = self.xy.shape[0]
        return csr_matrix((self.seconds, (self.edges[:, 0], self.edges[:, 1])), shape=(n, n))

    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.xy)

    def nodes_at(self, xy: np.ndarray) -> np.ndarray:
        """The index of the node at each position (the nearest node; trips' pickups and
        drop-offs lie on nodes)."""
        _, idx = self._tree.query(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return np.asarray(idx, dtype=np.int64)

    def free_flow_seconds(self, origins: np.ndarray, dests: np.ndarray) -> np.ndarray:
        """Free-flow seconds of the fastest path from each origin node to its destination node
        (one Dijkstra per distinct origin)."""
        origins = np.asarray(origins, dtype=np.int64)
        dests = np.asarray(dests, dtype=np.int64)
        out = np.full(origins.size, np.nan)
        if origins.size == 0:
            return out
        uniq, inv = np.unique(origins, return_inverse=True)
        for s in range(0, uniq.size, BLOCK):
            rows = dijkstra(self._time, indices=uniq[s:s + BLOCK])
            pick = (inv >= s) & (inv < s + BLOCK)
            out[pick] = rows[inv[pick] - s, dests[pick]]
        return out


def _name(scenario_text: str) -> str:
    """The network's name as the scenario gives it (``[world] network``), else ``"road"``."""
    try:
        return str(tomllib.loads(scenario_text).get("world", {}).get("network", "road"))
    except tomllib.TOMLDecodeError:
        return "road"


def read_network(folder: Path, name: str = "road") -> Network:
    """The network stored in ``folder`` (``nodes.parquet``, ``edges.parquet``)."""
    nodes = pq.read_table(folder / "nodes.parquet")
    edges = pq.read_table(folder / "edges.parquet")
    xy = np.column_stack([nodes.column("x").to_numpy(), nodes.column("y").to_numpy()])
    uv = np.column_stack([edges.column("u").to_numpy(), edges.column("v").to_numpy()])
    return Network(name, xy.astype(np.float64), uv.astype(np.int64),
                   edges.column("seconds").to_numpy().astype(np.float64))


def road_network(metadata: dict[str, str], search: list[Path] | None = None) -> Network | None:
    """The network of the run whose schema ``metadata`` is given (see the module docstring),
    or None where it cannot be found. Its folder is looked for relative to each folder of
    ``search`` (the results folders), then the current folder."""
    if metadata.get("dispatch.space") != "road":
        return None
    rel = metadata.get(METADATA_KEY)
    if not rel:
        log.info("no network stored with this run (written before networks were stored): "
                 "no streets on the map, no detour ratio")
        return None
    bases = [*(search or []), Path.cwd()]
    for base in bases:
        folder = Path(base) / rel
        if (folder / "nodes.parquet").is_file() and (folder / "edges.parquet").is_file():
            return read_network(folder, _name(metadata.get("dispatch.scenario", "")))
    log.info("road network %s not found under %s", rel, bases)
    return None


def direct_seconds(tasks: pd.DataFrame, network: Network | None) -> np.ndarray:
    """Per row of ``tasks``: the free-flow seconds of the fastest path from its pickup to its
    drop-off (NaN without a drop-off or a network)."""
    out = np.full(len(tasks), np.nan)
    if network is None or tasks.empty or "dropoff_x" not in tasks:
        return out
    has = tasks["dropoff_x"].notna().to_numpy()
    if not has.any():
        return out
    sub = tasks.loc[has]
    o = network.nodes_at(sub[["x", "y"]].to_numpy(dtype=float))
    d = network.nodes_at(sub[["dropoff_x", "dropoff_y"]].to_numpy(dtype=float))
    out[has] = network.free_flow_seconds(o, d)
    return out
