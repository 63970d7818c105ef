"""Earliest-arrival routing over a :class:`~dispatch.space.transit.Timetable` by the Connection
Scan Algorithm (Dibbelt, Pajor, Strasser and Wagner, "Connection Scan Algorithm", 2018),
compiled by numba like the kernel's other loops.

A query gives where a rider can be and from when (``sources``: stations and the times they are
ready there, e.g. after walking from their door) and, optionally, what each station is worth
as an end (``egress``: seconds from the station to the rider's goal). One scan of the day's
connections in departure order answers, for every station, the earliest arrival (by a train,
or by a footpath to another station after one; a source station counts as reached at its
ready time) and, with ``egress``, stops once no connection
can still improve the best ``arrival + egress``. :meth:`Arrivals.journey` rebuilds the legs
that reach a station: train legs (a trip boarded at one station and left at a later one) and
the walks between them (changes inside a station are no leg: the rider waits there).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dispatch._compiled import kernel
from dispatch.space.transit import Timetable


@kernel(interpret=False)  # (compiled at the first scan: numba is not imported with the module)
def _scan(tt_dep, tt_arr, frm, to, trip, fp_ptr, fp_to, fp_dur, ready0, egress, n_trips,
          start, horizon):  # pragma: no cover - compiled
    """The scan: from connection ``start`` on, in order, while departures are at most
    ``horizon`` and below the best ``arrival + egress``. Returns per station the earliest
    arrival and the (exit, entry) connections of the train that gave it (-1: a source; the
    exit connection arrives elsewhere when the rider walked on from there), and the ready
    time and the (exit, entry) connections of the footpath that gave it."""
    n = ready0.size
    ready = ready0.copy()
    arrive = ready0.copy()
    train = np.full(n, np.inf)
    exit_c = np.full(n, -1, np.int64)
    enter_c = np.full(n, -1, np.int64)
    r_exit = np.full(n, -1, np.int64)
    r_enter = np.full(n, -1, np.int64)
    t_enter = np.full(n_trips, -1, np.int64)
    best = np.inf
    for s in range(n):
        best = min(best, arrive[s] + egress[s])
    for c in range(start, tt_dep.size):
        d = tt_dep[c]
        if d >= best or d > horizon:
            break
        t = trip[c]
        if t_enter[t] < 0:
            if ready[frm[c]] > d:
                continue
            t_enter[t] = c
        v = to[c]
        a = tt_arr[c]
        if a < train[v]:
            train[v] = a
            if a < arrive[v]:
                arrive[v] = a
                exit_c[v] = c
                enter_c[v] = t_enter[t]
                best = min(best, a + egress[v])
            for k in range(fp_ptr[v], fp_ptr[v + 1]):
                w = fp_to[k]
                r = a + fp_dur[k]
                if r < ready[w]:
                    ready[w] = r
                    r_exit[w] = c
                    r_enter[w] = t_enter[t]
                if w != v and r < arrive[w]:  # a walk to another station reaches it too
                    arrive[w] = r
                    exit_c[w] = c
                    enter_c[w] = t_enter[t]
                    best = min(best, r + egress[w])
    return arrive, exit_c, enter_c, ready, r_exit, r_enter


@dataclass(frozen=True)
class TransitLeg:
    """One leg of a transit journey: ``mode`` ``"train"`` (``trip_id`` boarded at
    ``from_stop`` at its departure ``start``, left at ``to_stop`` at its arrival ``end``) or
    ``"walk"`` (between two stations, from arriving at ``from_stop`` to being ready to board
    at ``to_stop``). Stops are the feed's station ids; times seconds on the service day's
    clock. ``trip``: the row of the feed's trips (-1 for a walk), which tells a trip of the
    day before still running after midnight from the day's own of the same ``trip_id``
    (:attr:`dispatch.files.gtfs.Feed.trip_day`); not compared."""

    mode: str
    from_stop: str
    to_stop: str
    start: float
    end: float
    trip_id: str | None = None
    route_id: str | None = None
    trip: int = field(default=-1, compare=False)


@dataclass(frozen=True, eq=False)
class Arrivals:
    """The answer of one query: ``arrival`` per station (inf: not reached) and what rebuilds
    the journeys (:meth:`journey`)."""

    tt: Timetable
    arrival: np.ndarray
    exit_c: np.ndarray
    enter_c: np.ndarray
    ready: np.ndarray
    r_exit: np.ndarray
    r_enter: np.ndarray

    def best(self, egress: np.ndarray) -> tuple[int, float]:
        """The station that minimises ``arrival + egress`` and that sum (-1, inf: none)."""
        total = self.arrival + np.asarray(egress, np.float64)
        s = int(np.argmin(total))
        return (s, float(total[s])) if np.isfinite(total[s]) else (-1, float("inf"))

    def journey(self, station: int) -> list[TransitLeg]:
        """The legs, in time order, that reach ``station`` at ``arrival[station]`` (empty: a
        source reached on foot or not at all)."""
        tt = self.tt
        legs: list[TransitLeg] = []
        c, e = int(self.exit_c[station]), int(self.enter_c[station])
        if c >= 0 and int(tt.to[c]) != station:  # walked on from the train's station
            legs.append(TransitLeg("walk", str(tt.station_ids[tt.to[c]]),
                                   str(tt.station_ids[station]), float(tt.arr[c]),
                                   float(self.arrival[station])))
        while c >= 0:
            t = int(tt.trip[c])
            legs.append(TransitLeg("train", str(tt.station_ids[tt.frm[e]]),
                                   str(tt.station_ids[tt.to[c]]), float(tt.dep[e]),
                                   float(tt.arr[c]), str(tt.feed.trip_ids[t]),
                                   str(tt.feed.route_ids[tt.feed.trip_route[t]]), t))
            u = int(tt.frm[e])
            c, e = int(self.r_exit[u]), int(self.r_enter[u])
            if c >= 0 and int(tt.to[c]) != u:
                legs.append(TransitLeg("walk", str(tt.station_ids[tt.to[c]]),
                                       str(tt.station_ids[u]), float(tt.arr[c]),
                                       float(self.ready[u])))
        return legs[::-1]


def earliest_arrivals(tt: Timetable, sources: dict[int, float], *,
                      egress: np.ndarray | None = None,
                      horizon: float = float("inf")) -> Arrivals:
    """Earliest arrivals at every station from ``sources`` (``{station: ready time}``, seconds
    on the service day's clock), over connections leaving at most at ``horizon``; with
    ``egress`` (per station, seconds to the goal; inf: not an end) the scan stops once no
    connection can improve the best ``arrival + egress`` (arrivals at other stations are then
    only upper bounds)."""
    n = tt.n_stations
    ready0 = np.full(n, np.inf)
    for s, t in sources.items():
        if not 0 <= s < n:
            raise ValueError(f"source station {s} is not one of the timetable's {n}")
        ready0[s] = min(ready0[s], float(t))
    eg = np.full(n, np.inf) if egress is None else np.asarray(egress, np.float64)
    if eg.shape != (n,):
        raise ValueError(f"egress must hold one value per station ({n}), not {eg.shape}")
    start = int(np.searchsorted(tt.dep, ready0.min(), side="left")) if sources else tt.dep.size
    out = _scan(tt.dep, tt.arr, tt.frm, tt.to, tt.trip, tt.fp_ptr, tt.fp_to, tt.fp_dur, ready0,
                eg, int(tt.feed.trip_ids.size), start, float(horizon))
    return Arrivals(tt, *out)
