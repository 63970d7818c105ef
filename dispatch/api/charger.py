"""The contract of charging strategies (``dispatch.chargers`` plugins): what a strategy sees
(:class:`ChargingView`) and what it answers (:class:`ChargingStrategy`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np


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
