"""The small types every part of the kernel says "where" with.

They stand on the ground floor so that tasks, events, vehicles, contracts and the spaces'
parts can all name a location without importing a space (:mod:`dispatch.api.space`).
"""

from __future__ import annotations

from typing import Any

#: A location in some space: opaque to the kernel (a voxel cell, a road node, a road point).
Location = Any
#: A position in metres, ``(x, y, z)``.
Position = tuple[float, float, float]
#: A voxel cell ``(i, j, k)`` along x, y, z (see :mod:`dispatch.api.voxels`).
Cell = tuple[int, int, int]
