"""One run: wiring the space, the fleet, the task source, the dispatcher and the subscribers
onto one SimPy environment. Nothing here is reached back into during the run:

    TaskSource ──release──▶ TaskBook ◀──assign/pickup/close── Operator (vehicles, drivers)
        │                      ▲  │                               ▲
        └──notify──▶ Dispatcher┘  └─on_close─▶ RunStats, Recorder  └── Dispatcher.assign
    every process ──emit──▶ EventBus ──▶ Recorder (events), PyBullet mirror, user subscribers

Randomness: every stream is a ``numpy.random.Generator`` seeded from the run's seed and a fixed
stream number, so the world (obstacles) depends on the seed only, and the same seed gives the
same fleet and the same tasks whichever allocator runs: instances are paired across allocators.
"""

from __future__ import annotations

import gc
import json
import logging
import math
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
import simpy

from dispatch import network_file, registry
from dispatch.contracts import Allocator, Planner
from dispatch.demand import RoadDemand, VoxelDemand
from dispatch.dispatcher import Dispatcher
from dispatch.errors import PluginError, ScenarioError
from dispatch.events import EventBus
from dispatch.faults import FaultInjector, blackout_filter
from dispatch.placement import place_fleet
from dispatch.recorder import json_meta
from dispatch.recording import DecisionWriter, TaskWriter, event_writer, write_vehicles
from dispatch.reposition import Repositioner, Repositioning, summary_of
from dispatch.reservations import Hands, TimedExecution, Traffic
from dispatch.scenario import RoadConfig, RunSpec, Scenario, WorldConfig, _short
from dispatch.space import Space
from dispatch.stats import RunStats
from dispatch.tasks import SourceConfig, Task, TaskBook, TaskSource, TaskState
from dispatch.vehicles import CellDriver, Fleet, Operator, RoadDriver, stop_leg
from dispatch.world import World, build_world

log = logging.getLogger(__name__)

(STREAM_WORLD, STREAM_FLEET, STREAM_TASKS, STREAM_ALLOCATOR, STREAM_SOURCE, STREAM_FAULTS,
 STREAM_REPOSITION, STREAM_CHARGING) = range(8)

__all__ = ["Simulation", "make_plugin", "place_fleet", "rng_for", "space_for", "world_for"]


def rng_for(seed: int, stream: int) -> np.random.Generator:
    """The generator of one named stream of a run's seed."""
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(stream,)))


@lru_cache(maxsize=8)
def world_for(cfg: WorldConfig, seed: int) -> World:
    """The voxel world of a seed. Cached: runs that share it (other allocators, other fleet
    sizes) also share everything planners cache on its immutable grid."""
    o = cfg.obstacles
    return build_world(cfg.size, cfg.cell, o.count, o.min_size, o.max_size,
                       rng_for(seed, STREAM_WORLD))


def network_for(cfg: RoadConfig, scenario_path=None):
    """The road network of a scenario (loading is cached by the loader); a file that cannot
    be loaded is a ScenarioError naming the scenario file and ``world.network``."""
    from dispatch.roads import load_network

    try:
        return load_network(cfg.network, base=cfg.base, blocks=cfg.blocks, block=cfg.block,
                            speed=cfg.speed)
    except (ValueError, OSError) as e:
        raise ScenarioError(scenario_path or cfg.base, "world.network", str(e)) from None
    except Exception as e:  # noqa: BLE001 - a malformed file raises whatever its parser raises
        raise ScenarioError(scenario_path or cfg.base, "world.network",
                            f"{cfg.network} cannot be read ({type(e).__name__}: {e})") from None


def space_for(cfg: WorldConfig, seed: int, scenario_path=None) -> Space:
    """The run's space: its voxel world (per seed) or its road network."""
    return world_for(cfg, seed) if cfg.roads is None else network_for(cfg.roads, scenario_path)


def make_plugin(kind: str, name: str, params, *args):
    """Build an allocator or planner from its scenario parameters. Whatever its constructor
    raises (TypeError, ValueError, an error of a library it calls) becomes one PluginError
    naming the plugin, its parameters and the reason."""
    return _construct(kind, name, params, args, f"dispatch.{kind}_params")


def _construct(kind: str, name: str, params, args, key: str):
    """``make_plugin`` for any kind, the parameters read from the scenario table ``key``."""
    cls = registry.load(kind, name)
    params = dict(params)
    try:
        return cls(*args, **params)
    except Exception as e:  # a plugin's constructor may raise anything
        shown = ", ".join(f"{k} = {_short(v)}" for k, v in params.items()) or "none"
        reason = " ".join(str(e).split()) or type(e).__name__
        raise PluginError(f"{kind} {name!r} rejected its parameters ({key}: {shown}): "
                          f"{type(e).__name__}: {reason}") from e


def describe(allocator) -> str:
    """What an allocator says it ran, as a JSON object of strings (``"{}"`` if it says
    nothing): the optional ``describe() -> dict[str, str]`` method of an allocator plugin
    (e.g. a learned model's name, variant and checkpoint hash). It goes into the summary's
    ``allocator_info`` column and the ``dispatch.allocator_info`` Parquet metadata."""
    fn = getattr(allocator, "describe", None)
    info = fn() if callable(fn) else {}
    return json.dumps({str(k): str(v) for k, v in dict(info).items()}, sort_keys=True)


def make_repositioner(sc: Scenario, name: str) -> Repositioner:
    """The repositioner ``name`` built from its ``[reposition.<name>]`` table."""
    return _construct("repositioner", name, sc.reposition.params_of(name), (),
                      f"reposition.{name}")


def make_charger(sc: Scenario, name: str):
    """The charging strategy ``name`` built from its ``[charging.<name>]`` table."""
    return _construct("charger", name, sc.charging.params_of(name), (), f"charging.{name}")


def check_repositioner(sc: Scenario, name: str) -> None:
    """ScenarioError unless repositioner ``name`` serves the scenario's space (the kernel moves
    vehicles on road networks only: a voxel world takes passive ones, such as ``stay``)."""
    cls = registry.load("repositioner", name)
    space = sc.world.space
    serves = tuple(getattr(cls, "spaces", ("road",)))
    if space not in serves or (space != "road" and not getattr(cls, "passive", False)):
        key = "sweep.reposition" if sc.sweep.reposition else "reposition.policy"
        raise ScenarioError(sc.path, key, f"repositioner {name!r} moves vehicles on "
                                          f"{' and '.join(serves)} spaces, not this scenario's "
                                          f"{space} world (use 'stay' there)")


def check_runs(sc: Scenario, planners, repositioners=()) -> None:
    """Validate-time checks that need plugins or the network: every planner and repositioner
    serves the scenario's space; a road network loads; a trace names only nodes it has."""
    space = sc.world.space
    for name in repositioners:
        check_repositioner(sc, name)
    for name in planners:
        serves = getattr(registry.load("planner", name), "spaces", ("voxel",))
        if space not in serves:
            raise ScenarioError(sc.path, "dispatch.planner",
                                f"planner {name!r} serves {' and '.join(serves)} spaces, not "
                                f"this scenario's {space} world; {space} planners: "
                                f"{', '.join(registry.serving(space)) or 'none installed'}")
    if sc.world.roads is not None:
        net = network_for(sc.world.roads, sc.path)
        if sc.tasks.trips is not None:
            from dispatch.demand import trace_nodes_ok

            trace_nodes_ok(net, sc.tasks.trips)
    elif sc.tasks.trips is not None and sc.tasks.trips.dest is not None \
            and any(registry.load("planner", p).reservation_aware for p in planners):
        raise ScenarioError(sc.path, "tasks.trace", "trips with drop-offs are not supported "
                                                    "with reservation-based execution yet")


def _has_max_delay(sc: Scenario) -> bool:
    """Some request of the scenario has a drop-off delay limit (the file's or its trace's)."""
    trips = sc.tasks.trips
    return sc.tasks.max_delay is not None or (
        trips is not None and trips.max_delay is not None
        and bool(np.isfinite(trips.max_delay).any()))


#: Simulated-time ticks of a run's progress reports (see :class:`Simulation`).
PROGRESS_TICKS = 500
#: Allocations between two young-generation collections of the garbage collector while a run
#: goes (Python's default is 700; see :func:`run_gc`).
RUN_GC_YOUNG = 50_000


@contextmanager
def run_gc():
    """The garbage collector's settings while a run goes, restored afterwards: the objects that
    exist when the run starts (modules, the network, the planner's caches: hundreds of
    thousands) are frozen out of the collector's scans (``gc.freeze``), and the young
    generation is collected every ``RUN_GC_YOUNG`` allocations instead of 700. A run makes
    millions of short-lived objects (events, views, rows); with the defaults, a 20,000-trip
    day spent about a sixth of its time in the collector, mostly re-scanning the frozen ones.
    Only when objects are freed changes (reference cycles a little later), never a result."""
    old = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(max(old[0], RUN_GC_YOUNG), *old[1:])
    try:
        yield
    finally:
        gc.set_threshold(*old)
        gc.unfreeze()


class Simulation:
    """Everything one run needs; :meth:`run` executes it, recording into ``recorder``, and
    returns the summary row.

    ``progress``, if given, is called as ``progress(sim_time, duration, released, closed)``
    (seconds; task counts) ``PROGRESS_TICKS`` times over the run's duration and once at the
    end, from a SimPy process that touches nothing else (the run's results do not depend on
    it). The CLI draws its progress bar with it; library code prints nothing."""

    def __init__(self, spec: RunSpec, recorder, progress=None) -> None:
        sc = spec.scenario
        self.spec, self.recorder = spec, recorder
        self.env = env = simpy.Environment()
        self.space = space_for(sc.world, spec.seed, sc.path)
        self.world = self.space  # the voxel name, for callers that know they are in one
        allocator: Allocator = make_plugin("allocator", spec.allocator,
                                           sc.dispatch.allocator_params)
        self.planner: Planner = make_plugin("planner", spec.planner, sc.dispatch.planner_params,
                                            self.space)
        check_repositioner(sc, spec.reposition)
        self.repositioner: Repositioner = make_repositioner(sc, spec.reposition)
        self.allocator_info = describe(allocator)
        recorder.metadata["dispatch.allocator_info"] = self.allocator_info
        self.bus = bus = EventBus()
        self.book = book = TaskBook(env, bus)
        self.fleet = Fleet(place_fleet(self.space, spec, rng_for(spec.seed, STREAM_FLEET)))
        self.vehicles = self.fleet.vehicles
        self.stats = RunStats()
        recorder.metadata.update(self.space.describe())
        recorder.metadata.update(network_file.store(getattr(recorder, "out", None), self.space))
        self.physics = None
        roads = sc.world.roads is not None
        if roads:
            demand = RoadDemand(self.space, rng_for(spec.seed, STREAM_TASKS))
            driver = self._road_driver(sc)
        else:
            recorder.table_metadata["obstacles"] = {
                "dispatch.world_size": json_meta(list(self.space.size)),
                "dispatch.cell": str(self.space.cell),
            }
            demand = VoxelDemand(self.space.grid, sc.tasks.ground_fraction,
                                 rng_for(spec.seed, STREAM_TASKS))
            driver = CellDriver(self.space, self.planner, bus)
            if sc.world.physics:
                self._mirror()
        self._record_event = event_writer(recorder, self.space)
        bus.subscribe(self._record_event)
        self._record_task = TaskWriter(recorder, self.space)
        self._record_decision = DecisionWriter(recorder)
        book.on_close += [lambda t: self.planner.task_closed(t.id), self.stats.closed,
                          self._record_task, self._check_finished]
        #: reservation-based execution, with a reservation-aware planner only
        self.traffic = (Traffic(env, self.planner, self.space.grid, self.vehicles, bus.emit)
                        if self.planner.reservation_aware else None)
        timed = None
        if self.traffic is not None:
            def timed(op: Operator) -> TimedExecution:
                return TimedExecution(self.traffic, Hands(
                    book, self.fleet, sc.tasks.service_time, op.notify, op.breakdown))
        self.finished = env.event()
        self.dispatcher: Dispatcher
        self.operator = Operator(env, bus, book, self.fleet, driver, sc.tasks.service_time,
                                 lambda: self.dispatcher.notify(), timed)
        self.dispatcher = Dispatcher(env, book, self.fleet, self.operator, self.planner,
                                     allocator, self.space, sc.dispatch, sc.comms,
                                     rng_for(spec.seed, STREAM_ALLOCATOR), self._record_decision,
                                     blackout_filter(sc.faults),
                                     pooled=any(v.capacity > 1 for v in self.vehicles),
                                     max_delay=_has_max_delay(sc))
        self.dispatcher.run_id = driver.run_id = spec.run_id  # named in error messages
        t = sc.tasks
        count = spec.n_static_tasks if t.source == "static" else t.count
        kind, trips = t.source, t.trips
        if kind == "empirical":  # the day is drawn now and released as a trace
            from dispatch.empirical import draw_day, load_sample

            kind = "trace"
            trips = draw_day(load_sample(), t.trips_per_day, rng_for(spec.seed, STREAM_TASKS),
                             t.weekday)
        self.source = TaskSource(env, book, demand,
                                 SourceConfig(kind, count, t.interval, t.rate, t.max_active,
                                              t.ttl, t.max_wait, t.max_delay),
                                 rng_for(spec.seed, STREAM_SOURCE), self.dispatcher.notify,
                                 trips)
        self.source.on_done = self._check_finished
        self.operator.on_reopen = self.source.rearm
        #: the repositioning timer and drives (None: a passive repositioner, e.g. ``stay``)
        self.repositioning = None
        if not self.repositioner.passive:
            r = sc.reposition
            self.repositioning = Repositioning(env, bus, self.fleet, driver, self.space,
                                               self.repositioner, r.interval, r.horizon,
                                               rng_for(spec.seed, STREAM_REPOSITION),
                                               lambda: self.dispatcher.notify())
            self.repositioning.run_id = spec.run_id
            self.operator.on_assign = self.repositioning.stop
        self.faults = (FaultInjector(env, sc.faults, self.fleet, self.operator,
                                     rng_for(spec.seed, STREAM_FAULTS))
                       if sc.faults.vehicles else None)
        #: [fleet.energy]: batteries (dispatch.energy.Energy) and stations, visits (Charging)
        self.energy = self.charging = None
        if sc.fleet.energy is not None:
            self._electric(sc, driver)
        self.progress = progress
        if progress is not None and math.isfinite(sc.duration) and sc.duration > 0:
            env.process(self._report(sc.duration))

    def _report(self, duration: float):
        """Process: report progress every ``duration / PROGRESS_TICKS`` simulated seconds."""
        tick = duration / PROGRESS_TICKS
        while True:
            yield self.env.timeout(tick)
            self.progress(self.env.now, duration, self.book.released, self.stats.n_tasks)

    def _electric(self, sc: Scenario, driver) -> None:
        """Batteries, the reserve rule, stations and the charging strategy (see
        :mod:`dispatch.energy`)."""
        from dispatch.energy import Charging, Energy

        net = self.space
        ref = float(net.length.sum() / net.time.sum()) if hasattr(net, "length") else 10.0
        self.energy = Energy(sc.fleet.energy, self.fleet, self.env, ref)
        self.dispatcher.energy_filter = self.energy.filter
        self.env.process(self.energy.sampler(self.recorder.appender("soc")))
        cfg = sc.charging
        strategy = make_charger(sc, cfg.strategy) if cfg.stations else None
        self.charging = Charging(self.env, self.bus, self.fleet, self.operator, self.energy,
                                 cfg, net, strategy, rng_for(self.spec.seed, STREAM_CHARGING),
                                 sc.faults.on_board == "transfer",
                                 lambda: self.dispatcher.notify())
        self.charging.run_id = self.spec.run_id
        self.operator.strand = self.charging.strand
        if self.repositioning is not None:
            self.charging.on_assign = self.repositioning.stop

    def _road_driver(self, sc: Scenario) -> RoadDriver:
        """The road driver; with ``[world] congestion`` the planner's costs and the legs are
        scaled by the hour's factor (:mod:`dispatch.congestion`)."""
        factors = sc.world.roads.congestion
        if not factors:
            return RoadDriver(self.space, self.planner, self.bus, sc.world.edge_events)
        from dispatch.congestion import CongestedDriver, CongestedPlanner, HourlyFactors

        hourly = HourlyFactors(factors)
        self.planner = CongestedPlanner(self.planner, hourly, lambda: self.env.now)
        self.recorder.metadata["dispatch.congestion"] = json_meta(list(factors))
        return CongestedDriver(self.space, self.planner, self.bus, sc.world.edge_events, hourly)

    @property
    def allocator(self) -> Allocator:
        return self.dispatcher.allocator

    @allocator.setter
    def allocator(self, value: Allocator) -> None:
        """Swap the allocator before the run (tests script decisions this way)."""
        self.dispatcher.allocator = value

    def _mirror(self) -> None:
        """The PyBullet mirror (voxel worlds, ``[world] physics``): a subscriber."""
        from dispatch.physics import Physics, mirror

        self.physics = Physics(self.space)
        mirror(self.physics, self.bus, self.space, self.vehicles)

    def _check_finished(self, _task: Task | None = None) -> None:
        if self.source.finished and not self.finished.triggered and self.book.live == 0:
            self.finished.succeed()

    # --------------------------------------------------------------- running
    def run(self) -> dict:
        """Run until every task is terminal and the source is done, or the horizon; record
        the end-of-run tables and return the summary row."""
        env = self.env
        try:
            horizon = env.timeout(self.spec.scenario.duration)
            with run_gc():
                env.run(until=env.any_of([self.finished, horizon]))
            for v in self.vehicles:  # the part of a leg driven before the horizon counts
                if v.leg is not None:
                    stop_leg(v, env.now)
            self.book.close_all(TaskState.CANCELLED)
            if self.energy is not None:
                if self.charging is not None:
                    self.charging.finish()  # the charges cut by the end count
                self.energy.settle_all()
            if self.progress is not None:
                self.progress(env.now, self.spec.scenario.duration, self.book.released,
                              self.stats.n_tasks)
            for v in self.vehicles:
                if v.busy:
                    v.busy_seconds += env.now - v.busy_since
            if self.operator.timed is not None:
                self.operator.timed.end(env.now)
            return self._finish()
        finally:
            if self.physics is not None:
                self.physics.close()

    def _finish(self) -> dict:
        rec, spec = self.recorder, self.spec
        timed = self.operator.timed

        def counts(v) -> dict:  # reservation-based execution's, 0 without it
            return timed.counts(v) if timed is not None else {"waits": 0, "replans": 0,
                                                              "wait_seconds": 0.0}

        write_vehicles(rec, self.space, self.vehicles, float(self.env.now), counts)
        for b in getattr(self.space, "boxes", ()):
            rec.add("obstacles", x0=b.x0, y0=b.y0, z0=b.z0, x1=b.x1, y1=b.y1, z1=b.z1)
        if self.repositioning is not None:
            self.repositioning.finish()
        if self.charging is not None:
            for row in self.charging.rows():
                x, y, _ = self.space.position(row["node"])
                rec.add("chargers", x=x, y=y, **row)
        run = dict(scenario=spec.scenario.name, allocator=spec.allocator, planner=spec.planner,
                   reposition=spec.reposition, n_agents=len(self.vehicles), seed=spec.seed,
                   space=self.space.kind)
        summary = self.stats.summary(run=run, vehicles=self.vehicles,
                                     dispatcher=self.dispatcher, sim_time=float(self.env.now))
        summary.update(summary_of(self.repositioning))
        # what the allocator says at the end (a learned model's name, a batch method's counts)
        summary["allocator_info"] = describe(self.dispatcher.allocator)
        summary["objective"] = spec.scenario.dispatch.objective
        rec.add("summary", **summary)
        return summary
