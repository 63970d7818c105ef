"""Spaces: everything about "where things are".

A run happens in one space. The kernel never looks inside a location and never asks which
space it is in: it stores locations, hands them to the planner, and asks the space. A space
answers every question about location (RidePy's ``TransportSpace`` is the model):

* before it exists, of its ``[world]`` configuration (class methods): how it is loaded
  (:meth:`Space.load`), the planner a scenario gets by default, which scenario features it
  offers (:attr:`Space.features`), how a fleet start file and a trace are read in it, the
  validate-time checks and size bounds, a small instance for plugin checks;
* once built: positions in metres (for the recorded tables, the communication range and the
  plots), the driver that follows the planner's paths, where a location stands on the node
  arrays and whether a path reaches a goal, and the static tables it adds to the results.

What is built from a space is built by its own module, with one function per space kind in a
table there: the run's demand (:func:`dispatch.plan.demand.demand_for`), where the fleet starts
(:func:`dispatch.fleet.placement.place_fleet`), random views for the plugin checks
(:data:`dispatch.checks.planners.SAMPLERS`) and what they compare
(:data:`~dispatch.checks.planners.GUARDED`); the PyBullet mirror
(:func:`dispatch.space.physics.mirror_of`) and reservation-based execution
(:meth:`dispatch.plan.traffic.Traffic.in_space`) exist for voxel worlds only.

Two spaces ship with the kernel, registered in :data:`KINDS`:

* ``"voxel"``: :class:`dispatch.space.world.World`, the paper's 3D occupancy grid; a location is a
  cell ``(i, j, k)`` (:data:`dispatch.locations.Cell`);
* ``"road"``: :class:`dispatch.space.roads.RoadNetwork`, a directed graph with travel times; a
  location is a node index (``int``) or, for a vehicle, a :class:`dispatch.api.legs.RoadPoint`
  (on a node, or part-way along an edge).

A third space is one module with a :class:`Space` subclass (the abstract methods below, and
the class attributes it changes), a planner that serves its kind, an entry in :data:`KINDS`,
its entry in each builder table above (a test checks that every kind has one) and its branch
in the ``[world]`` parsing of :mod:`dispatch.scenario.sections`.

Planners declare the spaces they serve (:attr:`dispatch.api.contracts.Planner.spaces`); a planner
asked to work in another space is a scenario error found at validate time.

Where it stands: this contract is on the kernel's ground floor, under everything that holds a
location or a space (tasks, vehicles, contracts, the configuration). So it imports none of
them: the objects its hooks take and build (a ``[world]`` configuration,
:class:`dispatch.space.drivers.Driver`) are named in the docstrings. The builders stand above it and
the two spaces; the spaces' own parts (drivers) know them only through the small types below
both: :mod:`dispatch.locations`, :mod:`dispatch.api.voxels` and :mod:`dispatch.api.legs`.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import ClassVar

import numpy as np

from dispatch.locations import Location, Position

__all__ = ["KINDS", "Space", "space_class", "space_for"]

#: The spaces, by the kind a scenario's ``[world]`` table parses to
#: (:attr:`dispatch.config.world.WorldConfig.space`): ``"module:Class"`` of each, imported when
#: first asked for (a voxel run never imports the road network's libraries).
KINDS: dict[str, str] = {"voxel": "dispatch.space.world:World",
                         "road": "dispatch.space.roads:RoadNetwork"}


def space_class(kind: str) -> type[Space]:
    """The :class:`Space` subclass of a kind of :data:`KINDS` (KeyError: no such kind)."""
    module, _, name = KINDS[kind].partition(":")
    return vars(importlib.import_module(module))[name]


def space_for(cfg, seed: int, scenario_path=None) -> Space:
    """The run's space, built from its ``[world]`` configuration for ``seed`` (a voxel world's
    obstacles depend on it); loading errors are ScenarioErrors naming ``scenario_path``."""
    return space_class(cfg.space).load(cfg, seed, scenario_path)


class Space(ABC):
    """Where a run's vehicles and tasks are. Immutable once built, so planners may cache on it.

    A subclass implements the abstract methods; the class attributes and the methods with a
    default say what a space without more to offer answers."""

    #: ``"voxel"`` or ``"road"`` (its key in :data:`KINDS`): what planners match against.
    kind: ClassVar[str] = ""
    #: the planner a scenario gets without ``[dispatch] planner``
    default_planner: ClassVar[str] = ""
    #: what the space offers beyond point tasks, for the scenario checks: ``"pooling"``
    #: (shared rides, drop-off delay limits, the added_time objective), ``"reassign"``
    #: (re-assignment before pickup), ``"snap"`` (traces of coordinates snapped to it,
    #: ``max_snap``), ``"energy"`` (batteries and charging stations), ``"reposition"`` (the
    #: kernel drives idle vehicles), ``"rl"`` (:mod:`learning.rl`'s environment), ``"pricing"``
    #: (fares by the direct route's kilometres: ``[pricing]``), ``"depots"`` (shift depots
    #: named by node or snapped from ``x,y``: :mod:`dispatch.fleet.shifts`)
    features: ClassVar[frozenset[str]] = frozenset()
    #: a fleet start file may give a vehicle's node id (a ``node`` column) instead of metres
    start_nodes: ClassVar[bool] = False
    #: a fleet start file's ``z`` where it has none (nan: none)
    start_z: ClassVar[float] = float("nan")
    #: metres of a cell's side where the space is a grid of cells (the voxel world's
    #: :attr:`dispatch.api.problem.AllocationProblem.cell_size`); 1.0 in a space without cells
    cell: float = 1.0
    #: ``(x, y, z)`` of each node, in node order, as Python floats (node ``i``'s
    #: :meth:`position`), where locations may be node indices (a road network); None in a
    #: space without nodes
    node_positions: Sequence[Position] | None = None
    #: Metres per second that no drive beats in a straight line, where the space has nodes
    #: and promises it: for any nodes ``a`` and ``b``, the distance between
    #: ``node_positions[a]`` and ``node_positions[b]`` over ``top_speed`` never exceeds the
    #: seconds of the fastest drive from ``a`` to ``b`` by the space's own times (a road
    #: network: the fastest edge's straight-line speed, so by the triangle inequality of
    #: every path's). None: no such promise (the default).
    top_speed: float | None = None
    #: Further promises of that kind, each ``(speed, slack)``: the distance less ``slack``
    #: metres, over ``speed``, never exceeds the fastest drive's seconds (a slower speed that
    #: all but a few edges keep to, the metres those exceed it by in all). Empty: none.
    speed_slacks: tuple[tuple[float, float], ...] = ()

    # ------------------------------------------------------------ of its configuration
    @classmethod
    @abstractmethod
    def load(cls, cfg, seed: int, scenario_path: Path | None = None) -> Space:
        """The space of a ``[world]`` configuration and a seed (may be cached: spaces are
        immutable); what cannot be loaded is a ScenarioError naming ``scenario_path``."""

    @classmethod
    @abstractmethod
    def label(cls, cfg) -> str:
        """A few words saying which space a configuration is (``dispatch validate`` prints
        them)."""

    @classmethod
    def trace_bounds(cls, cfg) -> tuple[float, float, float] | None:
        """The extent in metres a trace's positions must lie in (None: any)."""
        return None

    @classmethod
    def check_size(cls, cfg, limits, refuse) -> None:
        """Refuse (``raise refuse(key, what)``) a space past ``limits``
        (:class:`dispatch.config.scenario.Limits`). Default: nothing to bound."""

    @classmethod
    def check_fleet(cls, sc, agents: int, key: str) -> None:
        """ScenarioError (at ``key``) unless ``agents`` vehicles can start in the space."""

    @classmethod
    def work_cells(cls, cfg) -> int | None:
        """The number of cells the voxel work bound (:mod:`dispatch.scenario.budget`) scales with;
        None: no such bound in this space."""
        return None

    @classmethod
    def check_runs(cls, sc, planners) -> None:
        """Validate-time checks that need the space or the plugins (the planner classes of
        ``planners`` are the registry's). Default: none."""

    @classmethod
    @abstractmethod
    def small(cls, seed: int = 0) -> Space:
        """A small instance for the plugin checks (:mod:`dispatch.checks.common`)."""

    # ------------------------------------------------------------ once built

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

    @abstractmethod
    def driver(self, planner, bus, cfg, clock):
        """The driver (:class:`dispatch.space.drivers.Driver`) that follows ``planner``'s paths in
        this space; its ``planner`` is the one the run uses (it may wrap ``planner``, e.g.
        for congestion, which reads the simulated time from ``clock()``)."""

    def tables(self) -> dict[str, tuple[dict[str, str], list[dict]]]:
        """Static tables the space adds to the results: name -> (the table's metadata, its
        rows). Default: none."""
        return {}

    def shared_tables(self) -> dict[str, dict[str, np.ndarray]]:
        """Tables of the space that every run on it shares, written once per results folder
        for readers that do not rebuild the space (:mod:`dispatch.output.space_files`; e.g. a road
        network's nodes and edges, which :mod:`analysis` reads): name -> {column: array}.
        Default: none."""
        return {}

    def stands(self, loc: Location) -> tuple[int, float, bool] | None:
        """Where ``loc`` stands in the space's node arrays (kept by
        :class:`dispatch.plan.vehicles.Fleet` for vectorized decisions): the node it is on or drives
        to next, the seconds left to it, and whether it is off a node; None where the space
        has no nodes (the default)."""
        return None

    @abstractmethod
    def reaches(self, path, start: Location, goal: Location) -> bool:
        """Whether a planner's non-empty ``path`` goes from ``start`` (where the vehicle is)
        to ``goal`` (what a driver and the planner checks accept)."""
