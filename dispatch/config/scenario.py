"""A scenario's typed configuration as a whole: :class:`Scenario`, which holds one frozen
dataclass per section of the file (each in its module of :mod:`dispatch.config`, each default
written there once; :func:`dispatch.scenario.load.load_scenario` is the parser), the resource
bounds, and the runs a scenario expands to (:class:`RunSpec`).

Nothing here reads a file: every value is already checked when one of these is built by the
parser (or by a test or a benchmark by hand).
"""

from __future__ import annotations

import itertools
import re
import reprlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from dispatch.api.acceptor import Pricing
from dispatch.api.space import space_class
from dispatch.config import runkeys
from dispatch.config.comms import CommsConfig
from dispatch.config.dispatching import DispatchConfig
from dispatch.config.energy import ChargingConfig
from dispatch.config.faults import FaultConfig
from dispatch.config.fleet import FleetConfig
from dispatch.config.offers import AcceptorConfig
from dispatch.config.reposition import RepositionConfig
from dispatch.config.runkeys import RUN_KEYS
from dispatch.config.sweep import SweepConfig
from dispatch.config.tasks import TaskConfig
from dispatch.config.transit import TransitConfig
from dispatch.config.world import WorldConfig
from dispatch.errors import ScenarioError

#: Resource bounds. Past a ``Limits`` value a scenario is refused with a clear error that
#: names the override (``--ignore-limits``); past a hard bound it is refused whatever.
MAX_SEED = 2**63 - 1  # seeds are stored as int64 (Parquet); hard


@dataclass(frozen=True)
class Limits:
    """Soft resource bounds, checked by :func:`check_limits` (``--ignore-limits`` skips them)."""

    file_bytes: int = 8 * 2**20  # a scenario file
    input_bytes: int = 512 * 2**20  # a trace or fleet start file
    cells: int = 50_000_000  # voxel grid cells
    releases: int = 2_000_000  # expected releases (or release ticks) of a generated source
    static_tasks: int = 100_000  # tasks released at once by a static source
    agents: int = 100_000  # vehicles of a run
    runs: int = 10_000  # runs of a sweep
    road_nodes: int = 1_000_000  # intersections of a generated manhattan grid
    #: calls of one periodic process (repositioner, charging strategy, sizer, state-of-charge
    #: samples) over a run: a shorter period would loop in (almost) no simulated time
    periodic_calls: int = 2_000_000


LIMITS = Limits()


def safe_name(name: str, fallback: str = "scenario") -> str:
    """``name`` made safe as one folder name: letters, digits, ``-``, ``_`` and ``.`` kept,
    every other run of characters one ``_``, no leading dot, no ``..``, at most 100 chars."""
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", name)
    s = re.sub(r"\.{2,}", ".", s).lstrip("._-")[:100]
    return s if s.strip("_.-") else fallback


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario file. ``text`` is the file's exact content (stored with results)."""

    #: names the run ids, the ``scenario=`` partition and the default output folder
    name: str = field(metadata={"default": "(the file's stem)"})
    path: Path
    text: str
    #: free text saying what the scenario is for; kept with the file's text in the results,
    #: never read by a run
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
    #: ``[chargers]`` / ``[charging]``; None: no charging (a fleet without ``[fleet.energy]``)
    charging: ChargingConfig | None = None
    #: ``[acceptor]``: offers riders may decline
    acceptor: AcceptorConfig = field(default_factory=AcceptorConfig)
    #: ``[pricing]`` (the fare of a ride, read by acceptors); None: no fares
    pricing: Pricing | None = None
    #: ``[transit]``: public transport riders may combine with the fleet; None: none
    transit: TransitConfig | None = None

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
