"""Door-to-door transit journeys on a :class:`~dispatch.space.transit.Timetable`: the stations
a rider reaches on foot from a point (:func:`access`), the best journey from where a rider is
ready to where they are going (:func:`best_journey`: walks to and from stations, trains and the
changes between them), summed up as a mode choice :class:`~dispatch.api.mode_choice.Option`.

Walks to and from stations are straight lines at the walk speed (as the timetable's footpaths
are). A feeder by the fleet plugs in through the same call: the fleet's drop-off at a station
is a source (``sources = {station: drop-off estimate}``, no access walk), and a fleet leg
after the train is an egress (``egress[station]`` = the fleet's estimate from the station to
the goal, including its wait), so one scan finds the best station for either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dispatch.api.mode_choice import Option
from dispatch.space.csa import TransitLeg, earliest_arrivals
from dispatch.space.transit import Timetable


def access(tt: Timetable, lon: float, lat: float, *, max_walk: float,
           walk_speed: float) -> dict[int, float]:
    """``{station: seconds}`` of the stations within ``max_walk`` metres (straight line) of a
    point, walked at ``walk_speed`` m/s."""
    stations, metres = tt.near(lon, lat, max_walk)
    return {int(s): float(m) / walk_speed for s, m in zip(stations, metres)}


@dataclass(frozen=True)
class Journey:
    """A transit journey from ``depart`` (when the rider is ready at the origin) to
    ``arrive`` at the goal: ``access_walk`` seconds to the first station (or a fleet's
    drop-off there), the ``legs`` between stations in time order (trains, and walks between
    stations), then ``egress`` seconds to the goal (a walk or a fleet leg, as the caller's
    egress was), and the :class:`~dispatch.api.mode_choice.Option` that sums it up."""

    depart: float
    arrive: float
    legs: tuple[TransitLeg, ...]
    access_walk: float
    egress: float
    option: Option


def best_journey(tt: Timetable, depart: float, sources: dict[int, float],
                 egress: dict[int, float], *, kind: str = "train", access_walks: bool = True,
                 egress_walks: bool = True) -> Journey | None:
    """The journey that reaches the goal first: ``sources`` (``{station: seconds from the
    origin}``: the access walks, or a fleet's drop-off less ``depart``) and ``egress``
    (``{station: seconds to the goal}``). ``access_walks`` / ``egress_walks``: the access /
    egress is a walk (counted as walking), else a fleet leg (counted as in-vehicle time, its
    wait included). None when no
    station of ``egress`` is reached (or either is empty), or when walking to the goal by way
    of a station beats every train. The option's ``wait + ivt + walk + change`` is
    ``arrive - depart``."""
    if not sources or not egress:
        return None
    eg = np.full(tt.n_stations, np.inf)
    for s, sec in egress.items():
        eg[s] = min(eg[s], sec)
    a = earliest_arrivals(tt, {s: depart + sec for s, sec in sources.items()}, egress=eg)
    end, total = a.best(eg)
    if end < 0:
        return None
    legs = a.journey(end)
    trains = [leg for leg in legs if leg.mode == "train"]
    if not trains:  # walking to the goal by way of a station beats every train
        return None
    walk_in = float(sources[tt.station(trains[0].from_stop)])
    ivt = sum(leg.end - leg.start for leg in trains)
    changes = len(trains) - 1
    # walks and waits between trains; a journey starts with a train, so any other walk
    # leg is after the last train (to a station nearer the goal)
    change = trains[-1].start - trains[0].end - sum(leg.end - leg.start for leg in trains[1:-1]) \
        if changes else 0.0
    wait = trains[0].start - depart - walk_in
    walk_out = sum(leg.end - leg.start for leg in legs
                   if leg.mode == "walk" and leg.start >= trains[-1].end)
    last = float(eg[end])
    walk = walk_out + (walk_in if access_walks else 0.0) + (last if egress_walks else 0.0)
    ivt += (0.0 if access_walks else walk_in) + (0.0 if egress_walks else last)
    option = Option(kind, total, ivt=ivt, wait=wait, walk=walk, change=change, changes=changes)
    return Journey(depart, total, tuple(legs), walk_in, last, option)
