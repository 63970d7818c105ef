"""Scenario files: TOML parsed once into the frozen, typed configuration of
:mod:`dispatch.config`.

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
import tomllib
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

from dispatch.config import (
    LIMITS,
    MAX_AXIS_CELLS,
    MAX_SEED,
    ROAD_KEYS,
    SOURCES,
    VOXEL_KEYS,
    CommsConfig,
    DispatchConfig,
    FleetConfig,
    Limits,
    ObstacleConfig,
    RepositionConfig,
    RoadConfig,
    RunSpec,
    Scenario,
    SweepConfig,
    TaskConfig,
    Vec3,
    WorldConfig,
    _check_fits,
    _short,
    safe_name,
)
from dispatch.errors import FORCE_HINT, ScenarioError
from dispatch.faults import FaultConfig, read_failures
from dispatch.space import space_class
from dispatch.table_files import check_file, decode_text, read_bytes
from dispatch.traces import (
    Trips,
    parse_datetime,
    read_fleet_capacities,
    read_fleet_start,
    read_trace,
    shipped_trace,
    within_snap,
)

log = logging.getLogger(__name__)

class _Table:
    """A TOML table being read: typed getters that raise ScenarioError, unknown-key check."""

    def __init__(self, file: Path, prefix: str, data: Any) -> None:
        self.file, self.prefix = file, prefix
        if not isinstance(data, dict):
            raise ScenarioError(file, prefix.rstrip(".") or "<root>", "must be a table")
        self.data, self.used = data, set()

    def key(self, k: str) -> str:
        return f"{self.prefix}{k}"

    def fail(self, k: str, reason: str) -> ScenarioError:
        return ScenarioError(self.file, self.key(k), reason)

    def get(self, k: str, default: Any) -> Any:
        self.used.add(k)
        return self.data.get(k, default)

    def table(self, k: str) -> _Table:
        return _Table(self.file, self.key(k) + ".", self.get(k, {}))

    def number(self, k, default, *, lo=None, gt=None, hi=None, integer=False, optional=False):
        v = self.get(k, default)
        if v is None and optional:
            return None
        kind = "an integer" if integer else "a number"
        if isinstance(v, bool) or not isinstance(v, (int, float) if not integer else int):
            raise self.fail(k, f"must be {kind}, got {_short(v)}")
        if not integer and not math.isfinite(v):
            raise self.fail(k, f"must be finite, got {_short(v)}")
        if lo is not None and v < lo:
            raise self.fail(k, f"must be >= {lo}, got {_short(v)}")
        if gt is not None and v <= gt:
            raise self.fail(k, f"must be > {gt}, got {_short(v)}")
        if hi is not None and v > hi:
            raise self.fail(k, f"must be <= {hi}, got {_short(v)}")
        return int(v) if integer else float(v)

    def string(self, k, default, choices=None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str) or not v:
            raise self.fail(k, f"must be a non-empty string, got {_short(v)}")
        if choices and v not in choices:
            raise self.fail(k, f"must be one of {', '.join(choices)}; got {_short(v)}")
        return v

    def vec3(self, k, default, *, gt=0.0) -> Vec3:
        v = self.get(k, default)
        if (
            not isinstance(v, (list, tuple))
            or len(v) != 3
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)
        ):
            raise self.fail(k, f"must be a list of 3 numbers, got {_short(v)}")
        if any(not math.isfinite(x) or x <= gt for x in v):
            raise self.fail(k, f"every entry must be finite and > {gt}, got {_short(v)}")
        return tuple(float(x) for x in v)  # type: ignore[return-value]

    def str_list(self, k) -> tuple[str, ...]:
        v = self.get(k, [])
        if not isinstance(v, list) or any(not isinstance(x, str) or not x for x in v):
            raise self.fail(k, f"must be a list of names, got {_short(v)}")
        return tuple(v)

    def int_list(self, k, lo=None, hi=None) -> tuple[int, ...]:
        v = self.get(k, [])
        if not isinstance(v, list) or any(isinstance(x, bool) or not isinstance(x, int) for x in v):
            raise self.fail(k, f"must be a list of integers, got {_short(v)}")
        if lo is not None and any(x < lo for x in v):
            raise self.fail(k, f"every entry must be >= {lo}, got {_short(v)}")
        if hi is not None and any(x > hi for x in v):
            raise self.fail(k, f"every entry must be <= {hi}, got {_short(v)}")
        return tuple(v)

    def params(self, k) -> tuple[tuple[str, Any], ...]:
        v = self.get(k, {})
        if not isinstance(v, dict):
            raise self.fail(k, "must be a table of parameters")
        return tuple(sorted(v.items()))

    def params_all(self) -> tuple[tuple[str, Any], ...]:
        """This whole table as sorted parameters."""
        self.used.update(self.data)
        return tuple(sorted(self.data.items()))

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used))
            raise self.fail(unknown[0], f"unknown key (known keys here: {known})")


def load_scenario(path: str | Path, *, force: bool = False) -> Scenario:
    """Read and validate a scenario file; raise ScenarioError naming file, key and reason.

    The file must be a regular file of at most ``Limits.file_bytes`` (``force``: any size) in
    UTF-8; the traces and start files it names are size-checked before they are read too."""
    path = Path(path)
    limits = None if force else LIMITS
    data = read_bytes(path, None if limits is None else limits.file_bytes, "scenario file")
    text = decode_text(path, data)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(path, "<syntax>", f"invalid TOML: {e}") from None
    except RecursionError:
        raise ScenarioError(path, "<syntax>", "invalid TOML: arrays or tables nested too "
                                              "deeply") from None
    except (ValueError, MemoryError) as e:  # e.g. an integer of more than 4300 digits
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ScenarioError(path, "<syntax>", f"invalid TOML: {reason}") from None
    return parse_scenario(doc, path, text, limits=limits)


def parse_scenario(data: dict, path: Path, text: str = "", *,
                   limits: Limits | None = LIMITS) -> Scenario:
    """Validate an already-decoded TOML document (see :func:`load_scenario`); ``limits`` bound
    the size of the files it names (None: no bound)."""
    max_bytes = None if limits is None else limits.input_bytes
    root = _Table(path, "", data)
    name = safe_name(root.string("name", path.stem), safe_name(path.stem))
    description = root.get("description", "")
    if not isinstance(description, str):
        raise root.fail("description", "must be a string")
    seed = root.number("seed", 0, lo=0, hi=MAX_SEED, integer=True)
    duration = root.number("duration", 3600.0, gt=0.0)

    w = root.table("world")
    world = _parse_world(w, path)
    w.done()

    f = root.table("fleet")
    fleet = FleetConfig(
        agents=f.number("agents", 8, lo=1, integer=True),
        uav_fraction=f.number("uav_fraction", 0.5, lo=0.0, hi=1.0),
        uav_speed=f.number("uav_speed", 5.0, gt=0.0),
        ugv_speed=f.number("ugv_speed", 3.0, gt=0.0),
        uav_max_start_altitude=f.number("uav_max_start_altitude", 10.0, lo=0.0),
        placement=f.string("placement", "uniform", ("uniform", "demand")),
        capacity=f.number("capacity", 1, lo=1, hi=10_000, integer=True),
    )
    start = f.get("start", None)
    if start is not None:
        if not isinstance(start, str) or not start:
            raise f.fail("start", f"must be a CSV file of vehicle_id and node or x, y; got {start!r}")
        start_path = (path.parent / start).resolve()
        kind = space_class(world.space)
        rows = read_fleet_start(start_path, kind.start_nodes, kind.start_z, max_bytes)
        agents = fleet.agents if "agents" in f.data else len(rows)
        if agents > len(rows):
            raise f.fail("agents", f"{agents} vehicles but the start file {start} places "
                                   f"{len(rows)}")
        fleet = replace(fleet, agents=agents, start=rows, start_file=start_path,
                        capacities=read_fleet_capacities(start_path, max_bytes)[:agents])
    if "energy" in f.data:
        fleet = replace(fleet, energy=_parse_energy(f.table("energy"), fleet, world))
    f.done()

    t = root.table("tasks")
    source = t.string("source", "static", SOURCES)
    tasks = TaskConfig(
        source=source,
        count=t.number("count", None, lo=1, integer=True, optional=True),
        interval=t.number("interval", None, gt=0.0, optional=True),
        rate=t.number("rate", None, gt=0.0, optional=True),
        max_active=t.number("max_active", None, lo=1, integer=True, optional=True),
        ground_fraction=t.number("ground_fraction", 0.5, lo=0.0, hi=1.0),
        service_time=t.number("service_time", 0.0, lo=0.0),
        ttl=t.number("ttl", None, gt=0.0, optional=True),
    )
    tasks = replace(tasks, max_wait=t.number("max_wait", 600.0 if source == "empirical"
                                             else None, gt=0.0, optional=True),
                    max_delay=t.number("max_delay", None, lo=0.0, optional=True))
    tasks = _parse_empirical(t, tasks, world, fleet)
    trace = t.get("trace", None)
    if source == "periodic" and tasks.interval is None:
        raise t.fail("interval", "is required when source = 'periodic'")
    if source == "poisson" and tasks.rate is None:
        raise t.fail("rate", "is required when source = 'poisson'")
    start, max_snap = _parse_start(t, source), _parse_max_snap(t, source, world)
    if source == "trace":
        if not isinstance(trace, str) or not trace:
            raise t.fail("trace", "is required when source = 'trace' (a CSV or Parquet file)")
        trace_path = shipped_trace(trace) or (path.parent / trace).resolve()
        trips = _read_trace(trace_path, world.space,
                            space_class(world.space).trace_bounds(world), max_bytes, start)
        if max_snap is not None:
            trips = _within_snap(t, trips, world, max_snap)
        for reason, n in trips.dropped:
            log.warning("%s: %d of %d trips left out: %s", trace_path.name, n,
                        n + len(trips), reason)
        tasks = replace(tasks, trace=trace_path, trips=trips, start=start, max_snap=max_snap)
    elif trace is not None:
        raise t.fail("trace", f"is only used when source = 'trace' (source is {source!r})")
    for k, value, allowed in (("interval", tasks.interval, ("periodic",)),
                              ("rate", tasks.rate, ("poisson",)),
                              ("max_active", tasks.max_active, ("periodic", "poisson")),
                              ("count", tasks.count, ("static", "periodic", "poisson", "trace"))):
        if value is not None and source not in allowed:
            raise t.fail(k, f"is only used when source is {' or '.join(allowed)} (not {source!r})")
    t.done()

    d = root.table("dispatch")
    reassign = d.get("reassign", False)
    if not isinstance(reassign, bool):
        raise d.fail("reassign", f"must be true or false, got {reassign!r}")
    features = space_class(world.space).features
    if reassign and "reassign" not in features:
        raise d.fail("reassign", "re-assignment before pickup needs a road network "
                                 "([world] network)")
    lazy = d.get("lazy_costs", False)
    if not isinstance(lazy, bool):
        raise d.fail("lazy_costs", f"must be true or false, got {lazy!r}")
    disp = DispatchConfig(
        allocator=d.string("allocator", "hungarian"),
        planner=d.string("planner", space_class(world.space).default_planner),
        batch_window=d.number("batch_window", 0.0, lo=0.0),
        max_rounds=d.number("max_rounds", 1000, lo=1, integer=True),
        reassign=reassign,
        lazy_costs=lazy,
        objective=d.string("objective", "pickup_time", ("pickup_time", "added_time")),
        allocator_params=d.params("allocator_params"),
        planner_params=d.params("planner_params"),
    )
    d.done()
    _check_pooling(path, world, fleet, tasks, disp)

    c = root.table("comms")
    comms = CommsConfig(
        range=c.number("range", None, lo=0.0, optional=True),
        latency=c.number("latency", 0.0, lo=0.0),
        loss=c.number("loss", 0.0, lo=0.0),
    )
    if comms.loss >= 1.0:
        raise c.fail("loss", f"must be < 1 (a link that drops every message is no link; use "
                             f"a small range for agents that cannot talk), got {comms.loss!r}")
    c.done()

    faults = _parse_faults(root.table("faults"), path)

    s = root.table("sweep")
    sweep = SweepConfig(
        allocator=s.str_list("allocator"),
        planner=s.str_list("planner"),
        agents=s.int_list("agents", lo=1),
        seed=s.int_list("seed", lo=0, hi=MAX_SEED),
        batch_window=_windows(s),
        reposition=s.str_list("reposition"),
    )
    disp = _parse_allocators(d, s, disp, sweep)
    declared = "reposition" in root.data
    reposition = _parse_reposition(root.table("reposition"), sweep, s)
    charging = _parse_charging(root, path, fleet, faults)
    s.done()
    root.done()

    sc = Scenario(name=name, path=path, text=text, description=description, seed=seed,
                  duration=duration, world=world, fleet=fleet, tasks=tasks, dispatch=disp,
                  sweep=sweep, comms=comms, faults=faults,
                  reposition=replace(reposition, declared=declared or bool(sweep.reposition)),
                  charging=charging)
    for n in sweep.agents or (fleet.agents,):
        _check_fits(sc, n, "sweep.agents" if sweep.agents else "fleet.agents")
    return sc


def _check_pooling(path: Path, world: WorldConfig, fleet: FleetConfig, tasks: TaskConfig,
                   disp: DispatchConfig) -> None:
    """Shared rides (a capacity above 1) and drop-off limits are for road networks; a pooled
    fleet decides with exact costs and without re-assignment before pickup."""
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
        if disp.objective != "pickup_time":
            raise ScenarioError(path, "dispatch.objective", "added_time needs a road network "
                                                            "([world] network)")
    if pooled and disp.reassign:
        raise ScenarioError(path, "dispatch.reassign", "re-assignment before pickup is for "
                                                       "vehicles of capacity 1")
    trips = tasks.trips
    if trips is not None and trips.passengers is not None and len(trips) and not pooling \
            and int(trips.passengers.max()) > 1:
        raise ScenarioError(path, "tasks.trace", "passengers above 1 need a road network")


def _parse_start(t: _Table, source: str) -> datetime | None:
    """``[tasks] start``: the date-time of second 0 of a trace of ``departure_time`` date-times
    (an ISO 8601 string such as "2014-12-21T00:00", or a TOML date-time)."""
    v = t.get("start", None)
    if v is None:
        return None
    if source != "trace":
        raise t.fail("start", f"is only used when source = 'trace' (not {source!r})")
    try:
        return parse_datetime(v)
    except (TypeError, ValueError):
        raise t.fail("start", f"must be a date-time such as \"2014-12-21T00:00\", got "
                              f"{_short(v)}") from None


def _parse_max_snap(t: _Table, source: str, world: WorldConfig) -> float | None:
    """``[tasks] max_snap``: metres (> 0) a trace's pickup or drop-off may lie from the road
    network's nearest node."""
    v = t.number("max_snap", None, gt=0.0, optional=True)
    if v is not None and (source != "trace" or "snap" not in space_class(world.space).features):
        raise t.fail("max_snap", "is only used with a trace on a road network "
                                 "(source = 'trace', [world] network)")
    return v


def _read_trace(path: Path, space: str, bounds, max_bytes: int | None,
                start: datetime | None) -> Trips:
    """:func:`dispatch.traces.read_trace`, the trips kept for the file's bytes as they are: a
    scenario parsed again (``dispatch run --duration`` parses its text again) does not read a
    large trace again."""
    check_file(path, max_bytes, "table file")  # before opening it: not a FIFO, not too large
    try:
        with open(path, "rb") as fh:
            digest = hashlib.file_digest(fh, "blake2b").digest()
    except OSError:
        return read_trace(path, space, bounds, max_bytes, start=start)  # it says why
    return _read_trace_of(path, digest, space, bounds, max_bytes, start)


@functools.lru_cache(maxsize=1)
def _read_trace_of(path: Path, digest: bytes, space: str, bounds, max_bytes: int | None,
                   start: datetime | None) -> Trips:
    return read_trace(path, space, bounds, max_bytes, start=start)


def _within_snap(t: _Table, trips: Trips, world: WorldConfig, max_snap: float) -> Trips:
    """The trace's trips within ``max_snap`` metres of the network (loaded here: it is cached
    for the run); ScenarioError when none is left or the network cannot be loaded."""
    from dispatch.roads import load_network

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


def _windows(s: _Table) -> tuple[float, ...]:
    """``[sweep] batch_window``: distinct finite seconds >= 0."""
    v = s.get("batch_window", [])
    if not isinstance(v, list) or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                      or not math.isfinite(x) or x < 0 for x in v) \
            or len(set(v)) != len(v):
        raise s.fail("batch_window", f"must be a list of distinct seconds >= 0, got {_short(v)}")
    return tuple(float(x) for x in v)


def _parse_empirical(t: _Table, tasks: TaskConfig, world: WorldConfig,
                     fleet: FleetConfig) -> TaskConfig:
    """``[tasks] source = "empirical"``: ``trips_per_day`` and ``weekday`` (see
    :mod:`dispatch.empirical`); the sample is snapped to the Chicago network only."""
    from dispatch.empirical import WEEKDAYS

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
    return replace(tasks, trips_per_day=t.number("trips_per_day", None, gt=0.0),
                   weekday=t.string("weekday", "all", ("all", *WEEKDAYS)))


def _parse_congestion(w: _Table, network: str) -> tuple[float, ...]:
    """``[world] congestion``: "chicago_taxi" (the factors calibrated from the taxi sample), a
    list of 24 factors > 0 (hour 0 first), or false / absent (free-flow times)."""
    v = w.get("congestion", False)
    if v is False:
        return ()
    if v == "chicago_taxi":
        from dispatch.empirical import load_factors

        return load_factors().factors
    ok = isinstance(v, list) and len(v) == 24 and all(
        not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) and x > 0
        for x in v)
    if not ok:
        raise w.fail("congestion", f"must be 'chicago_taxi', false or a list of 24 factors > 0 "
                                   f"(one per hour of day), got {_short(v)}")
    return tuple(float(x) for x in v)
def _parse_allocators(d: _Table, s: _Table, disp: DispatchConfig,
                      sweep: SweepConfig) -> DispatchConfig:
    """The allocators a file names (``dispatch.allocator``, ``sweep.allocator``), checked
    against the installed ones (an unknown name suggests the closest), and
    ``[dispatch.allocator_params]`` split into the flat keys (every allocator gets them) and
    one table per allocator or named variant (``[dispatch.allocator_params.magnnet]``,
    ``[dispatch.allocator_params."magnnet:paper"]``); a variant ``name:v`` in a list needs its
    table."""
    from dispatch import registry

    installed = registry.available("allocator")
    p = _Table(d.file, d.key("allocator_params") + ".", dict(disp.allocator_params))
    named = {disp.allocator, *sweep.allocator}

    def known(tab: _Table, key: str, name: str) -> None:
        base, colon, variant = name.partition(":")
        if base not in installed:
            raise tab.fail(key, registry.unknown("allocator", name))
        if colon and not variant:
            raise tab.fail(key, f"{name!r}: a named variant is 'allocator:variant'")

    flat, tables = [], []
    for k, v in disp.allocator_params:
        if isinstance(v, dict) and (k.partition(":")[0] in installed or ":" in k or k in named):
            quoted = f'"{k}"' if ":" in k else k  # as the file writes the table's name
            known(p, quoted, k)
            tables.append((k, _Table(d.file, p.key(quoted) + ".", v).params_all()))
        else:
            flat.append((k, v))
    for tab, names in ((d, (disp.allocator,)), (s, sweep.allocator)):
        for name in names:
            known(tab, "allocator", name)
            if ":" in name and name not in dict(tables):
                raise tab.fail("allocator", f"{name!r} names a variant of "
                                            f"{name.partition(':')[0]!r} without parameters: "
                                            f"add a [dispatch.allocator_params.\"{name}\"] "
                                            "table")
    return replace(disp, allocator_params=tuple(flat), allocator_tables=tuple(tables))


def _parse_reposition(r: _Table, sweep: SweepConfig, s: _Table) -> RepositionConfig:
    """``[reposition]``: the policy (an installed repositioner), its timer and look-back, and
    one ``[reposition.<name>]`` table of constructor arguments per policy that runs. Names are
    checked against the installed repositioners here; a policy's own arguments are checked by
    its constructor, the space it serves by :func:`dispatch.plugins.check_repositioner`
    (``dispatch validate`` does both)."""
    from dispatch import registry

    installed = registry.available("repositioner")
    policy = r.string("policy", "stay")
    interval = r.number("interval", 300.0, gt=0.0)
    horizon = r.number("horizon", 1800.0, gt=0.0)

    def known(tab: _Table, key: str, name: str) -> None:
        if name not in installed:
            raise tab.fail(key, f"unknown repositioner {name!r}; installed repositioners: "
                                f"{', '.join(installed) or 'none'}")

    known(r, "policy", policy)
    for name in sweep.reposition:
        known(s, "reposition", name)
    running = set(sweep.reposition or (policy,))
    params = []
    for name in sorted(k for k in r.data if k not in ("policy", "interval", "horizon")):
        if not isinstance(r.data[name], dict):
            raise r.fail(name, "unknown key (known keys here: horizon, interval, policy, and "
                               "one [reposition.<name>] table of parameters per repositioner)")
        known(r, name, name)
        if name not in running:
            raise r.fail(name, f"parameters of repositioner {name!r}, which does not run "
                               f"(running: {', '.join(sorted(running))})")
        params.append((name, r.params(name)))
    r.done()
    return RepositionConfig(policy=policy, interval=interval, horizon=horizon,
                            params=tuple(params))


def _parse_faults(f: _Table, path: Path) -> FaultConfig:
    """``[faults]``: vehicle breakdowns (a rate, a file) and communication blackouts."""
    rate = f.number("rate", 0.0, lo=0.0)
    repair = f.get("repair", 600.0)
    if isinstance(repair, bool) or not isinstance(repair, (int, float)) or math.isnan(repair) \
            or repair <= 0:
        raise f.fail("repair", f"must be a number of seconds > 0 (inf: for good), got {repair!r}")
    events: tuple = ()
    file = f.get("file", None)
    if file is not None:
        if not isinstance(file, str) or not file:
            raise f.fail("file", f"must be a CSV file of t, vehicle_id, duration; got {file!r}")
        events = read_failures((path.parent / file).resolve())
    on_board = f.string("on_board", "transfer", ("transfer", "fail"))
    tow = f.number("tow", 3600.0, gt=0.0)
    windows = f.get("blackout", [])
    if not isinstance(windows, list) or any(
            not isinstance(w, list) or len(w) != 2
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                   or x < 0 for x in w) or w[0] >= w[1] for w in windows):
        raise f.fail("blackout", f"must be a list of [t0, t1] windows with 0 <= t0 < t1, "
                                 f"got {windows!r}")
    region = f.get("blackout_region", None)
    if region is not None:
        if not isinstance(region, list) or len(region) != 4 or any(
                isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                for x in region) or region[0] > region[2] or region[1] > region[3]:
            raise f.fail("blackout_region", f"must be [x0, y0, x1, y1] in metres with x0 <= x1 "
                                            f"and y0 <= y1, got {region!r}")
        if not windows:
            raise f.fail("blackout_region", "needs blackout windows")
    f.done()
    return FaultConfig(rate=rate, repair=float(repair), events=events, on_board=on_board, tow=tow,
                       blackout=tuple((float(a), float(b)) for a, b in windows),
                       region=None if region is None else tuple(float(x) for x in region))


def _parse_world(w: _Table, path: Path) -> WorldConfig:
    """``[world]``: a voxel world (size, cell, obstacles) or a road network (network, ...)."""
    physics = w.get("physics", None)
    if physics is not None and not isinstance(physics, bool):
        raise w.fail("physics", f"must be true or false, got {physics!r}")
    if "network" in w.data:
        for k in VOXEL_KEYS:
            if k in w.data:
                raise w.fail(k, "is a voxel-world key; a road network (world.network) has none")
        network = w.string("network", "manhattan")
        blocks = w.int_list("blocks", lo=2) if "blocks" in w.data else (20, 20)
        if len(blocks) != 2:
            raise w.fail("blocks", f"must be [columns, rows] (intersections), got {list(blocks)}")
        block = w.number("block", 200.0, gt=0.0)
        speed = w.number("speed", 10.0, gt=0.0)
        if network != "manhattan":
            for k in ("blocks", "block", "speed"):
                if k in w.data:
                    raise w.fail(k, f"only describes network = 'manhattan' (not {network!r})")
        if physics:
            raise w.fail("physics", "the PyBullet mirror shows voxel worlds; a road network "
                                    "runs without it")
        edge_events = w.get("edge_events", False)
        if not isinstance(edge_events, bool):
            raise w.fail("edge_events", f"must be true or false, got {edge_events!r}")
        roads = RoadConfig(network=network, base=path.parent.resolve(), blocks=tuple(blocks),
                           block=block, speed=speed, congestion=_parse_congestion(w, network))
        return WorldConfig(roads=roads, physics=bool(physics), edge_events=edge_events)
    for k in (*ROAD_KEYS, "edge_events", "congestion"):
        if k in w.data:
            raise w.fail(k, "describes a road network; set world.network to use one")
    size = w.vec3("size", [50, 50, 30])
    cell = w.number("cell", 1.0, gt=0.0)
    for axis, s in zip("xyz", size):
        if not s / cell <= MAX_AXIS_CELLS:
            raise w.fail("cell", f"{cell} m cells make the world {s / cell:.3g} cells along "
                                 f"{axis} ({s} m); at most {MAX_AXIS_CELLS:,} per axis")
    for axis, s in zip("xyz", size):
        if abs(s / cell - round(s / cell)) > 1e-9 or round(s / cell) < 1:
            raise w.fail("size", f"{axis} size {s} is not a whole number of {cell} m cells")
    o = w.table("obstacles")
    obstacles = ObstacleConfig(
        count=o.number("count", 10, lo=0, integer=True),
        min_size=o.vec3("min_size", [3, 3, 5]),
        max_size=o.vec3("max_size", [10, 10, 30]),
    )
    for a, (lo_, hi_, s) in enumerate(zip(obstacles.min_size, obstacles.max_size, size)):
        if lo_ > hi_:
            raise o.fail("min_size", f"entry {a} ({lo_}) is larger than max_size's ({hi_})")
        if a < 2 and hi_ > s:
            raise o.fail("max_size", f"entry {a} ({hi_} m) does not fit in the world ({s} m)")
    o.done()
    world = WorldConfig(size=size, cell=cell, obstacles=obstacles,
                        physics=True if physics is None else physics)
    _check_obstacles_fit(o, world)
    return world


def _check_obstacles_fit(o: _Table, world: WorldConfig) -> None:
    """Obstacles stand one free cell apart: their smallest footprints must fit the ground."""
    nx, ny, _ = world.shape
    w = max(1, round(world.obstacles.min_size[0] / world.cell))
    d = max(1, round(world.obstacles.min_size[1] / world.cell))
    need = world.obstacles.count * (w + 1) * (d + 1)
    have = (nx + 1) * (ny + 1)
    if need > have // 2:
        raise o.fail(
            "count",
            f"{world.obstacles.count} obstacles of at least {w}x{d} cells (plus a free margin) "
            f"do not fit in a {nx}x{ny} ground with room left to move; use fewer or smaller ones",
        )


def check_limits(sc: Scenario, specs: list[RunSpec], limits: Limits = LIMITS) -> None:
    """Refuse runs that would not finish or not fit in memory (``--force`` skips this): too
    many runs, voxel cells, vehicles, static tasks, releases of a generated source, or
    intersections of a generated grid. Each refusal names the key, the amount and the bound."""

    def refuse(key: str, what: str) -> ScenarioError:
        return ScenarioError(sc.path, key, f"{what}; {FORCE_HINT}")

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
    from dispatch.budget import check_work  # work bounds: runs that would not finish

    check_work(sc, specs, refuse)


def _parse_energy(e: _Table, fleet: FleetConfig, world: WorldConfig):
    """``[fleet.energy]`` (see :mod:`dispatch.energy`): batteries on a road network."""
    from dispatch.energy import EnergyConfig, read_socs

    if "energy" not in space_class(world.space).features:
        raise e.fail("battery_kwh", "energy needs a road network ([world] network)")
    wh = e.get("wh_per_km", 140.0)
    table: tuple = ()
    if isinstance(wh, list):
        if len(wh) < 2 or any(not isinstance(r, list) or len(r) != 2 or any(
                isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                or x < 0 for x in r) for r in wh) or any(
                b[0] <= a[0] for a, b in zip(wh, wh[1:])):
            raise e.fail("wh_per_km", f"must be a number or a list of [km/h, Wh/km] pairs with "
                                      f"rising speeds, got {_short(wh)}")
        table = tuple((float(a), float(b)) for a, b in wh)
        wh = sum(b for _, b in table) / len(table)
    else:
        wh = e.number("wh_per_km", 140.0, gt=0.0)
    socs = () if fleet.start_file is None else read_socs(fleet.start_file)[:fleet.agents]
    cfg = EnergyConfig(
        battery_kwh=e.number("battery_kwh", 50.0, gt=0.0), wh_per_km=wh, speed_table=table,
        idle_kwh_per_hour=e.number("idle_kwh_per_hour", 0.0, lo=0.0),
        soc0=e.number("soc0", 1.0, lo=0.0, hi=1.0), reserve=e.number("reserve", 0.1, lo=0.0,
                                                                     hi=1.0),
        max_charge_kw=e.number("max_charge_kw", 1e9, gt=0.0), socs=socs,
        sample=e.number("sample", 900.0, gt=0.0))
    e.done()
    return cfg


def _parse_charging(root: _Table, path: Path, fleet: FleetConfig, faults):
    """``[chargers]`` (stations, taper) and ``[charging]`` (strategy, interval,
    ``[charging.<name>]``); None unless the fleet has energy."""
    from dispatch import registry
    from dispatch.energy import ChargingConfig, read_stations

    c, g = root.table("chargers"), root.table("charging")
    if fleet.energy is None:
        for t, k in ((c, "file"), (g, "strategy")):
            if t.data:
                raise t.fail(next(iter(t.data)), "needs [fleet.energy]")
        return None
    stations: tuple = ()
    file = c.get("file", None)
    if file is not None:
        if not isinstance(file, str) or not file:
            raise c.fail("file", f"must be a CSV file of stations, got {_short(file)}")
        fpath = (path.parent / file).resolve()
        try:
            stations = read_stations(fpath)
        except (OSError, ValueError) as err:
            raise c.fail("file", str(err)) from None
    else:
        fpath = None
    taper_from = c.number("taper_from", 0.8, lo=0.0, hi=1.0)
    taper_floor = c.number("taper_floor", 0.2, gt=0.0, hi=1.0)
    c.done()
    installed = registry.available("charger")
    strategy = g.string("strategy", "threshold")
    if strategy not in installed:
        raise g.fail("strategy", f"unknown charging strategy {strategy!r}; installed: "
                                 f"{', '.join(installed)}")
    interval = g.number("interval", 60.0, gt=0.0)
    params = []
    for name in sorted(k for k in g.data if k not in ("strategy", "interval")):
        if not isinstance(g.data[name], dict) or name not in installed:
            raise g.fail(name, "unknown key (known keys here: interval, strategy, and one "
                               "[charging.<name>] table per installed strategy)")
        params.append((name, g.params(name)))
    g.done()
    return ChargingConfig(stations=stations, file=fpath, taper_from=taper_from,
                          taper_floor=taper_floor, strategy=strategy, interval=interval,
                          params=tuple(params), tow=faults.tow)
