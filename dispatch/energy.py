"""Electric fleets: batteries, chargers as shared resources, charging strategies as plugins.

Everything here is off unless the scenario has ``[fleet.energy]``; a run without it builds none
of it and its tables are today's.

Energy (``[fleet.energy]``)
    Each vehicle carries a :class:`Battery`. A leg draws ``wh_per_km`` at the leg's mean speed
    (a constant, or a table of ``[km/h, Wh/km]`` points interpolated linearly, like HIVE's
    tabular powertrain) times its length, when it is counted (:meth:`dispatch.vehicles.Vehicle.
    drove`: a leg cut part-way by a decision, a breakdown or the horizon draws what was driven,
    at the cut part's mean speed). ``idle_kwh_per_hour`` is drawn over every second the
    vehicle is not plugged in (auxiliary load). The battery never goes below 0 kWh: a vehicle
    whose next leg would empty it drives until it is empty and is *stranded*
    (:meth:`Charging.strand`). Energy is conserved: ``kwh0 + kwh_charged - kwh_drawn = kwh``
    at every instant.

Reserve
    A vehicle whose plan, with a new request, would leave it below ``reserve`` of its battery
    is not a candidate for the request (``inf`` cost): the dispatcher estimates the energy of
    the plan's remaining drive seconds plus the drive to the pickup and the trip's direct time
    at the fleet's reference consumption (:attr:`Energy.kwh_per_second`).

Chargers (``[chargers]``)
    Stations from a CSV file (``station_id``, ``node`` or ``lon``/``lat``, ``plugs``, ``kw``);
    each is a ``simpy.Resource`` with one slot per plug: vehicles queue in SimPy's order.
    Power is ``min(station kw, [fleet.energy] max_charge_kw)`` up to ``taper_from`` (state of
    charge), then falls linearly to ``taper_floor`` of it at full (:func:`charge_seconds`).

A charging visit is a ``charge`` stop of the vehicle's stop list (:data:`CHARGE`, no task):
the vehicle drives to the station, queues (``queue`` event), charges (``charge_start``,
``charge_end``) to the strategy's target and is idle again. While on a visit it is neither
idle nor busy: no decision considers it. A breakdown ends the visit (the energy charged so far
counts). Strategies (``dispatch.chargers`` plugins, :class:`ChargingStrategy`) decide which
idle vehicles go where, every ``[charging] interval`` seconds.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import simpy

from dispatch.errors import PluginError
from dispatch.stops import Stop

if TYPE_CHECKING:
    from dispatch.events import EventBus
    from dispatch.vehicles import Fleet, Operator, Vehicle

CHARGE = "charge"
_EPS = 1e-12


# ----------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class EnergyConfig:
    """``[fleet.energy]`` (see the module docstring). ``speed_table``: ``((km/h, Wh/km), ...)``
    sorted by speed (empty: the constant ``wh_per_km``); ``socs``: a start file's ``soc``
    column per vehicle (row order; nan: ``soc0``)."""

    battery_kwh: float = 50.0
    wh_per_km: float = 140.0
    speed_table: tuple[tuple[float, float], ...] = ()
    idle_kwh_per_hour: float = 0.0
    soc0: float = 1.0
    reserve: float = 0.1
    max_charge_kw: float = math.inf
    socs: tuple[float, ...] = ()
    #: seconds between two rows per vehicle of the ``soc`` table
    sample: float = 900.0

    def wh_per_metre(self, speed: float) -> float:
        """Wh per metre at ``speed`` (m/s; 0 or nan: the constant, or the table's mean)."""
        if not self.speed_table:
            return self.wh_per_km / 1000.0
        s, w = zip(*self.speed_table)
        if not speed > 0:
            return float(np.mean(w)) / 1000.0
        return float(np.interp(speed * 3.6, s, w)) / 1000.0


@dataclass(frozen=True)
class StationRow:
    station_id: str
    node: Any  # a node id of the network file (or None: lon/lat given)
    lon: float
    lat: float
    plugs: int
    kw: float


@dataclass(frozen=True)
class ChargingConfig:
    """``[chargers]`` and ``[charging]``: the stations, the taper, the strategy and its
    parameters (``[charging.<name>]``), the timer."""

    stations: tuple[StationRow, ...] = ()
    file: Any = None
    taper_from: float = 0.8
    taper_floor: float = 0.2
    strategy: str = "threshold"
    interval: float = 60.0
    params: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    sweep: tuple[str, ...] = ()
    #: [faults] tow: seconds until a stranded vehicle stands charged-able at the nearest station
    tow: float = 3600.0

    def params_of(self, name: str) -> tuple[tuple[str, Any], ...]:
        return dict(self.params).get(name, ())


def read_stations(path, tab=None) -> tuple[StationRow, ...]:
    """Rows of a stations CSV: ``station_id``, ``node`` or ``lon``/``lat``, ``plugs``, ``kw``
    (HIVE's ``charger_count`` / ``charger_id`` are read as plugs / kW of LEVEL_1 3.3,
    LEVEL_2 7.2, DCFC 50 where ``plugs`` / ``kw`` are missing)."""
    import csv

    hive_kw = {"LEVEL_1": 3.3, "LEVEL_2": 7.2, "DCFC": 50.0}
    out = []
    with open(path, newline="", encoding="utf-8") as f:
        for i, r in enumerate(csv.DictReader(f), 1):
            try:
                sid = str(r["station_id"])
                plugs = int(r.get("plugs") or r["charger_count"])
                kw = float(r["kw"]) if r.get("kw") else hive_kw[r["charger_id"]]
                node = r.get("node") or None
                lon = float(r["lon"]) if r.get("lon") else math.nan
                lat = float(r["lat"]) if r.get("lat") else math.nan
            except (KeyError, ValueError) as e:
                raise ValueError(f"{path}: row {i}: {type(e).__name__}: {e} (want station_id, "
                                 f"node or lon/lat, plugs, kw)") from None
            if plugs < 1 or not kw > 0 or (node is None and math.isnan(lon + lat)):
                raise ValueError(f"{path}: row {i}: plugs must be >= 1, kw > 0, and a node or "
                                 f"lon/lat given")
            out.append(StationRow(sid, node, lon, lat, plugs, kw))
    if not out:
        raise ValueError(f"{path}: no station")
    return tuple(out)


def read_socs(path) -> tuple[float, ...]:
    """The optional ``soc`` column (0-1) of a fleet start file, in row order (blank: nan, the
    scenario's ``soc0``); empty if there is none."""
    import csv

    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows or "soc" not in rows[0]:
        return ()
    out = []
    for i, r in enumerate(rows, 1):
        x = float(r["soc"]) if r["soc"] not in ("", None) else math.nan
        if x == x and not 0.0 <= x <= 1.0:
            raise ValueError(f"{path}: row {i}: soc {x} not in [0, 1]")
        out.append(x)
    return tuple(out)


# ----------------------------------------------------------------------------- charging curve


def power_kw(soc: float, kw: float, taper_from: float, floor: float) -> float:
    """Charging power at state of charge ``soc``: ``kw`` up to ``taper_from``, then linear
    down to ``floor * kw`` at 1."""
    if soc <= taper_from or taper_from >= 1.0:
        return kw
    return kw * (1.0 - (1.0 - floor) * (soc - taper_from) / (1.0 - taper_from))


def charge_seconds(a: float, b: float, kwh: float, kw: float, taper_from: float,
                   floor: float) -> float:
    """Seconds to charge a ``kwh`` battery from state of charge ``a`` to ``b`` at ``kw``
    tapering as :func:`power_kw` (closed form: constant part + logarithmic taper part)."""
    if b <= a:
        return 0.0
    t = 0.0
    if a < taper_from:
        t += (min(b, taper_from) - a) * kwh / kw * 3600.0
        a = taper_from
    if b > a:
        k = (1.0 - floor) / (1.0 - taper_from)
        t += kwh / (kw * k) * math.log((1.0 - k * (a - taper_from)) /
                                       (1.0 - k * (b - taper_from))) * 3600.0
    return t


def soc_after(a: float, seconds: float, kwh: float, kw: float, taper_from: float,
              floor: float) -> float:
    """State of charge after charging ``seconds`` from ``a`` (the inverse of
    :func:`charge_seconds`)."""
    if seconds <= 0:
        return a
    if a < taper_from:
        t_flat = (taper_from - a) * kwh / kw * 3600.0
        if seconds <= t_flat:
            return a + seconds * kw / 3600.0 / kwh
        seconds -= t_flat
        a = taper_from
    k = (1.0 - floor) / (1.0 - taper_from)
    x = (1.0 - k * (a - taper_from)) * math.exp(-kw * k * seconds / 3600.0 / kwh)
    return min(1.0, taper_from + (1.0 - x) / k)


# ----------------------------------------------------------------------------- batteries


class Battery:
    """One vehicle's battery (kWh). ``now`` gives the simulated time (auxiliary draw is
    settled lazily: :meth:`settle`)."""

    __slots__ = ("cfg", "capacity", "kwh", "kwh0", "drawn", "charged", "charge_seconds",
                 "queue_seconds", "kwh_min", "t", "plugged", "now", "arr", "slot")

    def __init__(self, cfg: EnergyConfig, soc: float, now: Callable[[], float],
                 arr: np.ndarray, slot: int) -> None:
        self.cfg, self.capacity = cfg, cfg.battery_kwh
        self.kwh = self.kwh0 = self.kwh_min = soc * cfg.battery_kwh
        self.drawn = self.charged = self.charge_seconds = self.queue_seconds = 0.0
        self.t, self.plugged, self.now = 0.0, False, now
        self.arr, self.slot = arr, slot
        arr[slot] = self.kwh

    @property
    def soc(self) -> float:
        return self.kwh / self.capacity

    def _take(self, e: float) -> None:
        take = min(max(e, 0.0), self.kwh)
        self.kwh -= take
        self.drawn += take
        if self.kwh < self.kwh_min:
            self.kwh_min = self.kwh
        self.arr[self.slot] = self.kwh

    def settle(self) -> None:
        """Draw the auxiliary load up to now (nothing while plugged in)."""
        now = self.now()
        if now > self.t:
            if not self.plugged and self.cfg.idle_kwh_per_hour:
                self._take(self.cfg.idle_kwh_per_hour * (now - self.t) / 3600.0)
            self.t = now

    def leg_kwh(self, metres: float, seconds: float) -> float:
        """kWh a drive of ``metres`` in ``seconds`` draws (without the auxiliary load)."""
        speed = metres / seconds if seconds > 0 else 0.0
        return metres * self.cfg.wh_per_metre(speed) / 1000.0

    def drive(self, metres: float, seconds: float) -> None:
        self.settle()
        self._take(self.leg_kwh(metres, seconds))

    def runs_out(self, metres: float, seconds: float) -> float | None:
        """Seconds into a leg of ``metres`` in ``seconds`` at which the battery is empty, or
        None if it lasts the leg."""
        self.settle()
        aux = self.cfg.idle_kwh_per_hour * seconds / 3600.0
        need = self.leg_kwh(metres, seconds) + aux
        if need <= self.kwh + 1e-12:
            return None
        return seconds * self.kwh / need if need > 0 else 0.0

    def add(self, e: float) -> None:
        e = min(max(e, 0.0), self.capacity - self.kwh)
        self.kwh += e
        self.charged += e
        self.arr[self.slot] = self.kwh


class Energy:
    """The run's batteries and the dispatcher's reserve rule."""

    def __init__(self, cfg: EnergyConfig, fleet: Fleet, env: simpy.Environment,
                 ref_speed: float) -> None:
        self.cfg, self.fleet, self.env = cfg, fleet, env
        n = len(fleet)
        self.kwh = np.zeros(n)
        now = lambda: env.now  # noqa: E731
        for i, v in enumerate(fleet.vehicles):
            soc = cfg.socs[i] if i < len(cfg.socs) and cfg.socs[i] == cfg.socs[i] else cfg.soc0
            v.battery = Battery(cfg, soc, now, self.kwh, v._slot)
        #: kWh per second of driving at the reference speed (the network's mean free speed)
        self.kwh_per_second = cfg.wh_per_metre(ref_speed) * ref_speed / 1000.0
        self.reserve_kwh = cfg.reserve * cfg.battery_kwh

    def filter(self, cost: np.ndarray, drive: np.ndarray, slots: np.ndarray, tasks) -> np.ndarray:
        """``cost`` with ``inf`` where vehicle ``slots[i]`` would end below the reserve after
        the plan and request ``j`` (``drive``: seconds from each vehicle to each pickup)."""
        vs = self.fleet.vehicles
        plan_s = np.array([sum(s.leg for s in vs[k].stops) for k in slots.tolist()]) \
            if slots.size else np.zeros(0)
        direct = np.array([0.0 if t.dropoff is None or t.direct_time != t.direct_time
                           else t.direct_time for t in tasks])
        need = (plan_s[:, None] + drive + direct[None, :]) * self.kwh_per_second
        ok = self.kwh[slots][:, None] - need >= self.reserve_kwh
        return np.where(ok, cost, np.inf)

    def sampler(self, append: Callable[[tuple], None]):
        """Process: every ``sample`` seconds from 0, one ``soc`` row per vehicle."""
        ids = [v.id for v in self.fleet.vehicles]
        while True:
            self.settle_all()
            t = float(self.env.now)
            cap = self.cfg.battery_kwh
            for vid, k in zip(ids, (self.kwh / cap).tolist()):
                append((t, vid, k))
            yield self.env.timeout(self.cfg.sample)

    def settle_all(self) -> None:
        for v in self.fleet.vehicles:
            v.battery.settle()


# ----------------------------------------------------------------------------- stations


@dataclass(eq=False)
class Station:
    id: str
    index: int
    node: int
    plugs: int
    kw: float
    resource: simpy.Resource = field(repr=False)
    kwh: float = 0.0  # delivered
    busy_seconds: float = 0.0  # plug-seconds charging
    queue_seconds: float = 0.0  # vehicle-seconds queued
    visits: int = 0
    queued: int = 0  # visits that had to wait
    coming: int = 0  # vehicles driving to it on a visit

    @property
    def waiting(self) -> int:
        return len(self.resource.queue)

    @property
    def in_use(self) -> int:
        return self.resource.count


# ----------------------------------------------------------------------------- strategies


@dataclass(frozen=True, eq=False)
class ChargingView:
    """What a strategy sees (read-only arrays). Idle vehicles (row ``i``): ``vehicle_ids``,
    ``nodes`` (the node it stands on or reaches next), ``remaining`` (seconds to it),
    ``soc`` (0-1). Stations (row ``s``): ``station_ids``, ``station_nodes``, ``plugs``,
    ``in_use``, ``waiting`` (queued now), ``kw``. ``released_by_hour``: requests released in
    each hour of the run so far (index = hour since 0 s); ``time``; ``space`` (travel times:
    :meth:`travel_times`); ``battery_kwh``, ``reserve``; ``rng``."""

    time: float
    vehicle_ids: np.ndarray
    nodes: np.ndarray
    remaining: np.ndarray
    soc: np.ndarray
    station_ids: tuple[str, ...]
    station_nodes: np.ndarray
    plugs: np.ndarray
    in_use: np.ndarray
    waiting: np.ndarray
    kw: np.ndarray
    released_by_hour: np.ndarray
    battery_kwh: float
    reserve: float
    space: Any
    rng: np.random.Generator
    charge_seconds: Callable[[float, float, float], float] = field(repr=False)
    #: (stations, nodes) shortest drive seconds from every node to each station (None:
    #: computed on demand from ``space``)
    to_stations: np.ndarray | None = field(default=None, repr=False)
    #: vehicles driving to each station on a visit (None: none)
    coming: np.ndarray | None = None

    @property
    def n_vehicles(self) -> int:
        return int(self.vehicle_ids.size)

    def travel_times(self, rows=None) -> np.ndarray:
        """``(vehicles, stations)`` drive seconds from the idle vehicles ``rows`` (all if
        None) to every station."""
        rows = np.arange(self.n_vehicles) if rows is None else np.asarray(rows, np.int64)
        if rows.size == 0:
            return np.zeros((0, self.station_nodes.size))
        t = self.to_stations
        if t is None:
            t = self.space.distances_to(self.station_nodes)  # (stations, nodes)
        return t[:, self.nodes[rows]].T + self.remaining[rows][:, None]

    def queue_seconds(self, target: float = 0.8, extra=None) -> np.ndarray:
        """A rough wait at each station for a vehicle sent now: the vehicles ahead of it
        (charging, queueing, on their way, and ``extra`` more) beyond the plugs, times a mean
        charge (from 20 % to ``target``) divided by the plugs."""
        mean = np.array([self.charge_seconds(0.2, target, kw) for kw in self.kw.tolist()])
        ahead = self.in_use + self.waiting
        if self.coming is not None:
            ahead = ahead + self.coming
        if extra is not None:
            ahead = ahead + extra
        return np.maximum(ahead - self.plugs + 1, 0) * mean / self.plugs

    def best_station(self, rows, target: float = 0.8) -> np.ndarray:
        """For each vehicle of ``rows``, in that order, the station row of least drive + queue
        seconds, counting the vehicles sent before it in the queues (so that one call does not
        send every vehicle to the same station)."""
        rows = np.asarray(rows, np.int64)
        if rows.size == 0:
            return np.zeros(0, np.int64)
        t = self.travel_times(rows)
        extra = np.zeros(self.station_nodes.size, np.int64)
        mean = np.array([self.charge_seconds(0.2, target, kw) for kw in self.kw.tolist()])
        base = self.in_use + self.waiting + (0 if self.coming is None else self.coming)
        out = np.empty(rows.size, np.int64)
        for k in range(rows.size):
            q = np.maximum(base + extra - self.plugs + 1, 0) * mean / self.plugs
            s = int(np.argmin(t[k] + q))
            out[k] = s
            extra[s] += 1
        return out


class ChargingStrategy(ABC):
    """Base class of ``dispatch.chargers`` plugins.

    Every ``[charging] interval`` seconds the kernel hands :meth:`decide` a
    :class:`ChargingView` and it returns ``{vehicle id: (station id, target soc)}`` for idle
    vehicles to send charging now (target in (0, 1]). It must name only vehicles and stations
    of the view, must not mutate it, and draws randomness only from ``view.rng``. Constructor
    keyword arguments come from ``[charging.<name>]``; reject bad ones with ``TypeError`` /
    ``ValueError``."""

    name: ClassVar[str] = ""

    @abstractmethod
    def decide(self, view: ChargingView) -> Mapping[int, tuple[str, float]]:
        """The visits to start now."""


# ----------------------------------------------------------------------------- the kernel side


class Charging:
    """Stations, the strategy's timer, charging visits and strandings of one run."""

    def __init__(self, env: simpy.Environment, bus: EventBus, fleet: Fleet, operator: Operator,
                 energy: Energy, cfg: ChargingConfig, space, strategy: ChargingStrategy | None,
                 rng: np.random.Generator, transfer: bool, notify: Callable[[], None]) -> None:
        self.env, self.bus, self.fleet, self.op = env, bus, fleet, operator
        self.energy, self.cfg, self.space, self.strategy = energy, cfg, space, strategy
        self.rng, self.transfer, self.notify = rng, transfer, notify
        self.run_id = ""
        self.on_assign: Callable[[Vehicle], None] = lambda v: None
        ecfg = energy.cfg
        self.stations: list[Station] = []
        for k, row in enumerate(cfg.stations):
            if row.node is not None:
                node = space.index_of(_node_id(row.node))
            else:
                xy = space.lonlat_to_xy([row.lon], [row.lat])
                node = int(space.nearest(xy)[0][0])
            kw = min(row.kw, ecfg.max_charge_kw)
            self.stations.append(Station(row.station_id, k, int(node), row.plugs, kw,
                                         simpy.Resource(env, capacity=row.plugs)))
        self.by_id = {s.id: s for s in self.stations}
        #: (stations, nodes) drive seconds from each node to each station (static network)
        self.to_stations = (space.distances_to([s.node for s in self.stations])
                            if self.stations else np.zeros((0, space.n)))
        self.to_stations.setflags(write=False)
        self.hourly = np.zeros(1, np.int64)
        self.strandings = 0
        self.visits: dict[int, Any] = {}  # vehicle id -> its visit process
        #: vehicle id -> (station, since) queueing now / (station, soc at plug-in, target,
        #: since) plugged in now (closed by :meth:`finish` at the end of the run)
        self.queueing: dict[int, tuple] = {}
        self.plugged: dict[int, tuple] = {}
        bus.subscribe(self._released, ["release"])
        if strategy is not None and self.stations:
            env.process(self._loop())

    # ------------------------------------------------------------------ helpers
    def seconds(self, a: float, b: float, kw: float) -> float:
        c = self.cfg
        return charge_seconds(a, b, self.energy.cfg.battery_kwh, kw, c.taper_from, c.taper_floor)

    def _released(self, e) -> None:
        h = int(e.t // 3600)
        if h >= self.hourly.size:
            self.hourly = np.concatenate([self.hourly, np.zeros(h + 1 - self.hourly.size,
                                                               np.int64)])
        self.hourly[h] += 1

    def _loop(self):
        while True:
            yield self.env.timeout(self.cfg.interval)
            self.step()

    def view(self) -> ChargingView:
        now = self.env.now
        idle = [v for v in self.fleet.idle() if v.id not in self.visits]
        locs = [v.location(now) for v in idle]
        ro = _readonly
        st = self.stations
        return ChargingView(
            time=float(now), vehicle_ids=ro([v.id for v in idle], np.int64),
            nodes=ro([getattr(p, "node", p) for p in locs], np.int64),
            remaining=ro([max(getattr(p, "remaining", 0.0), 0.0) for p in locs], float),
            soc=ro([v.battery.soc for v in idle], float),
            station_ids=tuple(s.id for s in st), station_nodes=ro([s.node for s in st], np.int64),
            plugs=ro([s.plugs for s in st], np.int64), in_use=ro([s.in_use for s in st], np.int64),
            waiting=ro([s.waiting for s in st], np.int64), kw=ro([s.kw for s in st], float),
            coming=ro([s.coming for s in st], np.int64),
            released_by_hour=ro(self.hourly, np.int64),
            battery_kwh=self.energy.cfg.battery_kwh, reserve=self.energy.cfg.reserve,
            space=self.space, rng=self.rng, charge_seconds=self.seconds,
            to_stations=self.to_stations)

    def _fail(self, why: str) -> PluginError:
        name = getattr(self.strategy, "name", "") or type(self.strategy).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return PluginError(f"charging strategy {name!r}{run}, t = {self.env.now:.6g} s: {why}")

    def step(self) -> None:
        """Ask the strategy now and start the visits it returns (in vehicle id order)."""
        for v in self.fleet.idle():
            v.battery.settle()
        view = self.view()
        if not view.n_vehicles:
            return
        try:
            moves = self.strategy.decide(view)
        except PluginError:
            raise
        except Exception as e:  # noqa: BLE001 - a plugin may raise anything
            raise self._fail(f"decide() raised {type(e).__name__}: {e}") from e
        if not isinstance(moves, Mapping):
            raise self._fail(f"decide() must return a mapping, got {type(moves).__name__}")
        idle = set(view.vehicle_ids.tolist())
        for vid, what in sorted(moves.items()):
            try:
                sid, target = what
                target = float(target)
            except (TypeError, ValueError):
                raise self._fail(f"vehicle {vid!r}: want (station id, target soc), got "
                                 f"{what!r}") from None
            if vid not in idle:
                raise self._fail(f"vehicle {vid!r} is not an idle vehicle of the view")
            if sid not in self.by_id:
                raise self._fail(f"vehicle {vid}: unknown station {sid!r}")
            if not 0.0 < target <= 1.0:
                raise self._fail(f"vehicle {vid}: target soc {target!r} not in (0, 1]")
            self.send(self.fleet.by_id[int(vid)], self.by_id[sid], target)

    # ------------------------------------------------------------------ visits
    def send(self, v: Vehicle, station: Station, target: float) -> None:
        """Send the idle vehicle ``v`` charging at ``station`` up to ``target``."""
        self.on_assign(v)  # (a repositioning drive stops where it is)
        self.fleet.set_failed(v)  # neither idle nor busy: no decision sees it
        v.stops = [Stop(CHARGE, None, station.node, 0, math.inf, False)]
        self.op.changed(v)
        v.proc = self.env.process(self._visit(v, station, target))
        self.visits[v.id] = v.proc

    def _visit(self, v: Vehicle, station: Station, target: float):
        env, emit, bat = self.env, self.bus.emit, v.battery
        req = None
        t_q = t_c = None
        a = 0.0
        station.coming += 1
        coming = True
        try:
            if v.location(env.now) != station.node:
                leg = self.op.driver.plan(v, station.node, env.now)
                emit(env.now, "depart", v.id, -1, v.loc)
                cut = bat.runs_out(leg.length, leg.seconds)
                if cut is not None:
                    v.leg, v.leg_start = leg, env.now
                    yield env.timeout(cut)
                    from dispatch.vehicles import stop_leg

                    stop_leg(v, env.now)
                    self.visits.pop(v.id, None)
                    v.stops = []
                    station.coming -= 1
                    self.strand(v)
                    return
                yield from self.op.driver.drive(env, v, leg, -1)
            station.coming -= 1
            coming = False
            bat.settle()
            req = station.resource.request()
            station.visits += 1
            t_q = env.now
            if not req.triggered:
                station.queued += 1
                emit(env.now, "queue", v.id, -1, station.node)
            self.queueing[v.id] = (station, t_q)
            yield req
            del self.queueing[v.id]
            waited = env.now - t_q
            bat.queue_seconds += waited
            station.queue_seconds += waited
            t_q = None
            bat.settle()
            bat.plugged = True
            a = bat.soc
            dur = self.seconds(a, max(a, target), station.kw)
            t_c = env.now
            emit(env.now, "charge_start", v.id, -1, station.node)
            self.plugged[v.id] = (station, a, target, t_c)
            yield env.timeout(dur)
            del self.plugged[v.id]
            self._charged(v, station, a, target, env.now - t_c, exact=True)
            t_c = None
            station.resource.release(req)
            req = None
            emit(env.now, "charge_end", v.id, -1, station.node)
        except simpy.Interrupt:  # a breakdown: it has put the vehicle right
            self.queueing.pop(v.id, None)
            self.plugged.pop(v.id, None)
            if coming:
                station.coming -= 1
            if t_q is not None:
                waited = env.now - t_q
                bat.queue_seconds += waited
                station.queue_seconds += waited
            if t_c is not None:
                self._charged(v, station, a, target, env.now - t_c, exact=False)
                emit(env.now, "charge_end", v.id, -1, station.node)
            if req is not None:
                if req.triggered:
                    station.resource.release(req)
                else:
                    req.cancel()
            self.visits.pop(v.id, None)
            return
        self.visits.pop(v.id, None)
        v.stops, v.proc = [], None
        self.op.changed(v)
        self.fleet.set_idle(v)
        emit(env.now, "idle", v.id, -1, v.loc)
        self.notify()

    def _charged(self, v: Vehicle, station: Station, a: float, target: float, seconds: float,
                 exact: bool) -> None:
        bat, c = v.battery, self.cfg
        b = max(a, target) if exact else soc_after(a, seconds, bat.capacity, station.kw,
                                                   c.taper_from, c.taper_floor)
        before = bat.kwh
        bat.add(b * bat.capacity - bat.kwh)
        station.kwh += bat.kwh - before
        station.busy_seconds += seconds
        bat.charge_seconds += seconds
        bat.plugged = False
        bat.t = self.env.now

    def finish(self) -> None:
        """The run ends: what the vehicles still plugged in have charged so far counts (and
        their plug time), and the seconds the ones queueing have waited."""
        now = self.env.now
        fleet = self.fleet.by_id
        for vid, (station, since) in sorted(self.queueing.items()):
            fleet[vid].battery.queue_seconds += now - since
            station.queue_seconds += now - since
        for vid, (station, a, target, since) in sorted(self.plugged.items()):
            self._charged(fleet[vid], station, a, target, now - since, exact=False)
        self.queueing.clear()
        self.plugged.clear()

    # ------------------------------------------------------------------ strandings
    def nearest_station(self, node: int) -> Station | None:
        if not self.stations:
            return None
        t = self.to_stations[:, node]
        return self.stations[int(np.argmin(t))]

    def strand(self, v: Vehicle) -> None:
        """``v``'s battery is empty where it stands: a ``stranded`` event, a breakdown (its
        trips transferred or failed as ``[faults] on_board`` says) that lasts ``[faults] tow``
        seconds, after which it stands at the nearest station (idle; a strategy charges it)."""
        env = self.env
        self.strandings += 1
        self.bus.emit(env.now, "stranded", v.id, -1, v.loc)
        self.op.breakdown(v, math.inf, self.transfer)
        env.process(self._tow(v))

    def _tow(self, v: Vehicle):
        yield self.env.timeout(self.cfg.tow)
        node = getattr(v.loc, "node", v.loc)
        s = self.nearest_station(int(node))
        if s is not None:
            v.loc = s.node
        v.battery.settle()
        v.failed = False
        v.down_seconds += self.env.now - v.down_since
        self.fleet.set_idle(v)
        self.bus.emit(self.env.now, "repair", v.id, -1, v.loc)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()

    def rows(self):
        """The ``chargers`` table's rows (dicts)."""
        dur = max(float(self.env.now), 1e-9)
        for s in self.stations:
            yield dict(station_id=s.id, node=s.node, plugs=s.plugs, kw=s.kw, kwh_delivered=s.kwh,
                       busy_plug_hours=s.busy_seconds / 3600.0, visits=s.visits,
                       queued_visits=s.queued, queue_seconds=s.queue_seconds,
                       mean_queue=s.queue_seconds / dur)


def _node_id(x):
    try:
        f = float(x)
        return int(f) if f == int(f) else x
    except (TypeError, ValueError):
        return x


def _readonly(a, dtype) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a
