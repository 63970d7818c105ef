"""Chargers as shared resources and charging visits (``[chargers]``, ``[charging]``).

Chargers (``[chargers]``)
    Stations from a CSV file (``station_id``, ``node`` or ``lon``/``lat``, ``plugs``, ``kw``);
    each is a ``simpy.Resource`` with one slot per plug: vehicles queue in SimPy's order.
    Power is ``min(station kw, [fleet.energy] max_charge_kw)`` up to ``taper_from`` (state of
    charge), then falls linearly to ``taper_floor`` of it at full (:func:`charge_seconds`).

A charging visit is a charge stop of the vehicle's plan (:data:`dispatch.plan.stops.CHARGE`, no
task; its :class:`Visit`), driven by the operator like any stop
(:meth:`dispatch.plan.operator.Operator.charge`): the vehicle drives to the station, queues
(``queue`` event), charges (``charge_start``, ``charge_end``) to the strategy's target and is
idle again. While on a visit it is neither idle nor busy: no decision considers it. A breakdown
ends the visit (the energy charged so far counts). Strategies (``dispatch.chargers`` plugins,
:class:`dispatch.api.charger.ChargingStrategy`) decide which idle vehicles go where, every
``[charging] interval`` seconds. A vehicle whose battery runs empty is *stranded* and towed to
the nearest station (:meth:`dispatch.plan.breakdowns.Breakdowns.strand`,
:meth:`Stations.nearest_node`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import simpy

from dispatch.api.charger import ChargingStrategy, ChargingView
from dispatch.api.legs import as_point
from dispatch.config.energy import ChargingConfig
from dispatch.errors import PluginError
from dispatch.fleet.battery import Energy

if TYPE_CHECKING:
    from dispatch.events import EventBus
    from dispatch.plan.operator import Operator
    from dispatch.plan.vehicles import Fleet, Vehicle


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


class Stations:
    """The run's stations (``[chargers]``) on the road network ``space``, each power capped at
    ``max_kw`` (``[fleet.energy] max_charge_kw``), and the drive seconds to each."""

    def __init__(self, env: simpy.Environment, cfg: ChargingConfig, space,
                 max_kw: float) -> None:
        self.env = env
        self.stations: list[Station] = []
        for k, row in enumerate(cfg.stations):
            if row.node is not None:
                node = space.index_of(_node_id(row.node))
            else:
                xy = space.lonlat_to_xy([row.lon], [row.lat])
                node = int(space.nearest(xy)[0][0])
            kw = min(row.kw, max_kw)
            self.stations.append(Station(row.station_id, k, int(node), row.plugs, kw,
                                         simpy.Resource(env, capacity=row.plugs)))
        self.by_id = {s.id: s for s in self.stations}
        #: (stations, nodes) drive seconds from each node to each station (static network)
        self.to_stations = (space.distances_to([s.node for s in self.stations])
                            if self.stations else np.zeros((0, space.n)))
        self.to_stations.setflags(write=False)

    def nearest(self, node: int) -> Station | None:
        """The station of least drive seconds from ``node`` (None: there is none)."""
        if not self.stations:
            return None
        t = self.to_stations[:, node]
        return self.stations[int(np.argmin(t))]

    def nearest_node(self, node: int) -> int | None:
        """Where a vehicle stranded at ``node`` is towed: the nearest station's node (None:
        there is no station; it stays)."""
        s = self.nearest(int(node))
        return None if s is None else s.node

    def rows(self):
        """The ``chargers`` table's rows (dicts)."""
        dur = max(float(self.env.now), 1e-9)
        for s in self.stations:
            yield dict(station_id=s.id, node=s.node, plugs=s.plugs, kw=s.kw, kwh_delivered=s.kwh,
                       busy_plug_hours=s.busy_seconds / 3600.0, visits=s.visits,
                       queued_visits=s.queued, queue_seconds=s.queue_seconds,
                       mean_queue=s.queue_seconds / dur)


# ----------------------------------------------------------------------------- visits


@dataclass(eq=False)
class Visit:
    """One charging visit (a charge stop's ``visit``): to ``station``, up to ``target`` state
    of charge. The station counts it as *coming* from when it is made until the vehicle
    reaches the station or its drive there ends otherwise (:meth:`reached`)."""

    charging: Charging
    station: Station
    target: float

    def __post_init__(self) -> None:
        self.station.coming += 1

    def reached(self) -> None:
        """The drive to the station is over (arrived, or cut by a breakdown or an empty
        battery)."""
        self.station.coming -= 1

    def serve(self, v: Vehicle):
        """Process fragment: ``v`` at the station queues for a plug, charges to the target and
        leaves. A breakdown (an interrupt) closes the visit (the seconds queued, the energy
        charged so far and the plug count) and goes on to the caller."""
        c, station = self.charging, self.station
        env, emit, bat, target = c.env, c.bus.emit, v.battery, self.target
        t_c = None
        a = 0.0
        bat.settle()
        req = station.resource.request()
        station.visits += 1
        t_q = env.now
        try:
            if not req.triggered:
                station.queued += 1
                emit(env.now, "queue", v.id, -1, station.node)
            c.queueing[v.id] = (station, t_q)
            yield req
            del c.queueing[v.id]
            waited = env.now - t_q
            bat.queue_seconds += waited
            station.queue_seconds += waited
            t_q = None
            bat.settle()
            bat.plugged = True
            a = bat.soc
            dur = c.seconds(a, max(a, target), station.kw)
            t_c = env.now
            emit(env.now, "charge_start", v.id, -1, station.node)
            c.plugged[v.id] = (station, a, target, t_c)
            yield env.timeout(dur)
            del c.plugged[v.id]
            c.charged(v, station, a, target, env.now - t_c, exact=True)
            t_c = None
            station.resource.release(req)
            req = None
            emit(env.now, "charge_end", v.id, -1, station.node)
        except simpy.Interrupt:  # a breakdown: the operator has put the vehicle right
            c.queueing.pop(v.id, None)
            c.plugged.pop(v.id, None)
            if t_q is not None:
                waited = env.now - t_q
                bat.queue_seconds += waited
                station.queue_seconds += waited
            if t_c is not None:
                c.charged(v, station, a, target, env.now - t_c, exact=False)
                emit(env.now, "charge_end", v.id, -1, station.node)
            if req is not None:
                if req.triggered:
                    station.resource.release(req)
                else:
                    req.cancel()
            raise


# ----------------------------------------------------------------------------- the strategy's side


class Charging:
    """The charging strategy's timer and the visits it starts, on the run's ``stations``."""

    def __init__(self, env: simpy.Environment, bus: EventBus, fleet: Fleet, operator: Operator,
                 energy: Energy, cfg: ChargingConfig, *, stations: Stations, space,
                 strategy: ChargingStrategy | None, rng: np.random.Generator,
                 run_id: str = "") -> None:
        self.env, self.bus, self.fleet, self.op = env, bus, fleet, operator
        self.energy, self.cfg, self.space, self.strategy = energy, cfg, space, strategy
        self.rng, self.run_id = rng, run_id
        self.stations, self.by_id = stations.stations, stations.by_id
        self.to_stations = stations.to_stations
        self.hourly = np.zeros(1, np.int64)
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
        idle = self.fleet.idle()
        locs = [as_point(v.location(now)) for v in idle]
        ro = _readonly
        st = self.stations
        return ChargingView(
            time=float(now), vehicle_ids=ro([v.id for v in idle], np.int64),
            nodes=ro([p.node for p in locs], np.int64),
            remaining=ro([max(p.remaining, 0.0) for p in locs], float),
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
        name = self.strategy.name or type(self.strategy).__name__
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
        """Send the idle vehicle ``v`` charging at ``station`` up to ``target``: the operator
        drives the visit as its plan's charge stop."""
        self.op.charge(v, Visit(self, station, target))

    def charged(self, v: Vehicle, station: Station, a: float, target: float, seconds: float,
                exact: bool) -> None:
        """``v`` charged ``seconds`` at ``station`` from state of charge ``a``: to ``target``
        (``exact``), or as far as the curve got in that time; it is unplugged now."""
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
            self.charged(fleet[vid], station, a, target, now - since, exact=False)
        self.queueing.clear()
        self.plugged.clear()


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
