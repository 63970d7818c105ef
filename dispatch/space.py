"""Spaces: the small contract for "where things are".

A run happens in one space. The kernel never looks inside a location: it stores it, hands it to
the planner, and asks the space for its position in metres (for the recorded tables, the
communication range and the plots). Two spaces ship with the kernel:

* ``"voxel"``: :class:`dispatch.world.World`, the paper's 3D occupancy grid; a location is a
  cell ``(i, j, k)``;
* ``"road"``: :class:`dispatch.roads.RoadNetwork`, a directed graph with travel times; a
  location is a node index (``int``) or, for a vehicle, a :class:`dispatch.roads.RoadPoint`
  (on a node, or part-way along an edge).

Planners declare the spaces they serve (:attr:`dispatch.contracts.Planner.spaces`); a planner
asked to work in another space is a scenario error found at validate time.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

#: A location in some space: opaque to the kernel (a voxel cell, a road node, a road point).
Location = Any
Position = tuple[float, float, float]


class Space(ABC):
    """Where a run's vehicles and tasks are. Immutable once built, so planners may cache on it."""

    #: ``"voxel"`` or ``"road"``: what planners match against.
    kind: ClassVar[str] = ""

    @abstractmethod
    def position(self, loc: Location) -> Position:
        """``(x, y, z)`` in metres of a location (a road point part-way along an edge is
        interpolated along the edge's straight segment)."""

    def positions(self, locs: Sequence[Location]) -> np.ndarray:
        """``(len(locs), 3)`` float array of :meth:`position` (subclasses may vectorize)."""
        out = np.empty((len(locs), 3))
        for i, loc in enumerate(locs):
            out[i] = self.position(loc)
        return out

    @abstractmethod
    def describe(self) -> dict[str, str]:
        """A few ``dispatch.*`` metadata entries describing the space (stored with results)."""
