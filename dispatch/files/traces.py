"""Input files of a scenario: trip traces and fleet start files, validated row by row.

A **trace** (CSV or Parquet) holds one trip per row: its release time ``t`` (or
``release_time``, seconds; or ``departure_time``, a date-time read as seconds from the
scenario's ``[tasks] start``), its pickup and, optionally, its drop-off, and an optional
``max_wait`` and ``max_delay`` (seconds; blank: the scenario's), ``passengers`` (a whole
number >= 1; blank: 1), ``max_walk`` (metres) and ``walk_speed`` (m/s) of meeting points
(:mod:`dispatch.decide.meeting`; blank: the scenario's) and ``booked_at`` (when the trip was booked:
seconds, or a date-time where the trace's time column is ``departure_time``; blank: not
booked; never after the requested departure; see :mod:`dispatch.decide.prebook`). The trip's
id is its id column's cell: the column ``[tasks] id_column`` names, else the first of
``request_id``, ``trip_id``, ``id`` the trace has; kept as written (blank ids and an id of two rows
are refused), an integer where every id is one written plainly (``42``, ``-7``; not ``007``,
``+7`` or ``7.0``), else a string; without an id column, a trip's id is its 1-based data row. The
results' ``request_id`` is it, whatever the order the trips enter the run in. Other columns are
ignored.
Where things are, by space:

* voxel world: ``x, y, z`` (metres; the pickup), optionally ``dest_x, dest_y, dest_z``;
* road network, one of: ``origin_node, dest_node`` (node ids of the network);
  ``origin_x, origin_y, dest_x, dest_y`` (metres in the network's coordinates); or
  ``pickup_latitude, pickup_longitude, dropoff_latitude, dropoff_longitude`` or ``o_lat, o_lon,
  d_lat, d_lon`` (WGS 84, projected to the network's CRS). Positions are snapped to the nearest
  node at run time and the snapping distance is recorded per trip; with ``[tasks] max_snap``
  the trips with a pickup or drop-off farther than that from every node are left out before
  the run (:func:`within_snap`, a warning names the count).

A **fleet start file** (CSV) has ``vehicle_id`` (a unique integer, the vehicle's ``agent_id``)
and either ``node`` (roads) or ``x, y`` (and ``z`` in a voxel world; metres).

A bad row (a missing or non-numeric value, a negative time, a position outside the world)
raises a ScenarioError naming the file and its 1-based data row.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields, replace
from datetime import date, datetime
from pathlib import Path

import numpy as np

from dispatch.errors import ScenarioError
from dispatch.files.tables import CELLS, NUMBER, NUMBER_OR_BLANK, Table

TIME_COLUMNS = ("t", "release_time", "departure_time")
#: the time column given as date-times (seconds from ``[tasks] start``)
DATETIME_COLUMN = "departure_time"
#: when a trip was booked (optional; :mod:`dispatch.decide.prebook`)
BOOKED_COLUMN = "booked_at"
#: the columns that may hold a trip's id, the first found used (:attr:`Trips.ids`)
ID_COLUMNS = ("request_id", "trip_id", "id")
#: the column sets a trace may use, by space: (name, pickup columns, drop-off columns)
LAYOUTS = {
    "voxel": (("xyz", ("x", "y", "z"), ("dest_x", "dest_y", "dest_z")),),
    "road": (
        ("node", ("origin_node",), ("dest_node",)),
        ("metres", ("origin_x", "origin_y"), ("dest_x", "dest_y")),
        ("latlon", ("pickup_latitude", "pickup_longitude"),
         ("dropoff_latitude", "dropoff_longitude")),
        ("latlon", ("o_lat", "o_lon"), ("d_lat", "d_lon")),  # latitude first, as above
    ),
}


@dataclass(frozen=True, eq=False)
class Trips:
    """A trace's trips, sorted by release time (stable). ``layout`` names the columns used
    (``xyz``, ``node``, ``metres`` or ``latlon``); ``origin`` / ``dest`` hold them in that
    order (``dest`` is None when the trace has no drop-offs); ``max_wait`` is nan where blank."""

    path: Path
    layout: str
    t: np.ndarray
    origin: np.ndarray
    dest: np.ndarray | None
    max_wait: np.ndarray
    row: np.ndarray  # each trip's 1-based data row in the file (for error messages)
    #: riders per trip (``passengers`` column; 1 where absent or blank)
    passengers: np.ndarray | None = None
    #: seconds of delay over the direct drive each trip accepts (``max_delay``; nan: the
    #: scenario's)
    max_delay: np.ndarray | None = None
    #: metres each rider may walk to a boarding point and from an alighting point
    #: (``max_walk``; nan: the scenario's) and the rider's walking speed (``walk_speed``, m/s;
    #: nan: the scenario's); None where the trace has no such column
    max_walk: np.ndarray | None = None
    walk_speed: np.ndarray | None = None
    #: trips of the file left out, as ``(reason, count)`` pairs (before ``[tasks] start``;
    #: farther than ``[tasks] max_snap`` from the network): stored with the results
    dropped: tuple[tuple[str, int], ...] = ()
    #: when each trip was booked (seconds of the run, ``booked_at`` column; nan: not booked,
    #: it is requested at its release time): see :mod:`dispatch.decide.prebook`
    booked_at: np.ndarray | None = None
    #: each trip's id as the file wrote it (:func:`trip_ids`): int64 where every id is an
    #: integer written plainly (or the 1-based data rows of a trace without an id column),
    #: else Python strings; None for trips not read from a file (an empirical day): each
    #: request's id is then its number in the day
    ids: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def prebooked(self) -> bool:
        """Some trip is booked (a finite ``booked_at``)."""
        return self.booked_at is not None and bool(np.isfinite(self.booked_at).any())

    def subset(self, keep: np.ndarray, reason: str) -> Trips:
        """The trips where ``keep`` (a boolean mask) holds, the others counted under
        ``reason`` in :attr:`dropped` (every per-trip array is cut alike)."""
        keep = np.asarray(keep, dtype=bool)
        n_out = int(keep.size - keep.sum())
        if n_out == 0:
            return self
        return replace(self.take(keep), dropped=self.dropped + ((reason, n_out),))

    def take(self, index: np.ndarray) -> Trips:
        """The trips at ``index`` (a boolean mask or positions, e.g. a new order): every
        per-trip array is cut alike; :attr:`dropped` is kept."""
        n = len(self)
        cut = {}
        for f in fields(self):
            column = getattr(self, f.name)
            if isinstance(column, np.ndarray) and column.shape[:1] == (n,):
                cut[f.name] = column[index]
        return replace(self, **cut)


def parse_datetime(v) -> datetime:
    """A date-time of a trace cell or a scenario key: a ``datetime`` (a ``date`` is its
    midnight) or an ISO 8601 string (``2014-12-21 08:30:00``, ``2014-12-21T08:30``, with or
    without a UTC offset). ValueError otherwise."""
    if isinstance(v, datetime):
        return v
    if isinstance(v, date):
        return datetime(v.year, v.month, v.day)
    if isinstance(v, str) and v.strip():
        return datetime.fromisoformat(v.strip())
    raise ValueError(f"not a date-time: {v!r}")


def seconds_between(d: datetime, start: datetime) -> float:
    """Seconds from ``start`` to ``d``; where one is naive and the other aware, the naive one
    is read in the other's time zone."""
    if (d.tzinfo is None) != (start.tzinfo is None):
        if d.tzinfo is None:
            d = d.replace(tzinfo=start.tzinfo)
        else:
            start = start.replace(tzinfo=d.tzinfo)
    return (d - start).total_seconds()


def _seconds_since(path: Path, values: list, start: datetime) -> np.ndarray:
    """Seconds from ``start`` of each date-time of the ``departure_time`` column (a naive one
    and an aware one: the naive one is read in the other's time zone); a bad cell names its
    1-based data row."""
    out = np.empty(len(values))
    seen: dict = {}  # traces repeat their times (to the minute): parse each once
    for i, v in enumerate(values):
        key = v if isinstance(v, str) else None
        got = seen.get(key) if key is not None else None
        if got is None:
            try:
                d = parse_datetime(v)
            except (TypeError, ValueError):
                raise ScenarioError(path, f"row {i + 1}", f"{DATETIME_COLUMN} {v!r} is not a "
                                    "date-time (ISO 8601, e.g. 2014-12-21 08:30:00)") from None
            got = seconds_between(d, start)
            if key is not None:
                seen[key] = got
        out[i] = got
    return out


class IdColumnMissing(ScenarioError):
    """The id column a scenario names (``[tasks] id_column``) is not in the trace: ``column``
    and the trace's ``columns`` (in the file's order) for the scenario's own error."""

    def __init__(self, file: Path, column: str, columns: list[str]) -> None:
        self.column, self.columns = column, columns
        super().__init__(file, "<header>", f"no column {column!r} (its columns: "
                                           f"{', '.join(columns)})")


def read_trace(path: Path, space: str, size: tuple[float, float, float] | None,
               max_bytes: int | None = None, *, start: datetime | None = None,
               id_column: str | None = None) -> Trips:
    """Read and validate a trip trace for a ``space`` (``"voxel"``: ``size`` is the world's);
    a file of more than ``max_bytes`` is refused before it is read. A ``departure_time``
    column (date-times) needs ``start``: times are seconds from it, and trips departing before
    it are left out (counted in :attr:`Trips.dropped`). ``id_column``: the column of the trips'
    ids (None: the first of :data:`ID_COLUMNS` the trace has); one the trace lacks raises
    :class:`IdColumnMissing` once the header is read."""
    table = Table(path, max_bytes)
    columns = set(table.names)
    if id_column is not None and id_column not in columns:
        raise IdColumnMissing(path, id_column, list(dict.fromkeys(table.names)))
    tcol = next((c for c in TIME_COLUMNS if c in columns), None)
    layout = next((lay for lay in LAYOUTS[space] if all(c in columns for c in lay[1])), None)
    if tcol is None or layout is None:
        if len(LAYOUTS[space]) == 1:
            wanted = [c for c in LAYOUTS[space][0][1] if c not in columns]
        else:
            wanted = [" or ".join("(" + ", ".join(lay[1]) + ")" for lay in LAYOUTS[space])]
        missing = ([] if layout else wanted) + (
            [] if tcol else ["release_time (or t, or departure_time)"])
        raise table.after_rows(ScenarioError(path, "<header>",
                                               f"missing column(s): {', '.join(missing)}"))
    name, pick, drop = layout
    has_dest = all(c in columns for c in drop)
    if not has_dest and any(c in columns for c in drop):
        raise table.after_rows(ScenarioError(path, "<header>",
                                               f"drop-off needs all of {', '.join(drop)}"))
    if tcol == DATETIME_COLUMN and start is None:
        raise table.after_rows(ScenarioError(
            path, DATETIME_COLUMN, "holds date-times: set [tasks] start (e.g. start = "
            "\"2014-12-21T00:00\") in the scenario, the time the run's second 0 stands for"))
    if tcol != DATETIME_COLUMN and start is not None:
        raise table.after_rows(ScenarioError(
            path, tcol, "gives times in seconds; [tasks] start is only used with a "
            f"{DATETIME_COLUMN} column of date-times"))
    optional = [c for c in ("max_wait", "max_delay", "passengers", "max_walk", "walk_speed")
                if c in columns]
    booked = BOOKED_COLUMN in columns
    idcol = id_column or next((c for c in ID_COLUMNS if c in columns), None)
    cols = table.read({**({idcol: CELLS} if idcol else {}),
                       tcol: CELLS if tcol == DATETIME_COLUMN else NUMBER,
                       **{c: NUMBER for c in pick + (drop if has_dest else ())},
                       **{c: NUMBER_OR_BLANK for c in optional},
                       **({BOOKED_COLUMN: CELLS if tcol == DATETIME_COLUMN else NUMBER_OR_BLANK}
                          if booked else {})})
    if tcol == DATETIME_COLUMN:
        t = _seconds_since(path, cols.cells(tcol), start)
    else:
        t = cols.numbers((tcol,))[:, 0]
    origin = cols.numbers(pick)
    dest = cols.numbers(drop) if has_dest else None
    max_wait = (cols.numbers(("max_wait",))[:, 0]
                if "max_wait" in columns else np.full(len(t), math.nan))
    max_delay = (cols.numbers(("max_delay",))[:, 0]
                 if "max_delay" in columns else np.full(len(t), math.nan))
    passengers = (cols.numbers(("passengers",))[:, 0]
                  if "passengers" in columns else np.ones(len(t)))
    booked_at = None
    if booked:
        booked_at = booking_times(path, cols, tcol == DATETIME_COLUMN, start, t)
    max_walk = cols.numbers(("max_walk",))[:, 0] if "max_walk" in columns else None
    walk_speed = cols.numbers(("walk_speed",))[:, 0] if "walk_speed" in columns else None
    ids = trip_ids(path, idcol, cols.cells(idcol) if idcol else None, len(t))
    del cols
    early = t < 0 if tcol == DATETIME_COLUMN else np.zeros(len(t), dtype=bool)

    def check_row(i: int) -> None:
        """Raise the first error of row ``i`` (0-based), if it has one."""
        if max_delay[i] < 0:
            raise ScenarioError(path, f"row {i + 1}", f"max_delay {max_delay[i]} is negative")
        if max_walk is not None and max_walk[i] < 0:
            raise ScenarioError(path, f"row {i + 1}, column max_walk",
                                f"max_walk {max_walk[i]} is negative")
        if walk_speed is not None and walk_speed[i] <= 0:
            raise ScenarioError(path, f"row {i + 1}, column walk_speed",
                                f"walk_speed {walk_speed[i]} is not > 0")
        p = passengers[i]
        if p == p and (p < 1 or p != int(p) or p > 2**31):
            raise ScenarioError(path, f"row {i + 1}", f"passengers = {p} is not a whole "
                                                      f"number >= 1")
        if t[i] < 0:
            raise ScenarioError(path, f"row {i + 1}", f"release time {t[i]} is negative")
        if max_wait[i] <= 0:
            raise ScenarioError(path, f"row {i + 1}", f"max_wait {max_wait[i]} is not > 0")
        if size is not None:
            for cs, values in ((pick, origin[i]), (drop, dest[i] if has_dest else ())):
                for c, v, s in zip(cs, values, size):
                    if not 0 <= v < s:
                        raise ScenarioError(path, f"row {i + 1}",
                                            f"{c} = {v} is outside the world [0, {s})")
        if name == "node":
            for c, v in zip(pick + (drop if has_dest else ()),
                            (*origin[i], *(dest[i] if has_dest else ()))):
                if v != int(v):
                    raise ScenarioError(path, f"row {i + 1}", f"{c} = {v} is not a node id")
        if name == "latlon":
            for c, v in zip(pick + (drop if has_dest else ()),
                            (*origin[i], *(dest[i] if has_dest else ()))):
                if not -180 <= v <= 180 or (c.endswith(("latitude", "lat"))
                                            and not -90 <= v <= 90):
                    raise ScenarioError(path, f"row {i + 1}", f"{c} = {v} is not a coordinate")

    # the checks of every row at once; the first row failing one is checked alone, for its
    # message (rows departing before ``start`` are left out below, not checked)
    with np.errstate(invalid="ignore"):
        bad = (max_delay < 0) | (t < 0) | (max_wait <= 0) | (
            (passengers == passengers)
            & ((passengers < 1) | (passengers != np.trunc(passengers)) | (passengers > 2**31)))
        if max_walk is not None:
            bad |= max_walk < 0
        if walk_speed is not None:
            bad |= walk_speed <= 0
        points = [(pick, origin)] + ([(drop, dest)] if has_dest else [])
        for cs, values in points:
            if size is not None:
                for j, s in enumerate(size[:len(cs)]):
                    bad |= ~((values[:, j] >= 0) & (values[:, j] < s))
            if name == "node":
                bad |= (values != np.trunc(values)).any(axis=1)
            if name == "latlon":
                lat = np.array([c.endswith(("latitude", "lat")) for c in cs])
                bad |= (~((values >= -180) & (values <= 180))
                        | (lat & ~((values >= -90) & (values <= 90)))).any(axis=1)
    for i in np.flatnonzero(bad & ~early):
        check_row(int(i))
    passengers[(passengers != passengers) & ~early] = 1.0
    order = np.argsort(t, kind="stable")
    trips = Trips(path, name, t[order], origin[order],
                  None if dest is None else dest[order], max_wait[order], order + 1,
                  passengers[order].astype(np.int64), max_delay[order],
                  None if max_walk is None else max_walk[order],
                  None if walk_speed is None else walk_speed[order],
                  booked_at=None if booked_at is None else booked_at[order], ids=ids[order])
    if early.any():
        trips = trips.subset(~early[order], f"departed before tasks.start ({start.isoformat()})")
    if early.any() and not len(trips):
        raise ScenarioError(path, DATETIME_COLUMN, f"no trip departs at or after tasks.start "
                                                   f"({start.isoformat()})")
    return trips


#: an integer id written plainly: no sign but a minus, no leading zero, no point
_PLAIN_INT = re.compile(r"-?(0|[1-9][0-9]*)")


def trip_ids(path: Path, column: str | None, cells: list | None, n: int) -> np.ndarray:
    """The ids of a trace's ``n`` rows in file order: the ``column``'s ``cells`` as written,
    as int64 where every one is an integer written plainly (``42``, ``-7``; an integer of a
    Parquet file), else as strings (``007``, ``7.0`` and ``trip-7`` are kept as written);
    without an id column (``column`` None), each row's 1-based data row (int64). A blank cell
    or an id of an earlier row raises a ScenarioError naming the file, the row and the
    column."""
    if column is None:
        return np.arange(1, n + 1, dtype=np.int64)
    ids = np.empty(n, dtype=object)
    seen: dict[str, int] = {}
    for i, v in enumerate(cells):
        s = v if isinstance(v, str) else "" if v is None or v != v else str(v)
        if not s.strip():
            raise ScenarioError(path, f"row {i + 1}, column {column}", "the id is blank: "
                                "every trip needs its own id")
        first = seen.setdefault(s, i)
        if first != i:
            raise ScenarioError(path, f"row {i + 1}, column {column}",
                                f"{column} {s!r} is also the id of row {first + 1}: ids must "
                                "be unique")
        ids[i] = s
    plain = _PLAIN_INT.fullmatch
    if all(plain(s) for s in seen):
        try:
            return np.array([int(s) for s in ids], dtype=np.int64)
        except OverflowError:  # beyond int64: kept as written
            pass
    return ids


def booking_times(path: Path, cols, datetimes: bool, start: datetime | None,
                  t: np.ndarray) -> np.ndarray:
    """The ``booked_at`` column of a trace as seconds of the run (nan where blank): date-times
    (read from ``start``, as ``departure_time``) where ``datetimes``, else seconds. A booking
    after the row's requested departure ``t`` (seconds) raises a ScenarioError naming the file,
    the row and the column; rows departing before ``start`` (left out) are not checked."""
    if datetimes:
        cells = cols.cells(BOOKED_COLUMN)
        blank = np.array([c is None or (isinstance(c, str) and not c.strip())
                          or (isinstance(c, float) and c != c) for c in cells], dtype=bool)
        booked = np.full(len(cells), math.nan)
        if (~blank).any():
            keep = np.flatnonzero(~blank)
            try:
                got = _seconds_since(path, [cells[i] for i in keep.tolist()], start)
            except ScenarioError as e:  # its row is the k-th non-blank one: name the file's
                k = int(e.key.split()[-1]) - 1
                raise ScenarioError(path, f"row {int(keep[k]) + 1}",
                                    f"{BOOKED_COLUMN} {cells[int(keep[k])]!r} is not a "
                                    "date-time (ISO 8601, e.g. 2014-12-21 07:30:00)") from None
            booked[keep] = got
    else:
        booked = cols.numbers((BOOKED_COLUMN,))[:, 0]
    with np.errstate(invalid="ignore"):
        late = (booked > t) & (t >= 0)
    if late.any():
        i = int(np.flatnonzero(late)[0])
        raise ScenarioError(path, f"row {i + 1}",
                            f"{BOOKED_COLUMN} = {booked[i]:.6g} s is after the requested "
                            f"departure ({t[i]:.6g} s): a trip is booked at or before it departs")
    return booked


def snap_distances(trips: Trips, network) -> np.ndarray:
    """Per trip, metres from its pickup or drop-off (the farther) to the nearest node of
    ``network`` (0 for a trace of node ids)."""
    if trips.layout == "node":
        return np.zeros(len(trips))
    far = np.zeros(len(trips))
    for cols in (trips.origin, trips.dest):
        if cols is None:
            continue
        xy = cols[:, :2] if trips.layout == "metres" else \
            network.lonlat_to_xy(cols[:, 1], cols[:, 0])  # latitude, longitude columns
        far = np.maximum(far, network.nearest(xy)[1])
    return far


def within_snap(trips: Trips, network, max_snap: float) -> Trips:
    """The trips whose pickup and drop-off both lie within ``max_snap`` metres of a node of
    ``network``; the others are left out, counted in :attr:`Trips.dropped` (a point across a
    river from every street is not a request this network can serve)."""
    far = snap_distances(trips, network)
    return trips.subset(far <= max_snap, f"pickup or drop-off farther than tasks.max_snap = "
                                         f"{max_snap:g} m from the network")


#: traces shipped with the package, by the name a scenario's ``[tasks] trace`` may give
SHIPPED_TRACES = {"nyc_taxi_2014-12-21": "data/nyc_manhattan/nyc_taxi_2014-12-21_20k.csv"}


def shipped_trace(name: str) -> Path | None:
    """The path of a trace shipped with the package (:data:`SHIPPED_TRACES`), or None."""
    if name not in SHIPPED_TRACES:
        return None
    import importlib.resources

    return Path(str(importlib.resources.files("dispatch") / SHIPPED_TRACES[name]))


def read_fleet_start(path: Path, nodes: bool, default_z: float = math.nan,
                     max_bytes: int | None = None
                     ) -> tuple[tuple[int, float, float, float], ...]:
    """Rows ``(vehicle_id, a, b, c)``: where the space takes node ids (``nodes``, as
    :attr:`dispatch.api.space.Space.start_nodes` says) and the file has a ``node`` column, ``a``
    is a node id (``b``, ``c`` nan); else ``(a, b, c)`` metres, ``c`` from a ``z`` column or
    ``default_z`` (:attr:`dispatch.api.space.Space.start_z`)."""
    if path.suffix.lower() != ".csv":
        raise ScenarioError(path, "<file>", "a fleet start file must be a .csv file")
    table = Table(path, max_bytes)
    columns = set(table.names)
    if "vehicle_id" not in columns:
        raise table.after_rows(ScenarioError(path, "<header>", "missing column vehicle_id"))
    if nodes and "node" in columns:
        where = ("node",)
    elif "x" in columns and "y" in columns:
        where = ("x", "y") + (("z",) if "z" in columns else ())
    else:
        want = "node or x, y" if nodes else "x, y (and z)"
        raise table.after_rows(ScenarioError(path, "<header>", f"missing column(s): {want}"))
    cols = table.read(dict.fromkeys(where + ("vehicle_id",), NUMBER))
    pos = cols.numbers(where)
    ids = cols.numbers(("vehicle_id",))[:, 0]
    if len(ids) == 0:
        raise ScenarioError(path, "<file>", "places no vehicle")
    seen: set[int] = set()
    rows = []
    for i, (vid, p) in enumerate(zip(ids, pos), 1):
        if vid != int(vid) or vid < 0 or vid >= 2**63:
            raise ScenarioError(path, f"row {i}", f"vehicle_id {vid} is not an integer in "
                                                  "[0, 2^63)")
        if int(vid) in seen:
            raise ScenarioError(path, f"row {i}", f"vehicle_id {int(vid)} appears twice")
        seen.add(int(vid))
        p = list(p) + [math.nan] * (3 - len(p))
        if math.isnan(p[2]):
            p[2] = default_z
        rows.append((int(vid), *p))
    return tuple(rows)


def read_fleet_capacities(path: Path, max_bytes: int | None = None) -> tuple[int, ...]:
    """The optional ``capacity`` column of a fleet start file (seats per vehicle, in row
    order; blank: the scenario's ``[fleet] capacity``, given as 0); empty if there is none."""
    table = Table(path, max_bytes)
    if "capacity" not in table.names:
        table.read({})
        return ()
    seats = table.read({"capacity": NUMBER_OR_BLANK}).numbers(("capacity",))[:, 0]
    out = []
    for i, c in enumerate(seats, 1):
        if c != c:
            out.append(0)
        elif c < 1 or c != int(c) or c > 10_000:
            raise ScenarioError(path, f"row {i}", f"capacity = {c} is not a whole number of "
                                                  "seats in [1, 10000]")
        else:
            out.append(int(c))
    return tuple(out)
