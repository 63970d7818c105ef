"""Electric fleets' configuration: ``[fleet.energy]`` and ``[chargers]`` / ``[charging]`` as typed
values, and the two CSV files they name (stations; the ``soc`` column of a fleet start file).

The batteries are :mod:`dispatch.fleet.battery`, the stations and charging visits
:mod:`dispatch.fleet.chargers`, the strategies' contract :mod:`dispatch.api.charger`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dispatch.config.faults import FaultConfig


@dataclass(frozen=True)
class EnergyConfig:
    """``[fleet.energy]`` (see the module docstring). ``speed_table``: ``((km/h, Wh/km), ...)``
    sorted by speed (empty: the constant ``wh_per_km``); ``socs``: a start file's ``soc``
    column per vehicle (row order; nan: ``soc0``)."""

    battery_kwh: float = 50.0  # kWh: usable battery of every car
    #: Wh/km: consumption, a constant, or ``[[km/h, Wh/km], ...]`` with rising speeds,
    #: interpolated at each leg's mean speed (HIVE's tabular powertrain)
    wh_per_km: float = field(
        default=140.0, metadata={"toml": "float, or array of [km/h, Wh/km] pairs"})
    speed_table: tuple[tuple[float, float], ...] = ()
    #: kW: auxiliary draw (kWh per hour) over every second not plugged in, driving included
    idle_kwh_per_hour: float = 0.0
    #: share of the battery charged at the start (state of charge); a start file's soc
    #: column wins
    soc0: float = 1.0
    #: share of the battery a car keeps: a car whose plan and a new trip would leave less is
    #: no candidate for the trip
    reserve: float = 0.1
    max_charge_kw: float = math.inf  # kW: the car's charging power cap (inf: none)
    socs: tuple[float, ...] = ()
    #: seconds between two rows per vehicle of the ``soc`` table
    sample: float = 900.0

    def wh_per_metre(self, speed: float) -> float:
        """Wh per metre at ``speed`` (m/s; 0 or nan: the constant, or the table's mean)."""
        if not self.speed_table:
            return self.wh_per_km / 1000.0
        s, w = zip(*self.speed_table)
        if not speed > 0:
            return float(np.mean(w)) / 1000.0
        return float(np.interp(speed * 3.6, s, w)) / 1000.0


@dataclass(frozen=True)
class StationRow:
    station_id: str
    node: Any  # a node id of the network file (or None: lon/lat given)
    lon: float
    lat: float
    plugs: int
    kw: float


#: metres a station given by lon/lat may lie from the network's nearest node (``[chargers]
#: max_snap``): the shipped Manhattan stations lie up to 491 m from an intersection (so the
#: trips' 250 m would refuse one); a station a kilometre from every node is in another place
STATION_MAX_SNAP = 1000.0


@dataclass(frozen=True)
class ChargingConfig:
    """``[chargers]`` and ``[charging]``: the stations, the taper, the strategy and its
    parameters (``[charging.<name>]``), the timer."""

    stations: tuple[StationRow, ...] = ()
    #: the stations: station_id, node (an id of the network) or lon, lat, plugs, kw (HIVE's
    #: charger_count / charger_id = LEVEL_1 | LEVEL_2 | DCFC read too)
    file: Any = field(
        default=None, metadata={"toml": "string (a CSV file, relative to the scenario file)"})
    #: share of the battery (state of charge) up to which a car charges at the plug's full
    #: power, then linearly less
    taper_from: float = 0.8
    #: share of the plug's power left at a full battery (a 50 kW plug ends at 10 kW)
    taper_floor: float = 0.2
    #: metres a station given by lon/lat may lie from the nearest node (farther: refused)
    max_snap: float = STATION_MAX_SNAP
    strategy: str = "threshold"
    interval: float = 60.0
    params: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    sweep: tuple[str, ...] = ()
    #: [faults] tow: seconds until a stranded vehicle stands charged-able at the nearest station
    tow: float = FaultConfig.tow

    def params_of(self, name: str) -> tuple[tuple[str, Any], ...]:
        return dict(self.params).get(name, ())


def read_stations(path, tab=None) -> tuple[StationRow, ...]:
    """Rows of a stations CSV: ``station_id``, ``node`` or ``lon``/``lat``, ``plugs``, ``kw``
    (HIVE's ``charger_count`` / ``charger_id`` are read as plugs / kW of LEVEL_1 3.3,
    LEVEL_2 7.2, DCFC 50 where ``plugs`` / ``kw`` are missing)."""
    import csv

    hive_kw = {"LEVEL_1": 3.3, "LEVEL_2": 7.2, "DCFC": 50.0}
    out = []
    with open(path, newline="", encoding="utf-8") as f:
        for i, r in enumerate(csv.DictReader(f), 1):
            try:
                sid = str(r["station_id"])
                plugs = int(r.get("plugs") or r["charger_count"])
                kw = float(r["kw"]) if r.get("kw") else hive_kw[r["charger_id"]]
                node = r.get("node") or None
                lon = float(r["lon"]) if r.get("lon") else math.nan
                lat = float(r["lat"]) if r.get("lat") else math.nan
            except (KeyError, ValueError) as e:
                raise ValueError(f"{path}: row {i}: {type(e).__name__}: {e} (want station_id, "
                                 f"node or lon/lat, plugs, kw)") from None
            if plugs < 1 or not kw > 0 or (node is None and math.isnan(lon + lat)):
                raise ValueError(f"{path}: row {i}: plugs must be >= 1, kw > 0, and a node or "
                                 f"lon/lat given")
            out.append(StationRow(sid, node, lon, lat, plugs, kw))
    if not out:
        raise ValueError(f"{path}: no station")
    return tuple(out)


def read_socs(path) -> tuple[float, ...]:
    """The optional ``soc`` column (0-1) of a fleet start file, in row order (blank: nan, the
    scenario's ``soc0``); empty if there is none."""
    import csv

    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows or "soc" not in rows[0]:
        return ()
    out = []
    for i, r in enumerate(rows, 1):
        x = float(r["soc"]) if r["soc"] not in ("", None) else math.nan
        if x == x and not 0.0 <= x <= 1.0:
            raise ValueError(f"{path}: row {i}: soc {x} not in [0, 1]")
        out.append(x)
    return tuple(out)
