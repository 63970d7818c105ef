"""A scenario's typed configuration: the frozen dataclasses a scenario file is parsed into
(:func:`dispatch.scenario.load.load_scenario` is the parser), the resource bounds, and the runs a
scenario expands to (:class:`RunSpec`).

Nothing here reads a file: every value is already checked when one of these is built by the
parser (or by a test or a benchmark by hand).
"""

from __future__ import annotations

import itertools
import logging
import re
import reprlib
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from dispatch.api.space import space_class
from dispatch.config import runkeys
from dispatch.config.faults import FaultConfig
from dispatch.config.offers import AcceptorConfig
from dispatch.config.runkeys import RUN_KEYS
from dispatch.errors import ScenarioError
from dispatch.files.traces import Trips

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
SOURCES = ("static", "periodic", "poisson", "trace", "empirical")
VOXEL_KEYS = ("size", "cell", "obstacles")
ROAD_KEYS = ("network", "blocks", "block", "speed")

#: Resource bounds. Past a ``Limits`` value a scenario is refused with a clear error that
#: names the override (``--force``); past a hard bound it is refused whatever.
MAX_SEED = 2**63 - 1  # seeds are stored as int64 (Parquet); hard
MAX_AXIS_CELLS = 1_000_000  # cells along one axis of a voxel world; hard


@dataclass(frozen=True)
class Limits:
    """Soft resource bounds, checked by :func:`check_limits` (``--force`` skips them)."""

    file_bytes: int = 8 * 2**20  # a scenario file
    input_bytes: int = 512 * 2**20  # a trace or fleet start file
    cells: int = 50_000_000  # voxel grid cells
    releases: int = 2_000_000  # expected releases (or release ticks) of a generated source
    static_tasks: int = 100_000  # tasks released at once by a static source
    agents: int = 100_000  # vehicles of a run
    runs: int = 10_000  # runs of a sweep
    road_nodes: int = 1_000_000  # intersections of a generated manhattan grid


LIMITS = Limits()


def safe_name(name: str, fallback: str = "scenario") -> str:
    """``name`` made safe as one folder name: letters, digits, ``-``, ``_`` and ``.`` kept,
    every other run of characters one ``_``, no leading dot, no ``..``, at most 100 chars."""
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", name)
    s = re.sub(r"\.{2,}", ".", s).lstrip("._-")[:100]
    return s if s.strip("_.-") else fallback


@dataclass(frozen=True)
class ObstacleConfig:
    count: int = 10
    min_size: Vec3 = (3.0, 3.0, 5.0)  # metres (x, y, height)
    max_size: Vec3 = (10.0, 10.0, 30.0)


@dataclass(frozen=True)
class RoadConfig:
    """A road network: ``network`` is ``"manhattan"`` (generated from ``blocks``, ``block``,
    ``speed``), ``"chicago"`` (the Chicago Regional network shipped with the package) or a
    GraphML / TNTP file, relative to ``base`` (the scenario's folder)."""

    network: str
    base: Path
    blocks: tuple[int, int] = (20, 20)  # intersections along x (columns) and y (rows)
    block: float = 200.0  # metres between neighbouring intersections
    speed: float = 10.0  # m/s on every street of the generated grid
    #: hourly congestion factors (24; see dispatch.space.congestion); empty: free-flow times
    congestion: tuple[float, ...] = ()


@dataclass(frozen=True)
class WorldConfig:
    size: Vec3 = (50.0, 50.0, 30.0)  # metres
    cell: float = 1.0  # metres
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


@dataclass(frozen=True)
class FleetConfig:
    agents: int = 8
    uav_fraction: float = 0.5  # share of the fleet that flies (rounded to whole vehicles)
    uav_speed: float = 5.0  # m/s
    ugv_speed: float = 3.0  # m/s
    uav_max_start_altitude: float = 10.0  # metres: UAVs start in a free cell at or below this
    #: where the fleet starts (``[fleet] start``): ``(vehicle_id, a, b, c)`` rows from a CSV file;
    #: ``a`` a road node id (b, c nan) or ``(a, b[, c])`` a position in metres; empty: random
    start: tuple[tuple, ...] = ()
    start_file: Path | None = None
    #: roads, without a start file: "uniform" nodes, or "demand" (the empirical sample's
    #: pickup nodes, weighted by their trips)
    placement: str = "uniform"
    #: seats per vehicle (``[fleet] capacity``); a start file's ``capacity`` column per vehicle
    #: (row order; 0: the fleet's)
    capacity: int = 1
    capacities: tuple[int, ...] = ()
    #: ``[fleet.energy]`` (:class:`dispatch.config.energy.EnergyConfig`); None: no batteries
    energy: Any = None
    #: the start file's shift columns (:class:`dispatch.fleet.shifts.ShiftTable`); None: none
    shifts: Any = None
    #: seconds after its shift's end a vehicle may still complete its plan's last stop
    shift_grace: float = 0.0
    #: ``[fleet] sizing``: the fleet-sizing strategy (``dispatch.sizers``; None: not given,
    #: as ``fixed``: every vehicle on duty over its shift) and its ``[fleet.sizing_params]``
    sizing: str | None = None
    sizing_params: tuple[tuple[str, Any], ...] = ()

    @property
    def pooled(self) -> bool:
        """Some vehicle has more than one seat: busy vehicles take part in decisions."""
        return self.capacity > 1 or any(c > 1 for c in self.capacities)

    @property
    def n_uav(self) -> int:
        return int(round(self.agents * self.uav_fraction))


@dataclass(frozen=True)
class TaskConfig:
    source: str = "static"
    count: int | None = None  # static: number of tasks (None: as many as agents); others: cap
    interval: float | None = None  # periodic: seconds between releases
    rate: float | None = None  # poisson: releases per second
    max_active: int | None = None  # periodic/poisson: a release is skipped while this many are open
    ground_fraction: float = 0.5  # probability that a generated task is on the ground layer
    service_time: float = 0.0  # seconds a vehicle spends at the task after arriving
    ttl: float | None = None  # seconds an unassigned task waits before it expires
    max_wait: float | None = None  # seconds a request accepts to wait for its pickup
    #: seconds of delay a request accepts at its drop-off, over release + direct drive time
    max_delay: float | None = None
    trace: Path | None = None  # trace: CSV or Parquet file of trips (see dispatch.files.traces)
    trips: Trips | None = None
    trips_per_day: float | None = None  # empirical: expected trips over the 24 h day
    weekday: str = "all"  # empirical: the sample's trips of this weekday ("all": every day)
    #: trace: the date-time of second 0 (a trace's departure_time is read from it)
    start: datetime | None = None
    #: trace on roads: metres a pickup / drop-off may lie from the nearest node (farther:
    #: the trip is left out before the run, counted in trips.dropped); None: no bound
    max_snap: float | None = None
    #: share of the requests booked ahead (each drawn from the run's prebooking stream; a
    #: trace's booked_at column instead: see dispatch.decide.prebook)
    prebook_share: float = 0.0
    #: seconds before its departure a request of prebook_share is booked (0: at its
    #: departure, an immediate request dispatched as a booked one)
    prebook_lead: float = 3600.0

    @property
    def prebooked(self) -> bool:
        """Some request is booked ahead (``prebook_share``, or its trace's ``booked_at``)."""
        return self.prebook_share > 0 or (self.trips is not None and self.trips.prebooked)
    #: metres a rider may walk to a boarding point and from an alighting point (meeting
    #: points, dispatch.decide.meeting; 0: door to door; a trace's ``max_walk`` column per row)
    max_walk: float = 0.0
    #: m/s riders walk at (a trace's ``walk_speed`` column per row)
    walk_speed: float = 1.4
    #: boarding points (and as many alighting points) per request at most, the nearest
    #: within ``max_walk``
    meeting_points: int = 8

    @property
    def walking(self) -> bool:
        """Some rider may walk to a meeting point (``max_walk`` > 0, or its trace's column)."""
        trips = self.trips
        return self.max_walk > 0 or (
            trips is not None and trips.max_walk is not None
            and bool((np.nan_to_num(trips.max_walk) > 0).any()))

    @property
    def delay_limited(self) -> bool:
        """Some request has a drop-off delay limit (``max_delay``, or its trace's column)."""
        trips = self.trips
        return self.max_delay is not None or (
            trips is not None and trips.max_delay is not None
            and bool(np.isfinite(trips.max_delay).any()))


@dataclass(frozen=True)
class DispatchConfig:
    allocator: str = "hungarian"
    planner: str = "astar"
    batch_window: float = 0.0  # seconds the dispatcher waits after a wake-up to batch events
    max_rounds: int = 1000  # decision-round limit for decentralized allocators
    #: decisions also consider vehicles still driving to a pickup (roads; see
    #: dispatch.decide.dispatcher)
    reassign: bool = False
    #: decide on the planner's lower bounds and compute exact costs only for the pairs an
    #: optimal answer needs (see dispatch.decide.lazy); used when the planner and allocator support
    #: it
    lazy_costs: bool = False
    #: what a pair's cost is: "pickup_time" (seconds until the pickup) or "added_time" (how
    #: much longer the vehicle's whole plan gets; see dispatch.plan.stops)
    objective: str = "pickup_time"
    allocator_params: tuple[tuple[str, Any], ...] = ()
    planner_params: tuple[tuple[str, Any], ...] = ()
    #: ``[dispatch.allocator_params.<name>]`` tables: parameters of one allocator (``magnnet``)
    #: or of a named variant (``"magnnet:paper"``), over the flat ones (see :meth:`params_for`)
    allocator_tables: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    #: when a booked request enters dispatch: "at_booking" (when it is booked) or "lead"
    #: (prebook_lead seconds before its departure, not before its booking); dispatch.decide.prebook
    prebook: str = "at_booking"
    #: seconds before its departure a booked request enters dispatch with prebook = "lead"
    #: (unset: the [tasks] prebook_lead)
    prebook_lead: float | None = None

    def params_for(self, allocator: str) -> tuple[tuple[str, Any], ...]:
        """The constructor arguments of ``allocator`` (a name, or ``name:variant``): the flat
        ``[dispatch.allocator_params]`` keys, then its own table's, then its variant's."""
        tables = dict(self.allocator_tables)
        base = allocator.partition(":")[0]
        merged = dict(self.allocator_params)
        merged.update(tables.get(base, ()))
        if base != allocator:
            merged.update(tables.get(allocator, ()))
        return tuple(sorted(merged.items()))


@dataclass(frozen=True)
class CommsConfig:
    """Who can talk at a decision, and what a message costs (see :mod:`dispatch.api.comms`)."""

    range: float | None = None  # metres; None: unlimited
    latency: float = 0.0  # simulated seconds per message hop
    loss: float = 0.0  # probability that one reception of a message is lost, in [0, 1)

    @property
    def unlimited(self) -> bool:
        return self.range is None


@dataclass(frozen=True)
class RepositionConfig:
    """``[reposition]``: what idle vehicles do (see :mod:`dispatch.api.repositioner`).

    ``policy`` names an installed repositioner (``stay``: they wait where they are); a
    non-passive one is called every ``interval`` seconds and sees the requests released in the
    last ``horizon`` seconds. ``params`` holds each policy's ``[reposition.<name>]`` table
    (its constructor's keyword arguments). ``declared``: the file has a ``[reposition]`` table
    or a ``reposition`` sweep, so run ids and partitions name the repositioner (older layouts,
    and scenarios without it, keep theirs)."""

    policy: str = "stay"
    interval: float = 300.0  # seconds between two calls of the repositioner
    horizon: float = 1800.0  # seconds of released requests it sees
    params: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    declared: bool = False

    def params_of(self, name: str) -> tuple[tuple[str, Any], ...]:
        """The constructor arguments of repositioner ``name``."""
        return dict(self.params).get(name, ())


@dataclass(frozen=True)
class SweepConfig:
    allocator: tuple[str, ...] = ()
    planner: tuple[str, ...] = ()
    agents: tuple[int, ...] = ()
    seed: tuple[int, ...] = ()
    #: dispatch.batch_window values: a run key (a partition and a part of the run id)
    batch_window: tuple[float, ...] = ()
    reposition: tuple[str, ...] = ()

    @property
    def declared(self) -> bool:
        return any(getattr(self, k.sweep) for k in RUN_KEYS if k.sweep)


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario file. ``text`` is the file's exact content (stored with results)."""

    name: str
    path: Path
    text: str
    description: str = ""
    seed: int = 0
    duration: float = 3600.0  # simulated seconds before the run stops
    world: WorldConfig = field(default_factory=WorldConfig)
    fleet: FleetConfig = field(default_factory=FleetConfig)
    tasks: TaskConfig = field(default_factory=TaskConfig)
    dispatch: DispatchConfig = field(default_factory=DispatchConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    comms: CommsConfig = field(default_factory=CommsConfig)
    faults: FaultConfig = field(default_factory=FaultConfig)
    reposition: RepositionConfig = field(default_factory=RepositionConfig)
    #: ``[chargers]`` / ``[charging]`` (:class:`dispatch.config.energy.ChargingConfig`); None: none
    charging: Any = None
    #: ``[acceptor]`` (:class:`dispatch.config.offers.AcceptorConfig`): offers riders may decline
    acceptor: AcceptorConfig = field(default_factory=AcceptorConfig)
    #: ``[pricing]`` (:class:`dispatch.api.acceptor.Pricing`); None: no fares
    pricing: Any = None

    def runs(
        self,
        allocator: str | None = None,
        planner: str | None = None,
        agents: int | None = None,
        seed: int | None = None,
        batch_window: float | None = None,
    ) -> list[RunSpec]:
        """Expand the sweep into runs (every combination of the run keys' values, in
        :data:`~dispatch.config.runkeys.RUN_KEYS` order); a given argument replaces that sweep
        dimension. A run's scenario carries its batch window (``dispatch.batch_window``)."""
        if seed is not None and not 0 <= seed <= MAX_SEED:
            raise ScenarioError(self.path, "--seed", f"must be in [0, 2^63), got {seed}")
        if agents is not None and agents < 1:
            raise ScenarioError(self.path, "--agents", f"must be >= 1, got {agents}")
        if agents is not None:
            _check_fits(self, agents, "--agents")
        given = {"allocator": allocator, "planner": planner, "n_agents": agents, "seed": seed,
                 "batch_window": batch_window}
        dims = [(k.name, (given[k.name],) if given.get(k.name) is not None
                 else getattr(self.sweep, k.sweep) or (self.setting(k.setting),))
                for k in RUN_KEYS if k.sweep]
        specs = []
        for values in itertools.product(*(v for _, v in dims)):
            point = dict(zip((n for n, _ in dims), values))
            sc = self
            if point["batch_window"] != self.dispatch.batch_window:
                sc = replace(sc, dispatch=replace(sc.dispatch,
                                                  batch_window=float(point["batch_window"])))
            specs.append(RunSpec(sc.for_allocator(point["allocator"]), point["allocator"],
                                 point["planner"], point["n_agents"], point["seed"],
                                 point["reposition"]))
        return specs

    def setting(self, where: tuple[str, str]) -> Any:
        """The value of the setting ``(table, key)`` (``""``: top level) of a run key, as
        parsed (``("fleet", "agents")``: ``self.fleet.agents``)."""
        table, key = where
        return getattr(self if not table else getattr(self, table), key)

    def for_allocator(self, allocator: str) -> Scenario:
        """The scenario as a run of ``allocator`` sees it: ``dispatch.allocator_params`` holds
        that allocator's parameters (:meth:`DispatchConfig.params_for`); itself without
        per-allocator tables."""
        if not self.dispatch.allocator_tables:
            return self
        return replace(self, dispatch=replace(self.dispatch,
                                              allocator_params=self.dispatch.params_for(allocator)))


@dataclass(frozen=True)
class RunSpec:
    """One run of a scenario: the scenario with allocator, planner, fleet size, seed and
    repositioner fixed."""

    scenario: Scenario
    allocator: str
    planner: str
    agents: int
    seed: int
    reposition: str = "stay"

    @property
    def names_reposition(self) -> bool:
        """Whether the run id and the partition name the repositioner: when the scenario
        declares repositioning (or the run is not ``stay``), so that files of scenarios
        without it keep the layout they always had."""
        return self.scenario.reposition.declared or self.reposition != "stay"

    @property
    def names_batch_window(self) -> bool:
        """Whether the run id and the partition name the batch window: when the scenario
        sweeps it (``[sweep] batch_window``); other scenarios keep the layout they always
        had."""
        return bool(self.scenario.sweep.batch_window)

    @property
    def batch_window(self) -> float:
        """Seconds the dispatcher waits after a wake-up to batch events (this run's)."""
        return float(self.scenario.dispatch.batch_window)

    @property
    def keys(self) -> dict[str, Any]:
        """Every run key's value (:data:`~dispatch.config.runkeys.RUN_KEYS` order)."""
        values = {"scenario": self.scenario.name, "allocator": self.allocator,
                  "planner": self.planner, "reposition": self.reposition,
                  "batch_window": self.batch_window, "n_agents": self.agents,
                  "seed": self.seed}
        return {k.name: values[k.name] for k in RUN_KEYS}

    @property
    def run_id(self) -> str:
        return runkeys.run_id(self.partition)

    @property
    def fleet(self) -> FleetConfig:
        return replace(self.scenario.fleet, agents=self.agents)

    @property
    def n_static_tasks(self) -> int:
        """Tasks a static source releases (M = N unless ``tasks.count`` says otherwise)."""
        return self.scenario.tasks.count if self.scenario.tasks.count is not None else self.agents

    @property
    def partition(self) -> dict[str, Any]:
        """Hive partition keys of this run inside a sweep's output folder: the run keys, the
        optional ones (``reposition``, ``batch_window``) only where :attr:`names_reposition` /
        :attr:`names_batch_window`."""
        named = {"reposition": self.names_reposition, "batch_window": self.names_batch_window}
        keys = self.keys
        return {k.name: keys[k.name] for k in RUN_KEYS if not k.optional or named[k.name]}


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxdict, _REPR.maxstring, _REPR.maxother = 3, 8, 6, 80, 80
_REPR.maxlong = 40


def _short(v: Any, n: int = 160) -> str:
    """A bounded ``repr(v)`` (an error line stays one readable line whatever the value)."""
    r = _REPR.repr(v)
    return r if len(r) <= n else r[: n - 3] + "..."


def _check_fits(sc: Scenario, agents: int, key: str) -> None:
    """Vehicles start in distinct free cells: the fleet must fit beside the largest obstacles
    (on roads several vehicles may share a node); a start file must place every vehicle."""
    if sc.fleet.start and agents > len(sc.fleet.start):
        raise ScenarioError(sc.path, key, f"{agents} vehicles but the start file "
                                          f"{sc.fleet.start_file} places {len(sc.fleet.start)}")
    space_class(sc.world.space).check_fleet(sc, agents, key)
