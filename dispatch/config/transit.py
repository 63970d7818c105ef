"""``[transit]``: public transport riders may combine with the fleet, as data (the feed:
:mod:`dispatch.files.gtfs`; the router: :mod:`dispatch.space.csa`; the mode choice contract:
:mod:`dispatch.api.mode_choice`)."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class TransitConfig:
    """``[transit]``: the timetable (a GTFS feed and its service day), how riders walk to,
    from and between stations, the weights of a trip's generalized cost and the mode choice
    that weighs the options (``[transit.<mode_choice>]``: its parameters).

    A generalized cost is in seconds: ``w_ivt`` x in-vehicle time + ``w_wait`` x waiting +
    ``w_walk`` x walking + ``w_transfer`` x time spent changing trains (walking and waiting
    between two trains) + ``transfer_penalty`` per change. The default weights are the usual
    ones of transit appraisal (waiting and walking count twice a seated minute, a change five
    minutes)."""

    #: a shipped feed (``"nyc_subway"``: Manhattan's subway, one weekday) or a GTFS zip or
    #: folder, relative to the scenario file
    feed: str = "nyc_subway"
    #: the service day whose trips run (the shipped feed's is a Wednesday)
    service_date: dt.date = dt.date(2026, 9, 23)
    max_access_walk: float = 600.0  # metres a rider walks between a door and a station
    walk_speed: float = 1.3  # m/s, on every walk
    transfer_walk: float = 300.0  # metres between two stations a rider walks to change
    min_change: float = 60.0  # seconds to change trains in a station transfers.txt gives none
    w_ivt: float = 1.0  # weight of a second aboard (train or vehicle)
    w_wait: float = 2.0  # weight of a second waiting (for a train or a pickup)
    w_walk: float = 2.0  # weight of a second walking to or from a station
    w_transfer: float = 2.0  # weight of a second spent changing trains
    transfer_penalty: float = 300.0  # seconds added per change of train
    #: an installed mode choice (``dispatch plugins``): cheapest, logit, train_first
    mode_choice: str = "cheapest"
    #: the ``[transit.<mode_choice>]`` table: keyword arguments of its constructor
    params: tuple[tuple[str, Any], ...] = ()
    #: the feed's file, resolved (None: not read)
    feed_path: Path | None = None
