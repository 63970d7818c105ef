"""Zones over a road network's nodes: a regular grid of square cells in metres."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Zones:
    """A partition of the nodes into ``count`` zones: ``of_node[i]`` is node ``i``'s zone;
    ``centre[z]`` is the node of zone ``z`` nearest the mean position of its nodes (ties: the
    lowest node index), where vehicles sent to the zone go."""

    of_node: np.ndarray
    centre: np.ndarray

    @property
    def count(self) -> int:
        return int(self.centre.size)

    @classmethod
    def grid(cls, xy: np.ndarray, size: float) -> Zones:
        """Square cells of ``size`` metres, the first with its lower-left corner at the
        smallest node ``x`` and ``y``; only cells holding a node are zones, numbered by
        (column, row)."""
        xy = np.asarray(xy, dtype=np.float64)[:, :2]
        if xy.shape[0] == 0:
            raise ValueError("a network without nodes has no zones")
        ij = np.floor((xy - xy.min(axis=0)) / size).astype(np.int64)
        keys = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
        _, of_node = np.unique(keys, return_inverse=True)
        of_node = of_node.reshape(-1).astype(np.int64)
        z = int(of_node.max()) + 1
        counts = np.bincount(of_node, minlength=z)
        mean = np.column_stack([np.bincount(of_node, xy[:, k], minlength=z) for k in (0, 1)])
        mean /= counts[:, None]
        d2 = ((xy - mean[of_node]) ** 2).sum(axis=1)
        order = np.lexsort((np.arange(xy.shape[0]), d2, of_node))  # by zone, distance, index
        first = np.ones(order.size, dtype=bool)
        first[1:] = of_node[order][1:] != of_node[order][:-1]
        centre = order[first]
        for a in (of_node, centre):
            a.setflags(write=False)
        return cls(of_node, centre)
