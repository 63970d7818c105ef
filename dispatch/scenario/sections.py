"""The self-contained tables of a scenario file, each parsed into its part of the typed
configuration (:mod:`dispatch.config`; a key left out takes its field's default): ``[world]``
(a voxel world or a road network, its obstacles and congestion), ``[faults]``,
``[fleet.energy]``, ``[chargers]`` and ``[charging]``, ``[reposition]``, ``[pricing]``,
``[acceptor]``, and the allocators a file names. :mod:`dispatch.scenario.load`
reads the file and the tables that depend on one another.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from dispatch.api import registry
from dispatch.api.acceptor import Pricing
from dispatch.api.space import space_class
from dispatch.config.breaks import BreaksConfig
from dispatch.config.dispatching import DispatchConfig
from dispatch.config.energy import ChargingConfig, EnergyConfig, read_socs, read_stations
from dispatch.config.faults import FaultConfig
from dispatch.config.fleet import FleetConfig
from dispatch.config.offers import AcceptorConfig
from dispatch.config.reposition import RepositionConfig
from dispatch.config.scenario import _short
from dispatch.config.sweep import SweepConfig
from dispatch.config.world import (MAX_AXIS_CELLS, ROAD_KEYS, VOXEL_KEYS, ObstacleConfig,
                                   RoadConfig, WorldConfig)
from dispatch.errors import PluginError
from dispatch.files.empirical import load_factors
from dispatch.files.failures import read_failures
from dispatch.scenario.toml_table import Table


def parse_world(w: Table, path: Path) -> WorldConfig:
    """``[world]``: a voxel world (size, cell, obstacles) or a road network (network, ...)."""
    physics = w.given("physics")  # None: left out (on in a voxel world, off on roads)
    if physics is not None and not isinstance(physics, bool):
        raise w.fail("physics", f"must be true or false, got {_short(physics)}")
    if "network" in w.data:
        for k in VOXEL_KEYS:
            if k in w.data:
                raise w.fail(k, "is a voxel-world key; a road network (world.network) has none")
        network = w.string("network")
        blocks = w.int_list("blocks", lo=2)
        if len(blocks) != 2:
            raise w.fail("blocks", f"must be [columns, rows] (intersections), got {list(blocks)}")
        block = w.number("block", gt=0.0)
        speed = w.number("speed", gt=0.0)
        if network != "manhattan":
            for k in ("blocks", "block", "speed"):
                if k in w.data:
                    raise w.fail(k, f"only describes network = 'manhattan' (not {network!r})")
        if physics:
            raise w.fail("physics", "the PyBullet mirror shows voxel worlds; a road network "
                                    "runs without it")
        edge_events = w.flag("edge_events")
        roads = RoadConfig(network=network, base=path.parent.resolve(), blocks=tuple(blocks),
                           block=block, speed=speed, congestion=_parse_congestion(w, network))
        return WorldConfig(roads=roads, physics=bool(physics), edge_events=edge_events)
    # a misspelt ``network`` leaves a table that looks like a voxel world's: name the closest
    # of both kinds' keys (road keys are then refused just below, with their reason)
    w.expect({*VOXEL_KEYS, *ROAD_KEYS, "edge_events", "congestion", "physics"})
    for k in (*ROAD_KEYS, "edge_events", "congestion"):
        if k in w.data:
            raise w.fail(k, "describes a road network; set world.network to use one")
    size = w.vec3("size")
    cell = w.number("cell", gt=0.0)
    for axis, s in zip("xyz", size):
        if not s / cell <= MAX_AXIS_CELLS:
            raise w.fail("cell", f"{cell} m cells make the world {s / cell:.3g} cells along "
                                 f"{axis} ({s} m); at most {MAX_AXIS_CELLS:,} per axis")
    for axis, s in zip("xyz", size):
        if abs(s / cell - round(s / cell)) > 1e-9 or round(s / cell) < 1:
            raise w.fail("size", f"{axis} size {s} is not a whole number of {cell} m cells")
    o = w.table("obstacles", ObstacleConfig)
    obstacles = ObstacleConfig(
        count=o.number("count", lo=0, integer=True),
        min_size=o.vec3("min_size"),
        max_size=o.vec3("max_size"),
    )
    for a, (lo_, hi_, s) in enumerate(zip(obstacles.min_size, obstacles.max_size, size)):
        if lo_ > hi_:
            raise o.fail("min_size", f"entry {a} ({lo_}) is larger than max_size's ({hi_})")
        if a < 2 and hi_ > s:
            raise o.fail("max_size", f"entry {a} ({hi_} m) does not fit in the world ({s} m)")
    o.done()
    world = WorldConfig(size=size, cell=cell, obstacles=obstacles,
                        physics=w.default("physics") if physics is None else physics)
    _check_obstacles_fit(o, world)
    return world


def _check_obstacles_fit(o: Table, world: WorldConfig) -> None:
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


def _parse_congestion(w: Table, network: str) -> tuple[float, ...]:
    """``[world] congestion``: "chicago_taxi" (the factors calibrated from the taxi sample), a
    list of 24 factors > 0 (hour 0 first), or false / absent (free-flow times)."""
    v = w.get("congestion")
    if v is False or "congestion" not in w.data:
        return w.default("congestion")
    if v == "chicago_taxi":
        return load_factors().factors
    ok = isinstance(v, list) and len(v) == 24 and all(
        not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) and x > 0
        for x in v)
    if not ok:
        raise w.fail("congestion", f"must be 'chicago_taxi', false or a list of 24 factors > 0 "
                                   f"(one per hour of day), got {_short(v)}")
    return tuple(float(x) for x in v)


def parse_faults(f: Table, path: Path) -> FaultConfig:
    """``[faults]``: vehicle breakdowns (a rate, a file) and communication blackouts."""
    rate = f.number("rate", lo=0.0)
    repair = f.get("repair")
    if isinstance(repair, bool) or not isinstance(repair, (int, float)) or math.isnan(repair) \
            or repair <= 0:
        raise f.fail("repair", f"must be a number of seconds > 0 (inf: for good), got {repair!r}")
    events: tuple = ()
    file = f.given("file")
    if file is not None:
        if not isinstance(file, str) or not file:
            raise f.fail("file", f"must be a CSV file of t, vehicle_id, duration; got {file!r}")
        fpath = (path.parent / file).resolve()
        with f.reading("file", fpath):
            events = read_failures(fpath)
    on_board = f.string("on_board", choices=("transfer", "fail"))
    tow = f.number("tow", gt=0.0)
    windows = f.get("blackout")
    if not isinstance(windows, (list, tuple)) or any(
            not isinstance(w, list) or len(w) != 2
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x)
                   or x < 0 for x in w) or w[0] >= w[1] for w in windows):
        raise f.fail("blackout", f"must be a list of [t0, t1] windows with 0 <= t0 < t1, "
                                 f"got {windows!r}")
    region = f.given("blackout_region")
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


def parse_breaks(b: Table, world: WorldConfig):
    """``[fleet.breaks]`` (see :mod:`dispatch.plan.breaks`): drivers' breaks on a road
    network."""
    if "depots" not in space_class(world.space).features:
        raise b.fail("after", "drivers' breaks need a road network ([world] network)")
    out = BreaksConfig(after=b.number("after", gt=0.0), duration=b.number("duration", gt=0.0))
    b.done()
    return out


def parse_energy(e: Table, fleet: FleetConfig, world: WorldConfig):
    """``[fleet.energy]`` (see :mod:`dispatch.fleet.battery`): batteries on a road network."""
    if "energy" not in space_class(world.space).features:
        raise e.fail("battery_kwh", "energy needs a road network ([world] network)")
    wh = e.get("wh_per_km")
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
        wh = e.number("wh_per_km", gt=0.0)
    socs = () if fleet.start_file is None else read_socs(fleet.start_file)[:fleet.agents]
    cfg = EnergyConfig(
        battery_kwh=e.number("battery_kwh", gt=0.0), wh_per_km=wh, speed_table=table,
        idle_kwh_per_hour=e.number("idle_kwh_per_hour", lo=0.0),
        soc0=e.number("soc0", lo=0.0, hi=1.0), reserve=e.number("reserve", lo=0.0, hi=1.0),
        max_charge_kw=e.number("max_charge_kw", gt=0.0), socs=socs,
        sample=e.number("sample", gt=0.0))
    e.done()
    return cfg


def parse_charging(root: Table, path: Path, fleet: FleetConfig, faults, world):
    """``[chargers]`` (stations, taper, the snap limit of stations given by lon/lat) and
    ``[charging]`` (strategy, interval, ``[charging.<name>]``); None unless the fleet has
    energy."""
    c, g = root.table("chargers", ChargingConfig), root.table("charging", ChargingConfig)
    if fleet.energy is None:
        for t, k in ((c, "file"), (g, "strategy")):
            if t.data:
                raise t.fail(next(iter(t.data)), "needs [fleet.energy]")
        return None
    stations: tuple = ()
    file = c.get("file")
    if file is not None:
        if not isinstance(file, str) or not file:
            raise c.fail("file", f"must be a CSV file of stations, got {_short(file)}")
        fpath = (path.parent / file).resolve()
        try:
            with c.reading("file", fpath):
                stations = read_stations(fpath)
        except (OSError, ValueError) as err:
            raise c.fail("file", str(err)) from None
    else:
        fpath = None
    taper_from = c.number("taper_from", lo=0.0, hi=1.0)
    taper_floor = c.number("taper_floor", gt=0.0, hi=1.0)
    max_snap = c.number("max_snap", gt=0.0)
    _check_station_snap(c, stations, world, max_snap)
    c.done()
    installed = registry.available("charger")
    strategy = g.string("strategy")
    if strategy not in installed:
        raise g.fail("strategy", f"unknown charging strategy {strategy!r}; installed: "
                                 f"{', '.join(installed)}")
    interval = g.number("interval", gt=0.0)
    params = []
    for name in sorted(k for k in g.data if k not in ("strategy", "interval")):
        if not isinstance(g.data[name], dict) or name not in installed:
            raise g.fail(name, "unknown key (known keys here: interval, strategy, and one "
                               "[charging.<name>] table per installed strategy)")
        params.append((name, g.params(name)))
    g.done()
    return ChargingConfig(stations=stations, file=fpath, taper_from=taper_from,
                          taper_floor=taper_floor, max_snap=max_snap, strategy=strategy,
                          interval=interval, params=tuple(params), tow=faults.tow)


def _check_station_snap(c: Table, stations, world, max_snap: float) -> None:
    """Refuse, naming it, the first station given by lon/lat that lies farther than
    ``max_snap`` metres from every node of the road network (it would be snapped to a node far
    from where it is); the network is loaded here (cached for the run)."""
    import numpy as np

    from dispatch.space.roads import load_network

    placed = [s for s in stations if s.node is None]
    if not placed or world.roads is None:
        return
    r = world.roads
    try:
        net = load_network(r.network, base=r.base, blocks=r.blocks, block=r.block,
                           speed=r.speed)
        far = net.nearest(net.lonlat_to_xy([s.lon for s in placed],
                                           [s.lat for s in placed]))[1]
    except (ValueError, OSError) as e:
        raise c.fail("file", f"its stations cannot be placed on {r.network}: {e}") from None
    beyond = np.flatnonzero(np.asarray(far) > max_snap)
    if len(beyond):
        s = placed[int(beyond[0])]
        more = f" (and {len(beyond) - 1} more)" if len(beyond) > 1 else ""
        raise c.fail("file", f"station {s.station_id!r} at lon {s.lon:g}, lat {s.lat:g} lies "
                             f"{float(far[beyond[0]]):,.0f} m from the nearest node of "
                             f"{net.name}, farther than chargers.max_snap = {max_snap:g} m"
                             f"{more}")


def parse_allocators(d: Table, s: Table, disp: DispatchConfig,
                      sweep: SweepConfig) -> DispatchConfig:
    """The allocators a file names (``dispatch.allocator``, ``sweep.allocator``), checked
    against the installed ones (an unknown name suggests the closest), and
    ``[dispatch.allocator_params]`` split into the flat keys (every allocator gets them) and
    one table per allocator or named variant (``[dispatch.allocator_params.magnnet]``,
    ``[dispatch.allocator_params."magnnet:paper"]``); a variant ``name:v`` in a list needs its
    table, unless its plugin declares ``v`` (:attr:`dispatch.api.contracts.Allocator.variants`)."""
    installed = registry.available("allocator")
    p = Table(d.file, d.key("allocator_params") + ".", dict(disp.allocator_params))
    named = {disp.allocator, *sweep.allocator}

    def known(tab: Table, key: str, name: str) -> None:
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
            tables.append((k, Table(d.file, p.key(quoted) + ".", v).params_all()))
        else:
            flat.append((k, v))
    for tab, names in ((d, (disp.allocator,)), (s, sweep.allocator)):
        for name in names:
            known(tab, "allocator", name)
            why = None if name in dict(tables) else registry.undeclared_variant(name)
            if why is not None:
                raise tab.fail("allocator", f"{name!r} names a variant of "
                                            f"{name.partition(':')[0]!r} without parameters: "
                                            f"add a [dispatch.allocator_params.\"{name}\"] "
                                            f"table ({why})")
    return replace(disp, allocator_params=tuple(flat), allocator_tables=tuple(tables))


def parse_reposition(r: Table, sweep: SweepConfig, s: Table) -> RepositionConfig:
    """``[reposition]``: the policy (an installed repositioner), its timer and look-back, and
    one ``[reposition.<name>]`` table of constructor arguments per policy that runs. Names are
    checked against the installed repositioners here; a policy's own arguments are checked by
    its constructor, the space it serves by :func:`dispatch.run.plugins.check_repositioner`
    (``dispatch validate`` does both)."""
    installed = registry.available("repositioner")
    policy = r.string("policy")
    interval = r.number("interval", gt=0.0)
    horizon = r.number("horizon", gt=0.0)

    def known(tab: Table, key: str, name: str) -> None:
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


def parse_pricing(p: Table, world: WorldConfig):
    """``[pricing]``: a ride's fare, ``base + per_km * km + per_minute * minutes`` of the
    direct ride, less ``sharing_discount`` (a share, 0-1) for a pooled one
    (:class:`dispatch.api.acceptor.Pricing`); None without the section. Fares are of rides on a
    road network (the direct route's metres)."""
    if not p.data:
        return None
    if "pricing" not in space_class(world.space).features:
        raise p.fail(next(iter(p.data)), "fares need a road network ([world] network)")
    pricing = Pricing(base=p.number("base", lo=0.0), per_km=p.number("per_km", lo=0.0),
                      per_minute=p.number("per_minute", lo=0.0),
                      sharing_discount=p.number("sharing_discount", lo=0.0, hi=1.0))
    p.done()
    return pricing


def parse_acceptor(a: Table, pricing):
    """``[acceptor]``: the acceptor that answers offers (an installed one, default
    ``always``), ``retries`` (times a declined request is offered again, default 0) and its
    parameters, ``[acceptor.<name>]`` (checked here by building it: its constructor's refusal
    becomes one line naming the file and the table)
    (:class:`dispatch.config.offers.AcceptorConfig`)."""
    if not a.data:  # every rider accepts: nothing to load
        return AcceptorConfig()
    installed = registry.available("acceptor")
    name = a.string("name")
    if name not in installed:
        raise a.fail("name", registry.unknown("acceptor", name))
    retries = a.number("retries", lo=0, integer=True)
    for k in sorted(k for k in a.data if k not in ("name", "retries")):
        if not isinstance(a.data[k], dict):
            raise a.fail(k, "unknown key (known keys here: name, retries, and the "
                            "[acceptor.<name>] table of the acceptor's parameters)")
        if k != name:
            raise a.fail(k, f"parameters of acceptor {k!r}, which does not run (name is "
                            f"{name!r})")
    params = a.params(name) if name in a.data else ()
    a.done()
    try:
        cls = registry.load("acceptor", name)
    except PluginError as e:
        raise a.fail("name", str(e)) from None
    bad = registry.unknown_parameter(cls, params)
    if bad is not None:  # (a typo: one line naming the key, not Python's TypeError)
        raise a.fail(f"{name}.{bad[0]}", f"acceptor {name!r} {bad[1]}")
    try:
        made = cls(**dict(params))
    except (TypeError, ValueError) as e:
        raise a.fail(name, " ".join(str(e).split()) or type(e).__name__) from None
    if made.uses_fare and pricing is None:
        raise a.fail("name", f"acceptor {name!r} weighs the fare: add a [pricing] section")
    return AcceptorConfig(name=name, retries=retries, params=tuple(params))


#: plugin parameters that name a file: read relative to the scenario file, as its other paths
FILE_PARAMS = ("value",)


def files_near(path: Path, disp, reposition):
    """``(disp, reposition)`` with each relative path of :data:`FILE_PARAMS` in the allocators'
    parameters and the repositioners' tables made absolute from the scenario file's folder (a
    learned value named in ``[dispatch.allocator_params]`` or ``[reposition.<name>]``)."""
    def near(params: tuple) -> tuple:
        return tuple((k, str((path.parent / v).resolve())
                      if k in FILE_PARAMS and isinstance(v, str) and not Path(v).is_absolute()
                      else v) for k, v in params)

    return (replace(disp, allocator_params=near(disp.allocator_params),
                    allocator_tables=tuple((k, near(v)) for k, v in disp.allocator_tables)),
            replace(reposition, params=tuple((k, near(v)) for k, v in reposition.params)))
