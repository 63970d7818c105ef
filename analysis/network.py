"""The road network of a road run, rebuilt from its Parquet metadata, for what the tables do
not hold: the map's edges and the trips' direct free-flow times.

The run's files carry the scenario text (``dispatch.scenario``); its ``[world]`` names the
network (``"manhattan"`` with ``blocks``, ``block``, ``speed``; ``"chicago"``; a file). Rebuilding
it needs the ``dispatch`` package (numpy, scipy, networkx; no PyBullet, no torch). Where that
package is missing, or a network file named relative to the scenario cannot be found from here,
:func:`road_network` returns None and the callers do without (a map without streets; the
detour ratio NaN). Nothing here is imported by :mod:`analysis` at import time.
"""

from __future__ import annotations

import logging
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Network:
    """What the analysis needs of a road network: node positions (metres), the directed edges
    as index pairs, and a way to get free-flow shortest-path seconds between nodes."""

    name: str
    xy: np.ndarray  # (n, 2) metres
    edges: np.ndarray  # (e, 2) node indices
    net: object  # dispatch.roads.RoadNetwork

    def nodes_at(self, xy: np.ndarray) -> np.ndarray:
        """The index of the node at each position (the nearest node; trips' pickups and
        drop-offs lie on nodes)."""
        idx, _ = self.net.nearest(np.asarray(xy, dtype=float).reshape(-1, 2))
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
        block = 256
        for s in range(0, uniq.size, block):
            rows = self.net.distances_from(uniq[s:s + block])
            pick = (inv >= s) & (inv < s + block)
            out[pick] = rows[inv[pick] - s, dests[pick]]
        return out


def _world(scenario_text: str) -> dict | None:
    try:
        return tomllib.loads(scenario_text).get("world", {})
    except tomllib.TOMLDecodeError:
        return None


def road_network(metadata: dict[str, str], search: list[Path] | None = None) -> Network | None:
    """The network of the run whose schema ``metadata`` is given (see the module docstring),
    or None where it cannot be rebuilt here. A network file is looked for relative to each
    folder of ``search`` (e.g. the results folder, the current folder)."""
    if metadata.get("dispatch.space") != "road":
        return None
    world = _world(metadata.get("dispatch.scenario", ""))
    if world is None or "network" not in world:
        return None
    try:
        from dispatch.roads import load_network
    except ImportError:
        log.info("the dispatch package is not installed: no road network for the map")
        return None
    kw = {k: world[k] for k in ("blocks", "block", "speed") if k in world}
    bases = [Path.cwd(), Path.cwd() / "scenarios", *(search or [])]
    for base in bases:
        try:
            net = load_network(str(world["network"]), base=base, **kw)
            break
        except (ValueError, OSError):
            continue
    else:
        log.info("road network %r not found from %s", world["network"], bases)
        return None
    t = net.time.tocoo()
    edges = np.column_stack([t.row, t.col]).astype(np.int64)
    return Network(str(world["network"]), np.asarray(net.xy, dtype=float)[:, :2], edges, net)


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
