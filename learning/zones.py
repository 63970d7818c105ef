"""Zones of a road network: a grid of ``size``-metre squares over its nodes, numbered over the
squares that hold at least one node (so a big region with empty corners costs no table rows).

Used by :mod:`learning.rl` (recent demand per zone in the observations), :mod:`learning.value`
(the value of a vehicle's zone and time of day) and the ``demand`` repositioner
(:mod:`repositioners.demand`: it sends vehicles to zones' centre nodes). Deterministic: the
numbering depends only on the node positions and ``size``.
"""

from __future__ import annotations

import numpy as np


class Zones:
    """``size``-metre grid squares over ``xy`` (the ``(n_nodes, 2)`` node positions, metres).

    ``of_node[i]`` is the zone of node ``i``; :meth:`of_xy` maps positions (``-1`` outside
    every zone); ``n`` zones, numbered by (column, row), ``centres`` their ``(n, 2)`` square
    centres, ``centre_nodes[z]`` the node of zone ``z`` nearest the mean position of its nodes
    (ties: the lowest node index; ``-1``: a zone holding none of these nodes, when ``keys``
    come from elsewhere). ``origin`` and ``keys`` rebuild stored zones (:mod:`learning.value`)."""

    _WIDE = 1 << 31

    def __init__(self, xy: np.ndarray, size: float, origin: np.ndarray | None = None,
                 keys: np.ndarray | None = None) -> None:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if xy.shape[0] == 0:
            raise ValueError("a network without nodes has no zones")
        if not size > 0:
            raise ValueError(f"zone size must be > 0 metres, got {size}")
        self.size = float(size)
        self.origin = xy.min(axis=0) if origin is None else np.asarray(origin, dtype=float)
        node_keys = self._keys(xy)
        self.keys = np.unique(node_keys) if keys is None else np.asarray(keys, dtype=np.int64)
        self.n = int(self.keys.size)
        self.of_node = self._index(node_keys)
        cx, cy = np.divmod(self.keys, self._WIDE)
        self.centres = self.origin + (np.stack([cx, cy], axis=1) + 0.5) * self.size
        self.centre_nodes = self._nearest_mean(xy)

    def _nearest_mean(self, xy: np.ndarray) -> np.ndarray:
        """``centre_nodes`` (see the class) of the nodes at ``xy``."""
        inside = np.flatnonzero(self.of_node >= 0)
        zone, pos = self.of_node[inside], xy[inside]
        counts = np.bincount(zone, minlength=self.n)
        mean = np.column_stack([np.bincount(zone, pos[:, k], minlength=self.n) for k in (0, 1)])
        mean /= np.maximum(counts, 1)[:, None]
        d2 = ((pos - mean[zone]) ** 2).sum(axis=1)
        order = np.lexsort((inside, d2, zone))  # by zone, distance, node index
        first = np.ones(order.size, dtype=bool)
        first[1:] = zone[order][1:] != zone[order][:-1]
        out = np.full(self.n, -1, dtype=np.int64)
        out[zone[order][first]] = inside[order][first]
        return out

    def _keys(self, xy: np.ndarray) -> np.ndarray:
        cell = np.floor((np.asarray(xy, dtype=float).reshape(-1, 2) - self.origin)
                        / self.size).astype(np.int64)
        return cell[:, 0] * self._WIDE + cell[:, 1]

    def _index(self, keys: np.ndarray) -> np.ndarray:
        k = np.searchsorted(self.keys, keys)
        k = np.minimum(k, max(self.n - 1, 0))
        return np.where((self.n > 0) & (self.keys[k] == keys), k, -1).astype(np.int64)

    def of_xy(self, xy: np.ndarray) -> np.ndarray:
        """Zone of each position (``-1``: in no zone)."""
        return self._index(self._keys(xy))
