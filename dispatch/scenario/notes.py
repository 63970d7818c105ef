"""What reading a scenario tells its user once per process, however often the scenario is
read: a sweep, a bench or ``validate`` then ``run`` read the same trace many times, and the
same count of trips left out need be said once."""

from __future__ import annotations

import logging
from pathlib import Path

from dispatch.files.traces import Trips

log = logging.getLogger("dispatch.scenario.load")  # (where these lines were always logged)

#: the share of a trace's trips left out (by ``max_snap`` or ``start``) past which loading warns:
#: past it the trace and the network (or the start) probably do not match (another city,
#: coordinates in another CRS); below it the count is said at INFO level (``-v``)
DROPPED_WARN_SHARE = 0.25
#: (trace, reason, count) already said in this process: a sweep, a bench or ``validate`` then
#: ``run`` load the same trace many times, and the same count need be said once
SAID: set[tuple[str, str, int]] = set()


def say_dropped(trace_path: Path, trips: Trips) -> None:
    """Log the trips a trace's reading left out, once per trace, reason and count in a
    process: a warning past :data:`DROPPED_WARN_SHARE` of the file's trips, else at INFO."""
    total = len(trips) + sum(n for _, n in trips.dropped)
    for reason, n in trips.dropped:
        key = (str(trace_path), reason, n)
        if key in SAID:
            continue
        SAID.add(key)
        level = logging.WARNING if n > DROPPED_WARN_SHARE * total else logging.INFO
        log.log(level, "%s: %d of %d trips left out: %s", trace_path.name, n, total, reason)
