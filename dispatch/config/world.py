"""``[world]``: the space a run is in, a voxel world (its size, cells and obstacles) or a road
network, as data."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

Vec3 = tuple[float, float, float]
VOXEL_KEYS = ("size", "cell", "obstacles")
ROAD_KEYS = ("network", "blocks", "block", "speed")
MAX_AXIS_CELLS = 1_000_000  # cells along one axis of a voxel world; a hard resource bound


@dataclass(frozen=True)
class ObstacleConfig:
    count: int = 10
    min_size: Vec3 = (3.0, 3.0, 5.0)  # metres (x, y, height): the smallest box
    max_size: Vec3 = (10.0, 10.0, 30.0)  # metres (x, y, height): the largest box


@dataclass(frozen=True)
class RoadConfig:
    """A road network: ``network`` is ``"manhattan"`` (generated from ``blocks``, ``block``,
    ``speed``), a network shipped with the package (``"chicago"``: Chicago Regional;
    ``"manhattan_osm"``: Manhattan's OSMnx street network) or a GraphML / node-link JSON / TNTP
    file, relative to ``base`` (the scenario's folder)."""

    #: the road network the run drives on: a generated grid, a network shipped with the
    #: package, or a file of your own (relative to the scenario file); without it the run is
    #: in the voxel world
    network: str = field(metadata={"default": "(none: the voxel world)"})
    base: Path
    blocks: tuple[int, int] = (20, 20)  # intersections along x (columns) and y (rows)
    block: float = 200.0  # metres between neighbouring intersections
    speed: float = 10.0  # m/s on every street of the generated grid
    #: hourly congestion factors (24; see dispatch.space.congestion); empty: free-flow times
    congestion: tuple[float, ...] = ()


@dataclass(frozen=True)
class WorldConfig:
    #: metres: the voxel world's extent along x, y and z (each a whole number of cells)
    size: Vec3 = (50.0, 50.0, 30.0)
    cell: float = 1.0  # metres: the edge of one voxel cell (the planners' resolution)
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)
    roads: RoadConfig | None = None  # a road network instead of the voxel world
    physics: bool = True  # mirror the run in PyBullet (default: on in voxel worlds, off on roads)
    edge_events: bool = False  # roads: a `move` event per node passed (for animation)

    @property
    def space(self) -> str:
        return "voxel" if self.roads is None else "road"

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(round(s / self.cell)) for s in self.size)  # type: ignore[return-value]
