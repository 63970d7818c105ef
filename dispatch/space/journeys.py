"""Door-to-door journeys with public transport on a :class:`~dispatch.space.transit.Timetable`,
and the options a rider has (:func:`rider_options`), summed up as mode choice
:class:`~dispatch.api.mode_choice.Option`\\ s.

A journey is an access to a first station, trains (and walks between stations), and an egress
from a last station to the goal. An access or an egress is a :class:`Part`: the seconds it
spends waiting, aboard and walking. On foot (:func:`access`) it is a straight-line walk at the
walk speed (as the timetable's footpaths are); by the fleet it is the fleet's estimate (its
wait for the pickup, its ride) and the walk between the street node the vehicle stops at and
the station (:meth:`Timetable.snap <dispatch.space.transit.Timetable.snap>`). One scan of the
connections (:func:`best_journey`) finds the best pair of first and last stations among those
given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dispatch.api.mode_choice import Option
from dispatch.space.csa import TransitLeg, earliest_arrivals
from dispatch.space.transit import Timetable


@dataclass(frozen=True)
class Part:
    """An access to a station or an egress from one, in seconds: ``wait`` (for a vehicle),
    ``ivt`` (aboard it), ``walk``."""

    wait: float = 0.0
    ivt: float = 0.0
    walk: float = 0.0

    @property
    def seconds(self) -> float:
        return self.wait + self.ivt + self.walk


#: the fleet's estimate of a ride ``(from node, to node, ready time) -> (wait, ride)`` seconds
#: (None: no vehicle would take it); what the dispatcher's offer estimate gives
FleetEstimate = Callable[[int, int, float], tuple[float, float] | None]


def access(tt: Timetable, lon: float, lat: float, *, max_walk: float,
           walk_speed: float) -> dict[int, Part]:
    """The walks to (or from) the stations within ``max_walk`` metres (straight line) of a
    point, at ``walk_speed`` m/s."""
    stations, metres = tt.near(lon, lat, max_walk)
    return {int(s): Part(walk=float(m) / walk_speed) for s, m in zip(stations, metres)}


@dataclass(frozen=True)
class Journey:
    """A journey from ``depart`` (when the rider is ready at the origin) to ``arrive`` at the
    goal: ``first`` (the access to the first station), the ``legs`` between stations in time
    order (trains, and walks between stations), ``last`` (the egress from the last station),
    and the :class:`~dispatch.api.mode_choice.Option` that sums it up."""

    depart: float
    arrive: float
    first: Part
    legs: tuple[TransitLeg, ...]
    last: Part
    option: Option


def best_journey(tt: Timetable, depart: float, sources: dict[int, Part],
                 egress: dict[int, Part], *, kind: str = "train") -> Journey | None:
    """The journey that reaches the goal first, from the accesses ``sources`` (by first
    station) to the egresses ``egress`` (by last station). None when no station of
    ``egress`` is reached (or either is empty), or when going from a source station to the
    goal without a train beats every train. The option's ``wait + ivt + walk + change`` is
    ``arrive - depart``."""
    if not sources or not egress:
        return None
    eg = np.full(tt.n_stations, np.inf)
    for s, part in egress.items():
        eg[s] = part.seconds
    a = earliest_arrivals(tt, {s: depart + p.seconds for s, p in sources.items()}, egress=eg)
    end, total = a.best(eg)
    if end < 0:
        return None
    legs = a.journey(end)
    trains = [leg for leg in legs if leg.mode == "train"]
    if not trains:
        return None
    first, last = sources[tt.station(trains[0].from_stop)], egress[end]
    # walks and waits between trains; a journey starts with a train, so any other walk
    # leg is after the last train (to a station nearer the goal)
    gaps = trains[-1].start - trains[0].end - sum(leg.end - leg.start for leg in trains[1:-1])
    walk_out = sum(leg.end - leg.start for leg in legs
                   if leg.mode == "walk" and leg.start >= trains[-1].end)
    option = Option(kind, total,
                    ivt=first.ivt + sum(leg.end - leg.start for leg in trains) + last.ivt,
                    wait=first.wait + (trains[0].start - depart - first.seconds) + last.wait,
                    walk=first.walk + walk_out + last.walk,
                    change=gaps if len(trains) > 1 else 0.0, changes=len(trains) - 1)
    return Journey(depart, total, first, tuple(legs), last, option)


def _fleet_parts(fleet: FleetEstimate, pairs, ready: float,
                 walks: np.ndarray) -> dict[int, Part]:
    """``{station: Part}`` of fleet rides ``(station, from node, to node)``, each with the
    walk between the station and its node."""
    out = {}
    for s, u, v in pairs:
        est = fleet(int(u), int(v), ready)
        if est is not None:
            out[int(s)] = Part(wait=float(est[0]), ivt=float(est[1]), walk=float(walks[s]))
    return out


def rider_options(tt: Timetable, depart: float, ends: tuple[tuple[float, float], ...],
                  nodes: tuple[int, int], fleet: FleetEstimate | None, *,
                  snapped: tuple[np.ndarray, np.ndarray], max_walk: float, walk_speed: float,
                  feeders: int = 3) -> list[tuple[Option, Journey | None]]:
    """The options of a rider ready at ``depart`` to go from ``ends[0]`` to ``ends[1]``
    (longitude, latitude), street nodes ``nodes``: door to door by the fleet; a walk, trains
    and a walk; the fleet to one of the ``feeders`` stations nearest the origin, trains and a
    walk; a walk, trains and the fleet from one of the ``feeders`` stations nearest the goal
    (its estimate asked for ``depart``: the train's arrival is not known before the scan).
    ``snapped``: per station, its street node and the walk between them in metres
    (:meth:`~dispatch.space.transit.Timetable.snap`). Options no vehicle or train serves are
    left out; ``fleet`` None: no fleet."""
    (olon, olat), (glon, glat) = ends
    walks = snapped[1] / walk_speed
    out: list[tuple[Option, Journey | None]] = []
    if fleet is not None:
        est = fleet(nodes[0], nodes[1], depart)
        if est is not None:
            out.append((Option("fleet", depart + est[0] + est[1], ivt=est[1], wait=est[0],
                               walk=0.0), None))
    walk_in = access(tt, olon, olat, max_walk=max_walk, walk_speed=walk_speed)
    walk_out = access(tt, glon, glat, max_walk=max_walk, walk_speed=walk_speed)
    plans = [("train", walk_in, walk_out)]
    if fleet is not None:
        near_o = tt.near(olon, olat, np.inf)[0][:feeders]
        near_g = tt.near(glon, glat, np.inf)[0][:feeders]
        plans.append(("fleet+train", _fleet_parts(
            fleet, [(s, nodes[0], snapped[0][s]) for s in near_o], depart, walks), walk_out))
        plans.append(("train+fleet", walk_in, _fleet_parts(
            fleet, [(s, snapped[0][s], nodes[1]) for s in near_g], depart, walks)))
    for kind, sources, egress in plans:
        j = best_journey(tt, depart, sources, egress, kind=kind)
        if j is not None:
            out.append((j.option, j))
    return out
