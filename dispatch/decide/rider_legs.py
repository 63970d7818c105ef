"""A run's public transport as its riders use it (:class:`Transit`): the ``[transit]`` feed's
timetable placed on the run's road network and on the simulation's clock, and the legs of a
rider's trip (:class:`Leg`, one row of the ``legs`` table each).

Clocks: the timetable counts seconds of its service day (``[transit] service_date``); the
simulation counts seconds from ``[tasks] start``. Second 0 of a run is the time of day of
``[tasks] start`` on the service day (midnight without a start), whatever the start's date: a
trace of another day (NYC's Sunday 2014-12-21) is shifted onto the feed's day that way.

Places: a rider's door and goal are their request's street nodes; a station is placed on the
network by its coordinates (its ``from_x`` / ``to_x`` in the legs table) and is reached from the
street by the walk between it and its nearest node
(:meth:`~dispatch.space.transit.Timetable.snap`), which is where a feeder vehicle stops.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from dispatch.api.mode_choice import Option
from dispatch.config.transit import TransitConfig
from dispatch.files.gtfs import load_feed
from dispatch.space.csa import TransitLeg
from dispatch.space.journeys import Journey, Part, access, best_journey, rider_options
from dispatch.space.transit import Timetable

#: the columns of a leg's row, in order (the ``legs`` table's, ``run_id`` aside)
LEG_COLUMNS = ("request_id", "leg", "mode", "start", "end", "from_x", "from_y", "to_x", "to_y",
               "from_stop_id", "to_stop_id", "route_id", "trip_id", "agent_id")


@dataclass(frozen=True, slots=True)
class Leg:
    """One leg of a rider's trip on the simulation's clock: ``mode`` ``fleet`` (from boarding
    to getting off a vehicle, ``agent_id``), ``train`` (``trip_id`` of ``route_id`` from its
    departure at ``from_stop`` to its arrival at ``to_stop``) or ``walk``; ``frm`` / ``to``:
    metres on the road network's frame. Stop ids are the feed's station ids (None: a street
    node)."""

    mode: str
    start: float
    end: float
    frm: tuple[float, float]
    to: tuple[float, float]
    from_stop: str | None = None
    to_stop: str | None = None
    route_id: str | None = None
    trip_id: str | None = None
    agent_id: int | None = None

    def row(self, request_id, k: int) -> tuple:
        """The ``legs`` row of this leg as leg ``k`` of ``request_id``'s trip
        (:data:`LEG_COLUMNS`)."""
        return (request_id, k, self.mode, self.start, self.end, self.frm[0], self.frm[1],
                self.to[0], self.to[1], self.from_stop, self.to_stop, self.route_id,
                self.trip_id, self.agent_id)


@functools.lru_cache(maxsize=2)
def _timetable(path, date, walk_speed: float, walk_radius: float,
               min_change: float) -> Timetable:
    """The timetable of a feed's day, built once per process for each set of walking rules
    (a sweep's runs share it)."""
    return Timetable.from_feed(load_feed(path, date), walk_speed=walk_speed,
                               walk_radius=walk_radius, min_change=min_change)


def seconds_of_day(start) -> float:
    """The service day's second at the run's second 0: ``[tasks] start``'s time of day (0
    without a start)."""
    if start is None:
        return 0.0
    return float(start.hour * 3600 + start.minute * 60 + start.second)


class Transit:
    """The ``[transit]`` timetable of a run on its road network (``network``: a
    :class:`~dispatch.space.roads.RoadNetwork` with a CRS), its service day's second ``offset``
    at the run's second 0."""

    def __init__(self, cfg: TransitConfig, network, offset: float) -> None:
        self.cfg, self.offset = cfg, float(offset)
        self.tt = tt = _timetable(cfg.feed_path, cfg.service_date, cfg.walk_speed,
                                  cfg.transfer_walk, cfg.min_change)
        self.snapped = tt.snap(network)  # per station: its street node, metres to it
        self.station_xy = network.lonlat_to_xy(tt.lonlat[:, 0], tt.lonlat[:, 1])
        self.node_xy = np.asarray(network.xy, np.float64)[:, :2]
        self.node_lonlat = _lonlat(network)

    # ------------------------------------------------------------------ places
    def door(self, node: int) -> tuple[float, float]:
        x, y = self.node_xy[node]
        return float(x), float(y)

    def at(self, stop_id: str) -> tuple[float, float]:
        """The place of the station a stop id stands for."""
        x, y = self.station_xy[self.tt.station(stop_id)]
        return float(x), float(y)

    def street(self, station: int) -> tuple[int, float]:
        """A station's street node and the seconds walked between them."""
        return int(self.snapped[0][station]), float(self.snapped[1][station]) / self.cfg.walk_speed

    # ------------------------------------------------------------------ options and legs
    def options(self, now: float, origin: int, goal: int,
                fleet) -> list[tuple[Option, Journey | None]]:
        """A rider's options (:func:`~dispatch.space.journeys.rider_options`) ready at ``now``
        (simulated seconds) to go from the street node ``origin`` to ``goal``; ``fleet``: the
        fleet's estimate (its times on the service day's clock, which it does not read)."""
        c = self.cfg
        ends = (tuple(self.node_lonlat[origin]), tuple(self.node_lonlat[goal]))
        return rider_options(self.tt, now + self.offset, ends, (origin, goal), fleet,
                             snapped=self.snapped, max_walk=c.max_access_walk,
                             walk_speed=c.walk_speed)

    def between(self, legs: tuple[TransitLeg, ...]) -> list[Leg]:
        """The legs between stations of a journey (trains and walks), on the run's clock."""
        out = []
        for g in legs:
            out.append(Leg(g.mode, g.start - self.offset, g.end - self.offset, self.at(g.from_stop),
                           self.at(g.to_stop), g.from_stop, g.to_stop,
                           g.route_id if g.mode == "train" else None,
                           g.trip_id if g.mode == "train" else None))
        return out

    def walk_in(self, start: float, origin: int, j: Journey) -> Leg:
        """The walk from the door ``origin`` to a journey's first station, leaving at
        ``start``."""
        s = j.legs[0].from_stop
        return Leg("walk", start, start + j.first.walk, self.door(origin), self.at(s), None, s)

    def walk_out(self, arrive: float, stop_id: str, goal: int, seconds: float) -> Leg:
        """The walk from the station ``stop_id`` (arrived at ``arrive``) to the goal."""
        return Leg("walk", arrive, arrive + seconds, self.at(stop_id), self.door(goal), stop_id,
                   None)

    def to_street(self, arrive: float, stop_id: str) -> Leg:
        """The walk from a station (arrived at ``arrive``) to its street node."""
        node, secs = self.street(self.tt.station(stop_id))
        return Leg("walk", arrive, arrive + secs, self.at(stop_id), self.door(node), stop_id,
                   None)

    def from_street(self, at: float, station: int) -> Leg:
        """The walk from a station's street node (left at ``at``) into the station."""
        node, secs = self.street(station)
        sid = str(self.tt.station_ids[station])
        return Leg("walk", at, at + secs, self.door(node), self.at(sid), None, sid)

    def onward(self, j: Journey, goal: int) -> list[Leg]:
        """A journey's legs from its first train on: trains, walks between stations and the
        walk to the goal."""
        legs = self.between(j.legs)
        last = j.legs[-1]
        return [*legs, self.walk_out(last.end - self.offset, last.to_stop, goal, j.last.walk)]

    def replan(self, station: int, ready: float, goal: int) -> list[Leg]:
        """The rest of a trip from ``station``, where the rider is ready to board at ``ready``
        (simulated seconds) after missing the train they were to take: the earliest journey
        by the next trains and a walk to the goal (the Connection Scan from there), or the walk
        from the station to the goal where no train beats it (or none runs)."""
        c = self.cfg
        lon, lat = self.node_lonlat[goal]
        egress = access(self.tt, float(lon), float(lat), max_walk=c.max_access_walk,
                        walk_speed=c.walk_speed)
        j = best_journey(self.tt, ready + self.offset, {station: Part()}, egress)
        if j is not None:
            return self.onward(j, goal)
        sid = str(self.tt.station_ids[station])
        metres = float(np.hypot(*(self.station_xy[station] - self.node_xy[goal])))
        return [self.walk_out(ready, sid, goal, metres / c.walk_speed)]


def _lonlat(network) -> np.ndarray:
    """``(n, 2)``: each node's WGS84 longitude and latitude (the inverse of the network's
    :meth:`~dispatch.space.roads.RoadNetwork.lonlat_to_xy`)."""
    from pyproj import CRS, Transformer

    if network.crs is None:
        raise ValueError(f"road network {network.name!r} has no CRS: transit needs one")
    crs = CRS.from_user_input(network.crs)
    unit = crs.axis_info[0].unit_conversion_factor if crs.axis_info else 1.0
    xy = np.asarray(network.xy, np.float64)
    lon, lat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(
        xy[:, 0] / unit, xy[:, 1] / unit)
    return np.column_stack([lon, lat])


def percentile(values: list[float], q: float) -> float:
    """The ``q`` th percentile (linear, numpy's default) of ``values``; nan for none."""
    return float(np.percentile(values, q)) if values else math.nan
