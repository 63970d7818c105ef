"""``[tasks]``: where the requests come from (a generator, a trace, the empirical sample) and
the limits every request of the scenario accepts, as data. A trace row's own limits are its
columns (:class:`dispatch.files.traces.Trips`); where a row leaves one blank, the scenario's
value here holds."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np

from dispatch.files.traces import Trips

SOURCES = ("static", "periodic", "poisson", "trace", "empirical")
#: seconds a request of the empirical sample accepts to wait for its pickup where ``[tasks]
#: max_wait`` is not set (other sources: no limit, the field's None)
EMPIRICAL_MAX_WAIT = 600.0


@dataclass(frozen=True)
class TaskConfig:
    source: str = "static"
    count: int | None = None  # static: number of tasks (unset: as many as agents); others: cap
    interval: float | None = None  # periodic: seconds between releases
    rate: float | None = None  # poisson: releases per second
    max_active: int | None = None  # periodic/poisson: a release is skipped while this many are open
    ground_fraction: float = 0.5  # probability that a generated task is on the ground layer
    service_time: float = 0.0  # seconds a vehicle spends at the task after arriving
    ttl: float | None = None  # seconds an unassigned task waits before it expires
    max_wait: float | None = None  # seconds a request accepts to wait for its pickup
    #: seconds of delay a request accepts at its drop-off, over release + direct drive time
    max_delay: float | None = None
    trace: Path | None = None  # trace: CSV or Parquet file of trips (see dispatch.files.traces)
    #: trace: the column of each trip's id, carried into the results as ``request_id`` (None:
    #: the first of request_id, trip_id, id the trace has; without one, the row's number)
    id_column: str | None = None
    trips: Trips | None = None
    trips_per_day: float | None = None  # empirical: expected trips over the 24 h day
    weekday: str = "all"  # empirical: the sample's trips of this weekday ("all": every day)
    #: trace: the date-time of second 0 (a trace's departure_time is read from it)
    start: datetime | None = None
    #: trace on roads: metres a pickup / drop-off may lie from the nearest node (farther:
    #: the trip is left out before the run, counted in trips.dropped); unset: no bound
    max_snap: float | None = None
    #: share of the requests booked ahead (each drawn from the run's prebooking stream; a
    #: trace's booked_at column instead: see dispatch.decide.prebook)
    prebook_share: float = 0.0
    #: seconds before its departure a request of prebook_share is booked (0: at its
    #: departure, an immediate request dispatched as a booked one)
    prebook_lead: float = 3600.0
    #: metres a rider may walk to a boarding point and from an alighting point (meeting
    #: points, dispatch.decide.meeting; 0: door to door; a trace's ``max_walk`` column per row)
    max_walk: float = 0.0
    #: m/s riders walk at (a trace's ``walk_speed`` column per row)
    walk_speed: float = 1.4
    #: boarding points (and as many alighting points) per request at most, the nearest
    #: within ``max_walk``
    meeting_points: int = 8

    @property
    def prebooked(self) -> bool:
        """Some request is booked ahead (``prebook_share``, or its trace's ``booked_at``)."""
        return self.prebook_share > 0 or (self.trips is not None and self.trips.prebooked)

    @property
    def walking(self) -> bool:
        """Some rider may walk to a meeting point (``max_walk`` > 0, or its trace's column)."""
        trips = self.trips
        return self.max_walk > 0 or (
            trips is not None and trips.max_walk is not None
            and bool((np.nan_to_num(trips.max_walk) > 0).any()))

    @property
    def delay_limited(self) -> bool:
        """Some request has a drop-off delay limit (``max_delay``, or its trace's column)."""
        trips = self.trips
        return self.max_delay is not None or (
            trips is not None and trips.max_delay is not None
            and bool(np.isfinite(trips.max_delay).any()))
