"""One run: wiring the space, the fleet, the task source, the dispatcher and the subscribers
onto one SimPy environment. Nothing here is reached back into during the run::

    TaskSource ──release──▶ TaskBook ◀──assign/pickup/close── Operator (vehicles, drivers)
        │                      ▲  │                               ▲     │
        │                      │  └─on_close─▶ RunRecording       │     │
        │         Dispatcher ──┴──────────────assign──────────────┘     │
        │             ▲   (its Pipeline builds each problem)            │
        └──call──▶ Wakeup ◀───────────────────call──────────────────────┘
                   (repositioning and charging call it too)
    every process ──emit──▶ EventBus ──▶ RunRecording (events), the space's mirror, user
                                         subscribers

Everything is built once, in :class:`Simulation`'s constructor, each object from those made
before it. The one cycle (the operator wakes the dispatcher, the dispatcher drives the
operator) is broken by the :class:`~dispatch.decide.dispatcher.Wakeup`, made first and handed to
both; the decision's pipeline (:class:`~dispatch.decide.pipeline.Pipeline`) gets the energy filter
and the comms faults when it is built.

The jobs are the owners': the space (:mod:`dispatch.api.space`) loads itself and answers
everything about location (demand, where the fleet starts, the driver, its static tables),
:mod:`dispatch.run.plugins` builds the plugins, :class:`dispatch.output.rows.RunRecording` writes
the
tables and the summary.

Randomness: every stream is a ``numpy.random.Generator`` seeded from the run's seed and a fixed
stream number (:mod:`dispatch.streams`), so the world (obstacles) depends on the seed only, and
the same seed gives the same fleet and the same tasks whichever allocator runs: instances are
paired across allocators.
"""

from __future__ import annotations

import gc
import logging
import math
from contextlib import contextmanager
from functools import partial

import simpy

from dispatch.api.space import space_for
from dispatch.decide.dispatcher import Dispatcher, Wakeup
from dispatch.decide.meeting import Walks
from dispatch.decide.pipeline import Pipeline
from dispatch.decide.riders import Riders, rider_source, riders_for
from dispatch.decide.tally import Blame, Tally
from dispatch.events import EventBus
from dispatch.fleet.battery import Energy
from dispatch.fleet.chargers import Charging, Stations
from dispatch.fleet.faults import FaultInjector, blackout_filter
from dispatch.fleet.placement import place_fleet
from dispatch.fleet.repositioning import Repositioning, summary_of
from dispatch.fleet.shifts import Shifts, fleet_summary
from dispatch.output.energy import EnergyTally, energy_columns
from dispatch.output.rows import RunRecording
from dispatch.plan.breaks import Breaks
from dispatch.plan.demand import demand_for
from dispatch.plan.operator import Hooks, Operator, Towing
from dispatch.plan.tasks import Task, TaskBook, TaskState
from dispatch.plan.timed_drives import TimedExecution
from dispatch.plan.traffic import Traffic
from dispatch.plan.vehicles import Fleet, stop_leg
from dispatch.run.plugins import (check_repositioner, check_transit, describe, make_charger,
                                  make_mode_choice, make_plugin, make_repositioner, make_sizer,
                                  offering_for)
from dispatch.space.physics import mirror_of
from dispatch.streams import (STREAM_ALLOCATOR, STREAM_CHARGING, STREAM_FAULTS, STREAM_FLEET,
                              STREAM_MODE_CHOICE, STREAM_OFFERS, STREAM_PREBOOK,
                              STREAM_REPOSITION, STREAM_SIZING, STREAM_SOURCE, STREAM_TASKS,
                              rng_for)

log = logging.getLogger(__name__)


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
    it). The CLI draws its progress bar with it; library code prints nothing.

    ``allocator``, if given, decides instead of the one ``spec`` names (a test's scripted
    answers; :mod:`learning.rl`'s, which defers each decision to the environment's step), and
    ``env`` is the SimPy environment to run in where such an allocator was made with it
    (default: a fresh one)."""

    def __init__(self, spec, recorder, progress=None, *, allocator=None,
                 env: simpy.Environment | None = None) -> None:
        sc = spec.scenario
        check_transit(sc)
        self.spec, self.recorder = spec, recorder
        self.env = env = simpy.Environment() if env is None else env
        self.space = space = space_for(sc.world, spec.seed, sc.path)
        self.world = space  # the voxel name, for callers that know they are in one
        if allocator is None:
            allocator = make_plugin("allocator", spec.allocator, sc.dispatch.allocator_params)
        self.planner = make_plugin("planner", spec.planner, sc.dispatch.planner_params, space)
        check_repositioner(sc, spec.reposition)
        self.repositioner = make_repositioner(sc, spec.reposition)
        self.allocator_info = describe(allocator)
        recorder.metadata["dispatch.allocator_info"] = self.allocator_info
        self.bus = bus = EventBus()
        self.book = book = TaskBook(env, bus)
        self.fleet = Fleet(place_fleet(space, spec, rng_for(spec.seed, STREAM_FLEET)), space)
        self.vehicles = self.fleet.vehicles
        #: the run's tables, metadata and summary statistics (dispatch.output.rows)
        self.recording = RunRecording(recorder, space, book.request_ids)
        self.stats = self.recording.stats
        demand = demand_for(space, sc.tasks, rng_for(spec.seed, STREAM_TASKS))
        driver = space.driver(self.planner, bus, sc.world, lambda: self.env.now)
        self.planner = driver.planner  # (a space's driver may wrap it: congestion)
        recorder.metadata.update(driver.metadata)
        self.physics = mirror_of(space, bus, self.vehicles) if sc.world.physics else None
        self.recording.attach(bus)
        self._record_event = self.recording.event
        self._record_task = self.recording.task
        self._record_decision = self.recording.decision
        book.on_close += [lambda t: self.planner.task_closed(t.id), *self.recording.on_close,
                          self._check_finished]
        #: reservation-based execution, with a reservation-aware planner only
        self.traffic = (Traffic.in_space(env, self.planner, space, self.vehicles, bus.emit)
                        if self.planner.reservation_aware else None)
        self.finished = env.event()
        # the dispatcher's wake-up call first: the operator, the task source, repositioning
        # and charging call it, the dispatcher (made after the operator it drives) waits on it
        d = sc.dispatch
        wakeup = Wakeup(env, book, always=d.batch_window > 0 or d.reassign)
        #: [fleet.energy]: the stations (a stranded vehicle is towed to the nearest one)
        self.stations = (Stations(env, sc.charging, space, sc.fleet.energy.max_charge_kw)
                         if sc.fleet.energy is not None else None)
        towing = None if self.stations is None else Towing(
            sc.charging.tow, self.stations.nearest_node, sc.faults.on_board == "transfer")
        self.operator = Operator(env, bus, book, self.fleet, driver, sc.tasks.service_time,
                                 hooks=Hooks(wakeup, lambda task: self.source.rearm(task)),
                                 execution=None if self.traffic is None
                                 else partial(TimedExecution, self.traffic),
                                 towing=towing)
        #: [fleet.energy]: batteries and the reserve rule (dispatch.fleet.battery.Energy), or None
        self.energy = self._energy(sc)
        #: driver shifts and fleet sizing (dispatch.fleet.shifts); None without shift columns and
        #: with ``fixed`` sizing (every vehicle on duty all run)
        self.shifts = None
        sizer = None if sc.fleet.sizing is None else make_sizer(sc)
        if sc.fleet.shifts is not None or (sizer is not None and not sizer.passive):
            self.shifts = Shifts(env, bus, self.fleet, self.operator, space, sc.fleet,
                                 notify=wakeup, sizer=sizer,
                                 rng=rng_for(spec.seed, STREAM_SIZING))
        #: [fleet.breaks]: drivers' breaks planned into plans (dispatch.plan.breaks), or None
        breaks = sc.fleet.breaks
        self.breaks = None if breaks is None else Breaks(
            env, bus, self.operator, self.fleet.vehicles, breaks.after, breaks.duration)
        #: [fleet.energy]: charges and strandings, for the summary (None without energy)
        self.energy_tally = None if self.energy is None else EnergyTally(bus)
        #: what the decisions add up to (the summary's columns); the errors' context
        self.tally = Tally()
        blame = Blame(env, spec.run_id, self.tally)
        #: meeting points (dispatch.decide.meeting.Walks): None when every rider goes door to door
        self.walks = (Walks(space, sc.tasks.meeting_points) if sc.tasks.walking else None)
        if self.walks is not None:
            book.on_close.append(lambda t: self.walks.forget((t.id,)))
        #: [transit]: riders who may take the train (dispatch.decide.riders), or None
        self.riders = None if sc.transit is None else self._riders(sc)
        if self.riders is not None:
            book.on_close.append(self.riders.closed)
        pipeline = Pipeline(book, self.fleet, self.operator, self.planner, allocator, space,
                            cfg=d, comms=sc.comms, rng=rng_for(spec.seed, STREAM_ALLOCATOR),
                            tally=self.tally, blame=blame, links=blackout_filter(sc.faults),
                            energy_filter=None if self.energy is None else self.energy.filter,
                            pooled=any(v.capacity > 1 for v in self.vehicles)
                            or sc.tasks.prebooked  # (a promise waits in a plan)
                            or self.riders is not None,  # (so does a booked last leg)
                            # (a feeder's drop-off makes its train)
                            max_delay=sc.tasks.delay_limited or self.riders is not None,
                            shifts=self.shifts if self.shifts is not None
                            and self.shifts.limited else None, walks=self.walks)
        self.dispatcher = Dispatcher(env, wakeup, pipeline, self.fleet, self.operator,
                                     allocator, tally=self.tally, blame=blame,
                                     on_decision=self._record_decision,
                                     window=d.batch_window, latency=sc.comms.latency,
                                     offering=offering_for(sc, book, self.space,
                                                           rng_for(spec.seed, STREAM_OFFERS),
                                                           blame))
        driver.run_id = spec.run_id  # named in error messages
        t = sc.tasks
        source, extra = rider_source(sc, rng_for(spec.seed, STREAM_PREBOOK), self.riders)
        self.source = source.of(env, book, demand, t,
                                spec.n_static_tasks if t.source == "static" else t.count,
                                day_rng=lambda: rng_for(spec.seed, STREAM_TASKS),
                                rng=rng_for(spec.seed, STREAM_SOURCE), notify=wakeup, **extra)
        self.source.on_done = self._check_finished
        #: the repositioning timer and drives (None: a passive repositioner, e.g. ``stay``)
        self.repositioning = None
        if not self.repositioner.passive:
            r = sc.reposition
            self.repositioning = Repositioning(env, bus, self.fleet, self.operator, self.space,
                                               self.repositioner, interval=r.interval,
                                               horizon=r.horizon,
                                               rng=rng_for(spec.seed, STREAM_REPOSITION),
                                               run_id=spec.run_id)
        self.faults = (FaultInjector(env, sc.faults, self.fleet, self.operator,
                                     rng_for(spec.seed, STREAM_FAULTS))
                       if sc.faults.vehicles else None)
        #: [fleet.energy]: stations and visits (dispatch.fleet.chargers.Charging), or None
        self.charging = None
        if self.energy is not None:
            self._electric(sc)
        self.progress = progress
        if progress is not None and math.isfinite(sc.duration) and sc.duration > 0:
            env.process(self._report(sc.duration))

    def _report(self, duration: float):
        """Process: report progress every ``duration / PROGRESS_TICKS`` simulated seconds."""
        tick = duration / PROGRESS_TICKS
        while True:
            yield self.env.timeout(tick)
            self.progress(self.env.now, duration, self.book.released, self.stats.n_tasks)

    def _riders(self, sc) -> Riders:
        """``[transit]``: the timetable on the run's network and clock, the mode choice, and
        the ``legs`` table and the summary's transit columns in the recording."""
        free = self.planner.free_flow

        def between(u: int, v: int) -> float:
            return float(free.between([u], [v], pairwise=True)[0])

        return riders_for(sc, self.space, make_mode_choice(sc),
                          rng_for(self.spec.seed, STREAM_MODE_CHOICE), between=between,
                          recording=self.recording)

    def _energy(self, sc) -> Energy | None:
        """``[fleet.energy]``: the run's batteries and the dispatcher's reserve rule (see
        :mod:`dispatch.fleet.battery`); None without it."""
        if sc.fleet.energy is None:
            return None
        net = self.space
        # the network's mean edge speed (energy is a feature of road networks only)
        ref = float(net.length.sum() / net.time.sum())
        return Energy(sc.fleet.energy, self.fleet, self.env, ref)

    def _electric(self, sc) -> None:
        """The batteries' ``soc`` samples, stations and the charging strategy (see
        :mod:`dispatch.fleet.battery`, :mod:`dispatch.fleet.chargers`)."""
        net = self.space
        self.env.process(self.energy.sampler(self.recorder.appender("soc")))
        cfg = sc.charging
        strategy = make_charger(sc, cfg.strategy) if cfg.stations else None
        self.charging = Charging(self.env, self.bus, self.fleet, self.operator, self.energy,
                                 cfg, stations=self.stations, space=net, strategy=strategy,
                                 rng=rng_for(self.spec.seed, STREAM_CHARGING),
                                 run_id=self.spec.run_id)

    @property
    def allocator(self):
        """The run's allocator (:class:`dispatch.api.contracts.Allocator`)."""
        return self.dispatcher.allocator

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
            self.book.close_all(TaskState.CUT_OFF)
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
                if v.break_since is not None:  # a break the end cut: the part taken counts
                    v.break_seconds += env.now - v.break_since
            self.operator.execution.end(env.now)
            return self._finish()
        finally:
            if self.physics is not None:
                self.physics.close()

    def _finish(self) -> dict:
        spec = self.spec
        now = float(self.env.now)
        # (waits, replans, wait seconds: reservation-based execution's, 0 without it)
        self.recording.end_tables(self.vehicles, now, self.operator.execution.counts)
        self.operator.finish()
        if self.charging is not None:
            self.recording.chargers(self.stations.rows())
        run = dict(spec.keys, n_agents=len(self.vehicles), space=self.space.kind)
        # what the allocator says at the end (a learned model's name, a batch method's counts)
        extra = {**summary_of(self.repositioning),
                 **energy_columns(self.energy_tally, self.vehicles),
                 "allocator_info": describe(self.dispatcher.allocator),
                 "objective": spec.scenario.dispatch.objective,
                 **fleet_summary(self.vehicles, now, self.stats.count[TaskState.COMPLETED]),
                 "meeting_points": 0 if self.walks is None else self.walks.points,
                 "meeting_cut": 0 if self.walks is None else self.walks.cut,
                 **({} if self.riders is None else
                    self.riders.summary(sum(v.distance for v in self.vehicles)))}
        return self.recording.summary(run, self.vehicles, self.tally, now, extra)
