"""Chargers as shared resources and charging visits (``[chargers]``, ``[charging]``).

Chargers (``[chargers]``)
    Stations from a CSV file (``station_id``, ``node`` or ``lon``/``lat``, ``plugs``, ``kw``);
    each is a ``simpy.Resource`` with one slot per plug: vehicles queue in SimPy's order.
    Power is ``min(station kw, [fleet.energy] max_charge_kw)`` up to ``taper_from`` (state of
    charge), then falls linearly to ``taper_floor`` of it at full (:func:`charge_seconds`).

A charging visit is a ``charge`` stop of the vehicle's stop list (:data:`CHARGE`, no task):
the vehicle drives to the station, queues (``queue`` event), charges (``charge_start``,
``charge_end``) to the strategy's target and is idle again. While on a visit it is neither
idle nor busy: no decision considers it. A breakdown ends the visit (the energy charged so far
counts). Strategies (``dispatch.chargers`` plugins,
:class:`dispatch.charging_strategy.ChargingStrategy`) decide which idle vehicles go where, every
``[charging] interval`` seconds. A vehicle whose battery runs empty is *stranded*
(:meth:`Charging.strand`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import simpy

from dispatch.battery import Energy
from dispatch.charging_strategy import ChargingStrategy, ChargingView
from dispatch.energy_config import ChargingConfig
from dispatch.errors import PluginError
from dispatch.stops import Stop

if TYPE_CHECKING:
    from dispatch.events import EventBus
    from dispatch.vehicles import Fleet, Operator, Vehicle

CHARGE = "charge"


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
