"""A public-transport timetable of one service day, ready for routing: its stations, its
connections and the footpaths between stations (:class:`Timetable`, made from a
:class:`~dispatch.files.gtfs.Feed`); :mod:`dispatch.space.csa` routes over it.

The model the router answers in (and its tests check against):

* **stations**: each stop a trip calls at stands for its ``parent_station`` where it has one,
  else for itself (so a rider changes platforms inside a station by its change time, and
  ``transfers.txt`` rows between platforms or between stations mean the same);
* **connections**: a trip's ride from one call to the next, leaving at the first call's
  departure and arriving at the next call's arrival (a rider stays aboard through calls);
* **footpaths** ``a -> b``, ``d`` seconds, taken after arriving by train at ``a`` (once:
  footpaths do not chain): the change inside a station (``a == b``: ``transfers.txt``'s
  ``min_transfer_time`` for the station, else ``min_change``); a ``transfers.txt`` row
  between two stations (its ``min_transfer_time``, else the walk); every other pair of
  stations at most ``walk_radius`` metres apart in a straight line, at ``walk_speed``. Each is
  at least one second (so a change never makes a rider ready at the instant the train they
  left arrives, which keeps the scan's order exact). A footpath makes the rider ready to
  board at ``b`` at its end; one to another station (``a != b``) also reaches ``b`` then.

Positions are metres on a local flat frame of the stops (equirectangular about their mean
latitude: under 0.1 % off at a city's scale), so footpaths need no road network;
:meth:`Timetable.snap` places the stations on one (the nearest node and its distance).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from dispatch.files.gtfs import Feed

log = logging.getLogger(__name__)

EARTH_RADIUS = 6371008.8  # metres, the mean radius


def local_xy(lon: np.ndarray, lat: np.ndarray, lat0: float, lon0: float) -> np.ndarray:
    """``(k, 2)`` metres east and north of ``(lon0, lat0)`` on the equirectangular frame."""
    k = math.pi / 180 * EARTH_RADIUS
    return np.column_stack([(np.asarray(lon, np.float64) - lon0) * k * math.cos(
        math.radians(lat0)), (np.asarray(lat, np.float64) - lat0) * k])


@dataclass(frozen=True, eq=False)
class Timetable:
    """Stations, connections and footpaths of one service day (module docstring).

    ``station_stop``: per station (a node of the router), its row of the feed's stops;
    ``stop_station``: per row of the feed's stops, the station it stands for (-1: none);
    ``lonlat`` / ``xy``: its place (degrees; metres on the local frame). Connections, sorted
    by departure (then arrival, trip, call): ``dep`` / ``arr`` (seconds on the service day's
    clock), ``frm`` / ``to`` (stations), ``trip`` (a row of the feed's trips), ``call`` (the
    feed's call row of the departure). Footpaths in CSR form by their first station:
    ``fp_ptr``, ``fp_to``, ``fp_dur`` (seconds)."""

    feed: Feed
    station_stop: np.ndarray
    stop_station: np.ndarray
    lonlat: np.ndarray
    xy: np.ndarray
    dep: np.ndarray
    arr: np.ndarray
    frm: np.ndarray
    to: np.ndarray
    trip: np.ndarray
    call: np.ndarray
    fp_ptr: np.ndarray
    fp_to: np.ndarray
    fp_dur: np.ndarray
    walk_speed: float
    walk_radius: float
    min_change: float

    @classmethod
    def from_feed(cls, feed: Feed, *, walk_speed: float = 1.3, walk_radius: float = 300.0,
                  min_change: float = 60.0) -> Timetable:
        """The timetable of ``feed``: footpaths within ``walk_radius`` metres at
        ``walk_speed`` m/s, ``min_change`` seconds to change trains in a station that
        ``transfers.txt`` gives no time for."""
        if not walk_speed > 0 or not walk_radius >= 0 or not min_change >= 0:
            raise ValueError(f"walk_speed must be > 0, walk_radius and min_change >= 0 (got "
                             f"{walk_speed}, {walk_radius}, {min_change})")
        parent = feed.stop_parent
        station_of_stop = np.where(parent >= 0, parent, np.arange(parent.size))
        used = np.unique(station_of_stop[feed.call_stop])
        node = np.full(parent.size, -1, dtype=np.int64)
        node[used] = np.arange(used.size)
        lon, lat = feed.stop_lon[used].copy(), feed.stop_lat[used].copy()
        # a station without a place of its own takes the place of one of its platforms
        first = np.full(used.size, -1, dtype=np.int64)
        for s in np.flatnonzero(node[station_of_stop] >= 0)[::-1]:
            first[node[station_of_stop[s]]] = s
        gap = np.isnan(lon) | np.isnan(lat)
        lon[gap], lat[gap] = feed.stop_lon[first[gap]], feed.stop_lat[first[gap]]
        if np.isnan(lon).any() or np.isnan(lat).any():
            bad = feed.stop_ids[used[np.flatnonzero(np.isnan(lon) | np.isnan(lat))[0]]]
            raise ValueError(f"{feed.source}: stops.txt: stop {bad!r} is called at but has no "
                             "stop_lat / stop_lon")
        xy = local_xy(lon, lat, float(lat.mean()), float(lon.mean()))
        stop_node = node[station_of_stop]
        # connections: consecutive calls of one trip (calls are sorted by trip, sequence)
        i = np.flatnonzero(feed.call_trip[1:] == feed.call_trip[:-1])
        dep, arr = feed.call_departure[i], feed.call_arrival[i + 1]
        frm, to = stop_node[feed.call_stop[i]], stop_node[feed.call_stop[i + 1]]
        trip = feed.call_trip[i]
        order = np.lexsort((i, trip, arr, dep))
        fp = _footpaths(feed, stop_node, xy, walk_speed=walk_speed, walk_radius=walk_radius,
                        min_change=min_change)
        tt = cls(feed=feed, station_stop=used, stop_station=stop_node, lonlat=np.column_stack([lon, lat]), xy=xy,
                 dep=dep[order].astype(np.float64), arr=arr[order].astype(np.float64),
                 frm=frm[order], to=to[order], trip=trip[order].astype(np.int64),
                 call=i[order].astype(np.int64), fp_ptr=fp[0], fp_to=fp[1], fp_dur=fp[2],
                 walk_speed=float(walk_speed), walk_radius=float(walk_radius),
                 min_change=float(min_change))
        log.info("%r", tt)
        return tt

    @property
    def n_stations(self) -> int:
        return int(self.station_stop.size)

    @cached_property
    def station_ids(self) -> np.ndarray:
        """Per station, the feed's stop id it stands for."""
        return self.feed.stop_ids[self.station_stop]

    @cached_property
    def _by_id(self) -> dict[str, int]:
        return {str(sid): int(node) for sid, node in zip(self.feed.stop_ids, self.stop_station)
                if node >= 0}

    def station(self, stop_id: str) -> int:
        """The station a stop id of the feed (a station's or a platform's) stands for;
        KeyError, naming the feed, for an id of no station a trip calls at."""
        try:
            return self._by_id[str(stop_id)]
        except KeyError:
            raise KeyError(f"{self.feed.source}: stop {stop_id!r} is no station a trip of "
                           f"{self.feed.service_date} calls at") from None

    def near(self, lon: float, lat: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Stations within ``radius`` metres (straight line) of a point, nearest first, and
        their distances."""
        p = local_xy(np.array([lon]), np.array([lat]), *self._frame)[0]
        d = np.hypot(self.xy[:, 0] - p[0], self.xy[:, 1] - p[1])
        idx = np.flatnonzero(d <= radius)
        idx = idx[np.argsort(d[idx], kind="stable")]
        return idx, d[idx]

    @cached_property
    def _frame(self) -> tuple[float, float]:
        return float(self.lonlat[:, 1].mean()), float(self.lonlat[:, 0].mean())

    def snap(self, network) -> tuple[np.ndarray, np.ndarray]:
        """Per station, the nearest node of a road network (a
        :class:`~dispatch.space.roads.RoadNetwork` with a CRS) and the straight-line metres
        from the station to it: the walk between the station and the street a vehicle
        stops at."""
        xy = network.lonlat_to_xy(self.lonlat[:, 0], self.lonlat[:, 1])
        return network.nearest(xy)

    def __repr__(self) -> str:
        return (f"Timetable({self.feed.source!r}, {self.feed.service_date}: "
                f"{self.n_stations} stations, {self.dep.size} connections, "
                f"{self.fp_to.size} footpaths)")


def _footpaths(feed: Feed, stop_node: np.ndarray, xy: np.ndarray, *, walk_speed: float,
               walk_radius: float, min_change: float):
    """``(ptr, to, seconds)``: the footpaths of the module docstring in CSR form."""
    from scipy.spatial import cKDTree

    n = xy.shape[0]
    parts = []  # (from, to, seconds, rank): rank 0 = transfers.txt, 1 = a walk or a change
    a, b = stop_node[feed.transfer_from], stop_node[feed.transfer_to]
    ok = (a >= 0) & (b >= 0)
    a, b, secs = a[ok], b[ok], feed.transfer_seconds[ok]
    walk = np.hypot(*(xy[a] - xy[b]).T) / walk_speed
    secs = np.where(np.isnan(secs), np.where(a == b, min_change, np.ceil(walk)), secs)
    parts.append((a, b, secs, np.zeros(a.size)))
    pairs = cKDTree(xy).query_pairs(walk_radius, output_type="ndarray").reshape(-1, 2)
    u = np.concatenate([pairs[:, 0], pairs[:, 1]])
    v = np.concatenate([pairs[:, 1], pairs[:, 0]])
    parts.append((u, v, np.ceil(np.hypot(*(xy[u] - xy[v]).T) / walk_speed), np.ones(u.size)))
    own = np.arange(n)
    parts.append((own, own, np.full(n, float(min_change)), np.ones(n)))
    f, t, s, rank = (np.concatenate(x) for x in zip(*parts))
    order = np.lexsort((s, rank, t, f))
    f, t, s = f[order], t[order], s[order]
    first = np.r_[True, (f[1:] != f[:-1]) | (t[1:] != t[:-1])]
    f, t, s = f[first], t[first], np.maximum(s[first], 1.0)
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, f + 1, 1)
    return np.cumsum(ptr), t.astype(np.int64), s.astype(np.float64)
