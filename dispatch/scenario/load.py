"""Scenario files: TOML parsed once into the frozen, typed configuration of
:mod:`dispatch.config` (one dataclass per section; a key left out takes its field's default,
written there once); the tables that depend on one another (fleet, tasks, dispatch, comms,
sweep) here, the self-contained ones in :mod:`dispatch.scenario.sections`; and the limits a
scenario's runs must keep (:func:`check_limits`).

Every mistake (an unknown key, a wrong type, an impossible value) raises one
:class:`~dispatch.errors.ScenarioError` that names the file, the dotted key and the reason.
See ``scenarios/README.md`` for every key with its default; the configuration classes are
:mod:`dispatch.config`'s.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import math
import re
import tomllib
from dataclasses import replace
from datetime import datetime
from pathlib import Path

from dispatch.api import registry
from dispatch.api.acceptor import Pricing
from dispatch.api.space import space_class
from dispatch.config.comms import CommsConfig
from dispatch.config.dispatching import OUT_OF_REACH, DispatchConfig
from dispatch.config.breaks import BreaksConfig
from dispatch.config.energy import EnergyConfig
from dispatch.config.faults import FaultConfig
from dispatch.config.fleet import FleetConfig
from dispatch.config.offers import AcceptorConfig
from dispatch.config.reposition import RepositionConfig
from dispatch.config.scenario import (LIMITS, MAX_SEED, Limits, RunSpec, Scenario, _check_fits,
                                      _short, safe_name)
from dispatch.config.sweep import SweepConfig
from dispatch.config.tasks import EMPIRICAL_MAX_WAIT, SOURCES, TaskConfig
from dispatch.config.transit import TransitConfig
from dispatch.config.world import RoadConfig, WorldConfig
from dispatch.decide.prebook import MODES as PREBOOK_MODES
from dispatch.errors import LIMITS_HINT, ScenarioError
from dispatch.files.empirical import WEEKDAYS
from dispatch.files.tables import check_file, decode_text, read_bytes
from dispatch.files.traces import (IdColumnMissing, Trips, parse_datetime, read_fleet_capacities,
                                   read_fleet_start, read_trace, shipped_trace, within_snap)
from dispatch.fleet.shifts import read_shifts
from dispatch.scenario.notes import say_dropped
from dispatch.scenario.sections import (files_near, parse_acceptor, parse_allocators,
                                        parse_breaks, parse_charging, parse_energy, parse_faults,
                                        parse_pricing, parse_reposition, parse_world)
from dispatch.scenario.keys import KEYS, check_keys
from dispatch.scenario.transit import parse_transit
from dispatch.scenario.toml_table import Table, did_you_mean

log = logging.getLogger(__name__)


def load_scenario(path: str | Path, *, ignore_limits: bool = False,
                  overrides: list[tuple[str, str, str]] = ()) -> Scenario:
    """Read and validate a scenario file; raise ScenarioError naming file, key and reason.
    ``overrides`` (``(dotted key, TOML value, option)``, see :mod:`dispatch.scenario.overrides`) are
    written into its text before it is parsed, once.

    The file must be a regular file of at most ``Limits.file_bytes`` (``ignore_limits``: any
    size) in UTF-8; the traces and start files it names are size-checked before they are read
    too."""
    path = Path(path)
    limits = None if ignore_limits else LIMITS
    data = read_bytes(path, None if limits is None else limits.file_bytes, "scenario file")
    text = decode_text(path, data)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _syntax_error(path, e) from None
    except RecursionError:
        raise ScenarioError(path, "<syntax>", "invalid TOML: arrays or tables nested too "
                                              "deeply") from None
    except (ValueError, MemoryError) as e:  # e.g. an integer of more than 4300 digits
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ScenarioError(path, "<syntax>", f"invalid TOML: {reason}") from None
    if overrides:
        from dispatch.scenario.overrides import apply_overrides

        text, doc = apply_overrides(text, doc, list(overrides), path)
    return parse_scenario(doc, path, text, limits=limits)


def _syntax_error(path: Path, e: tomllib.TOMLDecodeError) -> ScenarioError:
    """``file: line L, column C: TOML syntax: what`` for tomllib's ``what (at line L, column
    C)``."""
    what = str(e)
    at = re.search(r"\s*\(at line (\d+), column (\d+)\)$", what)
    if at is None:
        return ScenarioError(path, "<syntax>", f"TOML syntax: {what}")
    return ScenarioError(path, f"line {at[1]}, column {at[2]}",
                         f"TOML syntax: {what[:at.start()]}")


def parse_scenario(data: dict, path: Path, text: str = "", *,
                   limits: Limits | None = LIMITS) -> Scenario:
    """Validate an already-decoded TOML document (see :func:`load_scenario`); ``limits`` bound
    the size of the files it names (None: no bound)."""
    max_bytes = None if limits is None else limits.input_bytes
    root = Table(path, "", data, (Scenario,))
    check_keys(path, data)  # before any file is read
    root.expect(KEYS[""])
    name = safe_name(root.string("name", path.stem), safe_name(path.stem))
    description = root.get("description")
    if not isinstance(description, str):
        raise root.fail("description", "must be a string")
    seed = root.number("seed", lo=0, hi=MAX_SEED, integer=True)
    duration = root.number("duration", gt=0.0)

    w = root.table("world", WorldConfig, RoadConfig)
    world = parse_world(w, path)
    w.done()

    f = root.table("fleet", FleetConfig)
    f.expect(KEYS["fleet"])
    fleet = FleetConfig(
        agents=f.number("agents", lo=1, integer=True),
        uav_fraction=f.number("uav_fraction", lo=0.0, hi=1.0),
        uav_speed=f.number("uav_speed", gt=0.0),
        ugv_speed=f.number("ugv_speed", gt=0.0),
        uav_max_start_altitude=f.number("uav_max_start_altitude", lo=0.0),
        placement=f.string("placement", choices=("uniform", "demand")),
        capacity=f.number("capacity", lo=1, hi=10_000, integer=True),
    )
    start = f.given("start")  # the file's name
    if start is not None:
        if not isinstance(start, str) or not start:
            raise f.fail("start", f"must be a CSV file of vehicle_id and node or x, y; "
                                  f"got {start!r}")
        start_path = (path.parent / start).resolve()
        kind = space_class(world.space)
        with f.reading("start", start_path):
            rows = read_fleet_start(start_path, kind.start_nodes, kind.start_z, max_bytes)
            capacities = read_fleet_capacities(start_path, max_bytes)
        agents = fleet.agents if "agents" in f.data else len(rows)
        if agents > len(rows):
            raise f.fail("agents", f"{agents} vehicles but the start file {start} places "
                                   f"{len(rows)}")
        fleet = replace(fleet, agents=agents, start=rows, start_file=start_path,
                        capacities=capacities[:agents])
    if "energy" in f.data:
        with f.reading("start", fleet.start_file or path):  # its soc column
            fleet = replace(fleet, energy=parse_energy(f.table("energy", EnergyConfig), fleet,
                                                       world))
    if "breaks" in f.data:
        fleet = replace(fleet, breaks=parse_breaks(f.table("breaks", BreaksConfig), world))
    fleet = _parse_sizing(f, fleet)
    f.done()

    t = root.table("tasks", TaskConfig)
    t.expect(KEYS["tasks"])
    source = t.string("source", choices=SOURCES)
    tasks = TaskConfig(
        source=source,
        count=t.number("count", lo=1, integer=True),
        interval=t.number("interval", gt=0.0),
        rate=t.number("rate", gt=0.0),
        max_active=t.number("max_active", lo=1, integer=True),
        ground_fraction=t.number("ground_fraction", lo=0.0, hi=1.0),
        service_time=t.number("service_time", lo=0.0),
        ttl=t.number("ttl", gt=0.0),
    )
    max_wait = EMPIRICAL_MAX_WAIT if source == "empirical" else t.default("max_wait")
    tasks = replace(tasks, max_wait=t.number("max_wait", max_wait, gt=0.0),
                    max_delay=t.number("max_delay", lo=0.0),
                    max_walk=t.number("max_walk", lo=0.0),
                    walk_speed=t.number("walk_speed", gt=0.0),
                    meeting_points=t.number("meeting_points", lo=1, integer=True))
    tasks = _parse_empirical(t, tasks, world, fleet)
    tasks = replace(tasks, prebook_share=t.number("prebook_share", lo=0.0, hi=1.0),
                    prebook_lead=t.number("prebook_lead", lo=0.0))
    trace = t.get("trace")
    if source == "periodic" and tasks.interval is None:
        raise t.fail("interval", "is required when source = 'periodic'")
    if source == "poisson" and tasks.rate is None:
        raise t.fail("rate", "is required when source = 'poisson'")
    start, max_snap = _parse_start(t, source), _parse_max_snap(t, source, world)
    id_column = t.string("id_column")
    if source == "trace":
        if not isinstance(trace, str) or not trace:
            raise t.fail("trace", "is required when source = 'trace' (a CSV or Parquet file)")
        trace_path = shipped_trace(trace) or (path.parent / trace).resolve()
        with t.reading("trace", trace_path):
            try:
                trips = _read_trace(trace_path, world.space,
                                    space_class(world.space).trace_bounds(world), max_bytes,
                                    start, id_column=id_column)
            except IdColumnMissing as e:
                raise t.fail("id_column", f"{trace_path.name} has no column {e.column!r}"
                                          f"{did_you_mean(e.column, e.columns)} (its columns: "
                                          f"{', '.join(e.columns)})") from None
        if max_snap is not None:
            trips = _within_snap(t, trips, world, max_snap)
        say_dropped(trace_path, trips)
        tasks = replace(tasks, trace=trace_path, trips=trips, start=start, max_snap=max_snap,
                        id_column=id_column)
    elif trace is not None:
        raise t.fail("trace", f"is only used when source = 'trace' (source is {source!r})")
    elif id_column is not None:
        raise t.fail("id_column", f"is only used when source = 'trace' (source is {source!r})")
    for k, value, allowed in (("interval", tasks.interval, ("periodic",)),
                              ("rate", tasks.rate, ("poisson",)),
                              ("max_active", tasks.max_active, ("periodic", "poisson")),
                              ("count", tasks.count, ("static", "periodic", "poisson", "trace"))):
        if value is not None and source not in allowed:
            raise t.fail(k, f"is only used when source is {' or '.join(allowed)} (not {source!r})")
    t.done()
    if fleet.start_file is not None:  # (date-times in the shift columns need [tasks] start)
        with f.reading("start", fleet.start_file):
            fleet = replace(fleet, shifts=read_shifts(fleet.start_file, fleet.agents, start,
                                                      max_bytes))

    d = root.table("dispatch", DispatchConfig)
    d.expect(KEYS["dispatch"])
    reassign = d.flag("reassign")
    features = space_class(world.space).features
    if reassign and "reassign" not in features:
        raise d.fail("reassign", "re-assignment before pickup needs a road network "
                                 "([world] network)")
    disp = DispatchConfig(
        allocator=d.string("allocator"),
        planner=d.string("planner", space_class(world.space).default_planner),
        batch_window=d.number("batch_window", lo=0.0),
        max_rounds=d.number("max_rounds", lo=1, integer=True),
        reassign=reassign,
        lazy_costs=d.flag("lazy_costs"),
        objective=d.string("objective", choices=("pickup_time", "added_time")),
        allocator_params=d.params("allocator_params"),
        planner_params=d.params("planner_params"),
    )
    disp = replace(disp, prebook=d.string("prebook", choices=PREBOOK_MODES),
                   prebook_lead=d.number("prebook_lead", gt=0.0),
                   out_of_reach=d.string("out_of_reach", choices=OUT_OF_REACH))
    d.done()
    _check_prebooking(path, world, tasks, disp)
    _check_pooling(path, world, fleet, tasks, disp)

    c = root.table("comms", CommsConfig)
    c.expect(KEYS["comms"])
    comms = CommsConfig(
        range=c.number("range", lo=0.0),
        latency=c.number("latency", lo=0.0),
        loss=c.number("loss", lo=0.0),
    )
    if comms.loss >= 1.0:
        raise c.fail("loss", f"must be < 1 (a link that drops every message is no link; use "
                             f"a small range for agents that cannot talk), got {comms.loss!r}")
    c.done()

    faults = parse_faults(root.table("faults", FaultConfig), path)

    s = root.table("sweep", SweepConfig)
    s.expect(KEYS["sweep"])
    sweep = SweepConfig(
        allocator=s.str_list("allocator"),
        planner=s.str_list("planner"),
        agents=s.int_list("agents", lo=1),
        seed=s.int_list("seed", lo=0, hi=MAX_SEED),
        batch_window=_windows(s),
        reposition=s.str_list("reposition"),
    )
    disp = parse_allocators(d, s, disp, sweep)
    declared = "reposition" in root.data
    reposition = parse_reposition(root.table("reposition", RepositionConfig), sweep, s)
    disp, reposition = files_near(path, disp, reposition)  # (plugins' files: by the scenario)
    charging = parse_charging(root, path, fleet, faults, world)
    pricing = parse_pricing(root.table("pricing", Pricing), world)
    acceptor = parse_acceptor(root.table("acceptor", AcceptorConfig), pricing)
    transit = (parse_transit(root.table("transit", TransitConfig), path, world, disp.reassign)
               if "transit" in root.data else None)
    s.done()
    root.done()

    sc = Scenario(name=name, path=path, text=text, description=description, seed=seed,
                  duration=duration, world=world, fleet=fleet, tasks=tasks, dispatch=disp,
                  sweep=sweep, comms=comms, faults=faults,
                  reposition=replace(reposition, declared=declared or bool(sweep.reposition)),
                  charging=charging, acceptor=acceptor, pricing=pricing, transit=transit)
    for n in sweep.agents or (fleet.agents,):
        _check_fits(sc, n, "sweep.agents" if sweep.agents else "fleet.agents")
    return sc


def _check_prebooking(path: Path, world: WorldConfig, tasks: TaskConfig,
                      disp: DispatchConfig) -> None:
    """Prebooking (dispatch.decide.prebook) inserts into plans: a road network, no re-assignment
    before pickup, and one source of bookings (a trace's ``booked_at`` or ``prebook_share``)."""
    if not tasks.prebooked:
        return
    key = "tasks.prebook_share" if tasks.prebook_share > 0 else "tasks.trace"
    if "pooling" not in space_class(world.space).features:
        raise ScenarioError(path, key, "prebooking needs a road network ([world] network)")
    if disp.reassign:
        raise ScenarioError(path, "dispatch.reassign", "re-assignment before pickup and "
                                                       "prebooking do not go together")
    if tasks.prebook_share > 0 and tasks.trips is not None and tasks.trips.prebooked:
        raise ScenarioError(path, "tasks.prebook_share", "the trace has a booked_at column: "
                                                         "its bookings are used, not a share")


def _check_pooling(path: Path, world: WorldConfig, fleet: FleetConfig, tasks: TaskConfig,
                   disp: DispatchConfig) -> None:
    """Shared rides (a capacity above 1) and drop-off limits are for road networks; a pooled
    fleet, or riders who walk, decide without re-assignment before pickup."""
    pooled = fleet.pooled
    pooling = "pooling" in space_class(world.space).features
    if not pooling:
        if pooled:
            key = "fleet.capacity" if fleet.capacity > 1 else "fleet.start"
            raise ScenarioError(path, key, "shared rides (a capacity above 1) need a road "
                                           "network ([world] network)")
        if tasks.max_delay is not None:
            raise ScenarioError(path, "tasks.max_delay", "a drop-off delay limit needs a road "
                                                         "network ([world] network)")
        if tasks.walking:
            raise ScenarioError(path, "tasks.max_walk", "meeting points need a road network "
                                                        "([world] network)")
        if disp.objective != "pickup_time":
            raise ScenarioError(path, "dispatch.objective", "added_time needs a road network "
                                                            "([world] network)")
    if pooled and disp.reassign:
        raise ScenarioError(path, "dispatch.reassign", "re-assignment before pickup is for "
                                                       "vehicles of capacity 1")
    if tasks.walking and disp.reassign:
        # meeting points go out as insertions, which re-assignment drops as stale: a loop
        raise ScenarioError(path, "dispatch.reassign", "re-assignment before pickup and "
                                                       "meeting points (max_walk) do not go "
                                                       "together")
    trips = tasks.trips
    if trips is not None and trips.passengers is not None and len(trips) and not pooling \
            and int(trips.passengers.max()) > 1:
        raise ScenarioError(path, "tasks.trace", "passengers above 1 need a road network")


def _parse_sizing(f: Table, fleet: FleetConfig) -> FleetConfig:
    """``[fleet] shift_grace`` (seconds), ``sizing`` (a ``dispatch.sizers`` plugin) and its
    ``[fleet.sizing_params]`` (see :mod:`dispatch.fleet.shifts`)."""
    sizing = f.string("sizing")  # None: left out
    if sizing is not None and sizing not in registry.available("sizer"):
        raise f.fail("sizing", registry.unknown("sizer", sizing))
    if sizing is None and "sizing_params" in f.data:
        raise f.fail("sizing_params", "is only used with [fleet] sizing")
    return replace(fleet, shift_grace=f.number("shift_grace", lo=0.0), sizing=sizing,
                   sizing_params=f.params("sizing_params"))


def _parse_start(t: Table, source: str) -> datetime | None:
    """``[tasks] start``: the date-time of second 0 of a trace of ``departure_time`` date-times
    (an ISO 8601 string such as "2014-12-21T00:00", or a TOML date-time)."""
    v = t.get("start")
    if v is None:  # left out
        return None
    if source != "trace":
        raise t.fail("start", f"is only used when source = 'trace' (not {source!r})")
    try:
        return parse_datetime(v)
    except (TypeError, ValueError):
        raise t.fail("start", f"must be a date-time such as \"2014-12-21T00:00\", got "
                              f"{_short(v)}") from None


def _parse_max_snap(t: Table, source: str, world: WorldConfig) -> float | None:
    """``[tasks] max_snap``: metres (> 0) a trace's pickup or drop-off may lie from the road
    network's nearest node."""
    v = t.number("max_snap", gt=0.0)
    if v is not None and (source != "trace" or "snap" not in space_class(world.space).features):
        raise t.fail("max_snap", "is only used with a trace on a road network "
                                 "(source = 'trace', [world] network)")
    return v


def _read_trace(path: Path, space: str, bounds, max_bytes: int | None,
                start: datetime | None, *, id_column: str | None) -> Trips:
    """:func:`dispatch.files.traces.read_trace`, the trips kept for the file's bytes as they are: a
    scenario parsed again (the same file in one process: tests, notebooks, a second command)
    does not read a large trace again."""
    check_file(path, max_bytes, "table file")  # before opening it: not a FIFO, not too large
    try:
        with open(path, "rb") as fh:
            digest = hashlib.file_digest(fh, "blake2b").digest()
    except OSError:
        return read_trace(path, space, bounds, max_bytes, start=start,  # it says why
                          id_column=id_column)
    return _read_trace_of(path, digest, space, bounds, max_bytes, start=start,
                          id_column=id_column)


@functools.lru_cache(maxsize=1)
def _read_trace_of(path: Path, digest: bytes, space: str, bounds, max_bytes: int | None, *,
                   start: datetime | None, id_column: str | None) -> Trips:
    return read_trace(path, space, bounds, max_bytes, start=start, id_column=id_column)


def _within_snap(t: Table, trips: Trips, world: WorldConfig, max_snap: float) -> Trips:
    """The trace's trips within ``max_snap`` metres of the network (loaded here: it is cached
    for the run); ScenarioError when none is left or the network cannot be loaded."""
    from dispatch.space.roads import load_network

    if trips.layout == "node":
        raise t.fail("max_snap", "is only used with a trace of coordinates (its trips name "
                                 "network nodes)")
    r = world.roads
    try:
        net = load_network(r.network, base=r.base, blocks=r.blocks, block=r.block,
                           speed=r.speed)
        kept = within_snap(trips, net, max_snap)
    except (ValueError, OSError) as e:
        raise ScenarioError(t.file, "world.network", str(e)) from None
    except Exception as e:  # noqa: BLE001 - a malformed file raises whatever its parser raises
        raise ScenarioError(t.file, "world.network", f"{r.network} cannot be read "
                                                     f"({type(e).__name__}: {e})") from None
    if not len(kept):
        raise t.fail("max_snap", f"leaves no trip of {trips.path.name}: every one has a pickup "
                                 f"or drop-off farther than {max_snap:g} m from a node of "
                                 f"{net.name}")
    return kept


def _windows(s: Table) -> tuple[float, ...]:
    """``[sweep] batch_window``: distinct finite seconds >= 0."""
    v = s.get("batch_window")
    if not isinstance(v, (list, tuple)) or any(
            isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
            or x < 0 for x in v) or len(set(v)) != len(v):
        raise s.fail("batch_window", f"must be a list of distinct seconds >= 0, got {_short(v)}")
    return tuple(float(x) for x in v)


def _parse_empirical(t: Table, tasks: TaskConfig, world: WorldConfig,
                     fleet: FleetConfig) -> TaskConfig:
    """``[tasks] source = "empirical"``: ``trips_per_day`` and ``weekday`` (see
    :mod:`dispatch.files.empirical`); the sample is snapped to the Chicago network only."""
    if tasks.source != "empirical":
        for k in ("trips_per_day", "weekday"):
            if k in t.data:
                raise t.fail(k, f"is only used when source = 'empirical' (not {tasks.source!r})")
        if fleet.placement == "demand":
            raise t.fail("source", "fleet.placement = 'demand' places vehicles on the empirical "
                                   "sample's pickups; it needs source = 'empirical'")
        return tasks
    if world.roads is None or world.roads.network != "chicago":
        raise t.fail("source", "'empirical' draws trips from the Chicago taxi sample, snapped "
                               "to the Chicago network: set world.network = 'chicago'")
    if "trips_per_day" not in t.data:
        raise t.fail("trips_per_day", "is required when source = 'empirical' (the expected "
                                      "number of trips over the 24 h day)")
    return replace(tasks, trips_per_day=t.number("trips_per_day", gt=0.0),
                   weekday=t.string("weekday", choices=("all", *WEEKDAYS)))


def check_limits(sc: Scenario, specs: list[RunSpec], limits: Limits = LIMITS) -> None:
    """Refuse runs that would not finish or not fit in memory (``--ignore-limits`` skips this):
    too many runs, voxel cells, vehicles, static tasks, releases of a generated source,
    intersections of a generated grid, or calls of a periodic process (a period too short).
    Each refusal names the key, the amount and the bound."""

    def refuse(key: str, what: str) -> ScenarioError:
        return ScenarioError(sc.path, key, f"{what}; {LIMITS_HINT}")

    sweep_key = "sweep" if sc.sweep.declared else "<runs>"
    if len(specs) > limits.runs:
        raise refuse(sweep_key, f"expands to {len(specs):,} runs (more than {limits.runs:,})")
    space_class(sc.world.space).check_size(sc.world, limits, refuse)
    agents = max(s.agents for s in specs)
    if agents > limits.agents:
        raise refuse("sweep.agents" if sc.sweep.agents else "fleet.agents",
                     f"{agents:,} vehicles (more than {limits.agents:,})")
    t = sc.tasks
    if t.source == "static":
        m = max(s.n_static_tasks for s in specs)
        if m > limits.static_tasks:
            raise refuse("tasks.count" if t.count is not None else "fleet.agents",
                         f"{m:,} static tasks (more than {limits.static_tasks:,})")
    elif t.source in ("periodic", "poisson"):
        ticks = sc.duration / t.interval if t.source == "periodic" else sc.duration * t.rate
        key = "tasks.interval" if t.source == "periodic" else "tasks.rate"
        # skipped releases (max_active reached) still wake the source, so `count` bounds the
        # work only without max_active
        if t.count is not None and t.max_active is None:
            ticks = min(ticks, t.count)
        if not ticks <= limits.releases:
            raise refuse(key, f"about {ticks:.3g} releases in {sc.duration:g} s (more than "
                              f"{limits.releases:,}; set tasks.count to cap them)")
    elif t.source == "empirical" and not t.trips_per_day <= limits.releases:
        raise refuse("tasks.trips_per_day", f"{t.trips_per_day:.3g} trips a day (more than "
                                            f"{limits.releases:,})")
    elif t.trips is not None and len(t.trips) > limits.releases:
        raise refuse("tasks.trace", f"{len(t.trips):,} trips (more than {limits.releases:,})")
    from dispatch.scenario.budget import check_periodic, check_work  # runs that would not end

    check_periodic(sc, limits.periodic_calls, refuse)
    check_work(sc, specs, refuse)


