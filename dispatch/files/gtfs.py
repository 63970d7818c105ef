"""GTFS feeds read for one service day: a zip of GTFS text files or a folder of them (the
shipped Manhattan subway feed, ``"nyc_subway"``, or a user's own), read with pyarrow's CSV
reader into index arrays (:class:`Feed`).

What one service day holds: the trips whose ``service_id`` runs on the date (``calendar.txt``:
the date in ``start_date .. end_date`` on a weekday flagged 1; then ``calendar_dates.txt``:
``exception_type`` 1 adds the service that date, 2 removes it; either file may be absent, not
both) and their calls (``stop_times.txt``), times in seconds on the service day's clock (GTFS
"noon minus 12 h": midnight except on the days clocks change); times past ``24:00:00`` are
trips of this service day running after midnight and are kept as such (``25:10:00`` =
90,600 s). The trips of the day before that run past its midnight are included too, 24 h
earlier (``25:10:00`` of the day before = 4,200 s; their calls before midnight negative), so
that the first hours of the day have the night's trains.

A call with neither time between two timed calls of its trip gets a time interpolated
linearly by call index; a call with one of the two times has both equal to it. A trip whose
first or last call has no time, whose times run backwards, or with a repeated
``stop_sequence`` is refused. ``transfers.txt`` (optional) keeps its rows of
``transfer_type`` 0, 1 and 2 (``min_transfer_time`` blank: NaN); rows naming trips or routes
(``from_trip_id`` ...) and the other types are left out.

Every problem is one :class:`~dispatch.errors.ScenarioError` line naming the feed and file
(``feed.zip:stop_times.txt``), the row (1-based data row) or column, and the reason: a missing
file or column, an unknown stop, trip, route or parent station id, a bad time, date or
coordinate.
"""

from __future__ import annotations

import codecs
import csv
import datetime as dt
import functools
import logging
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dispatch.errors import ScenarioError

log = logging.getLogger(__name__)

#: the shipped feeds, by the name a scenario gives
SHIPPED = {"nyc_subway": ("nyc_subway", "manhattan_subway.zip")}
WEEKDAYS = ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday")
#: a GTFS time: hours of any width (past 24 allowed), minutes and seconds of two digits
TIME = r"^\s*(?P<h>\d{1,3}):(?P<m>[0-5]\d):(?P<s>[0-5]\d)\s*$"
DAY = 86400.0


@dataclass(frozen=True, eq=False)
class Feed:
    """One service day of a GTFS feed, as index arrays.

    ``stop_*``: every stop of ``stops.txt`` in file order (``stop_parent``: the row of its
    ``parent_station``, -1 for none; ``stop_lon`` / ``stop_lat`` NaN where the file gives none,
    which it may for nodes and boarding areas only). ``route_ids``: every route. ``trip_*``:
    the trips that run on ``service_date`` and call at least twice, in file order, then those
    of the day before still running after its midnight (``trip_day`` -1, their times less
    24 h; 0 for the day's own; a trip id may so appear twice); ``trip_route``: a row of
    ``route_ids``. ``call_*``: their calls, by trip then
    ``stop_sequence`` (``call_trip``: a row of ``trip_ids``; ``call_stop``: a row of
    ``stop_ids``; ``call_arrival`` / ``call_departure``: seconds on the service day's clock,
    ``arrival <= departure <=`` the next call's arrival). ``transfer_*``: rows of
    ``transfers.txt`` (stop rows; ``transfer_seconds`` NaN where none is given)."""

    source: str
    service_date: dt.date
    stop_ids: np.ndarray
    stop_names: np.ndarray
    stop_lon: np.ndarray
    stop_lat: np.ndarray
    stop_parent: np.ndarray
    route_ids: np.ndarray
    trip_ids: np.ndarray
    trip_route: np.ndarray
    trip_day: np.ndarray
    call_trip: np.ndarray
    call_stop: np.ndarray
    call_arrival: np.ndarray
    call_departure: np.ndarray
    transfer_from: np.ndarray
    transfer_to: np.ndarray
    transfer_seconds: np.ndarray

    def __repr__(self) -> str:
        return (f"Feed({self.source!r}, {self.service_date.isoformat()}: {self.stop_ids.size} "
                f"stops, {self.trip_ids.size} trips, {self.call_trip.size} calls)")


class _Source:
    """The member files of a feed, a zip (members at its top or in one folder) or a folder."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.zip = None
        if path.is_dir():
            self.names = {p.name: p for p in path.iterdir() if p.suffix == ".txt"}
            return
        try:
            self.zip = zipfile.ZipFile(path)
        except FileNotFoundError:
            raise ScenarioError(path, "<file>", "cannot be read: file not found") from None
        except (OSError, zipfile.BadZipFile) as e:
            raise ScenarioError(path, "<file>", f"is not a GTFS zip or folder ({e})") from None
        self.names = {}
        for info in self.zip.infolist():
            parts = info.filename.strip("/").split("/")
            if (not info.is_dir() and parts[-1].endswith(".txt") and len(parts) <= 2
                    and not parts[0].startswith("__MACOSX")):
                self.names.setdefault(parts[-1], info.filename)

    def label(self, name: str) -> str:
        return f"{self.path}:{name}" if self.zip is not None else str(self.path / name)

    def has(self, name: str) -> bool:
        return name in self.names

    def read(self, name: str, required: tuple[str, ...], optional: tuple[str, ...] = ()):
        """``{column: pyarrow string array}`` of the file's ``required`` columns (a missing file
        or column is an error) and the ``optional`` ones it has (cells stripped of spaces)."""
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.csv as pcsv

        label = self.label(name)
        if name not in self.names:
            raise ScenarioError(label, "<file>", "is missing from the feed")
        try:
            data = (self.zip.read(self.names[name]) if self.zip is not None
                    else self.names[name].read_bytes())
        except (OSError, zipfile.BadZipFile) as e:
            raise ScenarioError(label, "<file>", f"cannot be read ({e})") from None
        data = data.removeprefix(codecs.BOM_UTF8)
        first = data.split(b"\n", 1)[0].decode("utf-8", "replace")
        header = [c.strip() for c in next(csv.reader([first]), [])]
        missing = [c for c in required if c not in header]
        if missing:
            raise ScenarioError(label, missing[0], f"column is missing (the header has "
                                                   f"{', '.join(header) or 'no columns'})")
        names = [f"{c}\x00{i}" if c in header[:i] else c for i, c in enumerate(header)]
        keep = [c for c in (*required, *optional) if c in header]
        try:
            table = pcsv.read_csv(
                pa.py_buffer(data),
                read_options=pcsv.ReadOptions(column_names=names, skip_rows=1),
                convert_options=pcsv.ConvertOptions(
                    column_types={c: pa.string() for c in names}, strings_can_be_null=False,
                    include_columns=keep))
        except (pa.ArrowInvalid, UnicodeDecodeError) as e:
            raise ScenarioError(label, "<file>", f"is not a readable CSV file "
                                                 f"({str(e).splitlines()[0]})") from None
        return {c: pc.utf8_trim_whitespace(table.column(c).combine_chunks()) for c in keep}


def _array(arr, dtype) -> np.ndarray:
    """A numeric or boolean pyarrow array as numpy (its null cells' values undefined: callers
    raise on them first), copied from its buffers: pyarrow's own conversion imports pandas,
    which a run never loads (so does any Python scalar handed to pyarrow)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if pa.types.is_boolean(arr.type):
        arr = pc.cast(arr, pa.int8())
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    kind = np.dtype(arr.type.to_pandas_dtype())
    return np.frombuffer(arr.buffers()[1], dtype=kind, count=len(arr),
                         offset=arr.offset * kind.itemsize).astype(dtype)


def _blank(values) -> np.ndarray:
    """Which cells of a pyarrow string array are empty (without a Python scalar, whose
    conversion imports pandas)."""
    import pyarrow.compute as pc

    return _array(pc.utf8_length(values), np.int64) == 0


def _bad(label: str, column: str, mask: np.ndarray, values, reason: str) -> None:
    """Raise the first row where ``mask`` is True: ``row N: column 'value' reason``."""
    rows = np.flatnonzero(mask)
    if rows.size:
        i = int(rows[0])
        more = f" (and {rows.size - 1} more rows)" if rows.size > 1 else ""
        raise ScenarioError(label, f"row {i + 1}",
                            f"{column} {str(values[i])!r} {reason}{more}")


def _index(src: _Source, name: str, column: str, values, keys, what: str):
    """Rows of ``keys`` (a pyarrow string array) of ``values``; an unknown id is an error."""
    import pyarrow.compute as pc

    idx = pc.index_in(values, value_set=keys)
    missing = _array(idx.is_null(), bool)
    _bad(src.label(name), column, missing, values, f"names no {what}")
    return _array(idx, np.int64)


def _numbers(src: _Source, name: str, column: str, values, lo: float, hi: float, *,
             blank_ok: np.ndarray | None = None) -> np.ndarray:
    """Floats of a column (within ``[lo, hi]``); blank is NaN where ``blank_ok``."""
    out = np.full(len(values), np.nan)
    cells = values.to_pylist()
    for i, cell in enumerate(cells):
        if cell == "" and blank_ok is not None and blank_ok[i]:
            continue
        try:
            v = float(cell)
        except ValueError:
            v = np.nan
        if not lo <= v <= hi:
            raise ScenarioError(src.label(name), f"row {i + 1}",
                                f"{column} {cell!r} is not a number in [{lo:g}, {hi:g}]")
        out[i] = v
    return out


def _date(label: str, key: str, text: str) -> dt.date:
    try:
        return dt.datetime.strptime(text, "%Y%m%d").date()
    except ValueError:
        raise ScenarioError(label, key, f"{text!r} is not a date YYYYMMDD") from None


def _services(src: _Source, day: dt.date, *, required: bool = True) -> set[str]:
    """The service ids that run on ``day`` (see the module's docstring); none is an error
    where ``required``."""
    if not src.has("calendar.txt") and not src.has("calendar_dates.txt"):
        raise ScenarioError(src.label("calendar.txt"), "<file>",
                            "is missing, and so is calendar_dates.txt: a feed needs one")
    on: set[str] = set()
    span = []
    if src.has("calendar.txt"):
        cal = src.read("calendar.txt", ("service_id", *WEEKDAYS, "start_date", "end_date"))
        label = src.label("calendar.txt")
        cols = {k: v.to_pylist() for k, v in cal.items()}
        for i, sid in enumerate(cols["service_id"]):
            start = _date(label, f"row {i + 1}", cols["start_date"][i])
            end = _date(label, f"row {i + 1}", cols["end_date"][i])
            span += [start, end]
            flag = cols[WEEKDAYS[day.weekday()]][i]
            if flag not in ("0", "1"):
                raise ScenarioError(label, f"row {i + 1}",
                                    f"{WEEKDAYS[day.weekday()]} {flag!r} is not 0 or 1")
            if start <= day <= end and flag == "1":
                on.add(sid)
    if src.has("calendar_dates.txt"):
        ex = src.read("calendar_dates.txt", ("service_id", "date", "exception_type"))
        label = src.label("calendar_dates.txt")
        for i, (sid, d, kind) in enumerate(zip(*(ex[c].to_pylist() for c in
                                                 ("service_id", "date", "exception_type")))):
            when = _date(label, f"row {i + 1}", d)
            span.append(when)
            if kind not in ("1", "2"):
                raise ScenarioError(label, f"row {i + 1}",
                                    f"exception_type {kind!r} is not 1 (added) or 2 (removed)")
            if when == day:
                (on.add if kind == "1" else on.discard)(sid)
    if not on and required:
        covers = f" (its dates run from {min(span)} to {max(span)})" if span else ""
        raise ScenarioError(src.label("calendar.txt" if src.has("calendar.txt")
                                      else "calendar_dates.txt"), "service_date",
                            f"no service runs on {day.isoformat()}{covers}")
    return on


def _times(label: str, column: str, values) -> np.ndarray:
    """Seconds of GTFS times (NaN for blank); anything else blank or H:MM:SS is an error."""
    import pyarrow.compute as pc

    parts = pc.extract_regex(values, TIME)
    valid = parts.is_valid()
    ok = _array(valid, bool)
    blank = _blank(values)
    _bad(label, column, ~ok & ~blank, values, "is not a time H:MM:SS")
    out = np.full(len(values), np.nan)
    if ok.any():
        hms = [_array(pc.cast(parts.field(k).filter(valid), "int64"), np.float64)
               for k in ("h", "m", "s")]
        out[ok] = hms[0] * 3600 + hms[1] * 60 + hms[2]
    return out


def _fill(label: str, trip_ids: np.ndarray, trip: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Interpolate untimed calls (NaN) linearly by index between the timed calls around them
    in the same trip (calls sorted by trip); a trip's first or last call untimed is an error."""
    n = t.size
    timed = ~np.isnan(t)
    first = np.r_[True, trip[1:] != trip[:-1]]
    last = np.r_[trip[1:] != trip[:-1], True]
    bad = (first | last) & ~timed
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ScenarioError(label, "arrival_time", f"trip {trip_ids[trip[k]]!r}: its "
                                                   f"{'first' if first[k] else 'last'} call "
                                                   "has no time")
    if timed.all():
        return t
    pos = np.arange(n)
    prev = np.maximum.accumulate(np.where(timed, pos, 0))
    nxt = np.minimum.accumulate(np.where(timed, pos, n - 1)[::-1])[::-1]
    frac = (pos - prev) / np.maximum(nxt - prev, 1)
    return np.where(timed, t, np.round(t[prev] + frac * (t[nxt] - t[prev])))


def _calls(src: _Source, stops, trips_all, keep_trip: np.ndarray):
    """``(trip, stop, arrival, departure)`` of the calls of the kept trips, sorted by trip and
    ``stop_sequence`` (rows of ``trips_all`` / ``stops``), checked."""
    import pyarrow.compute as pc

    name = "stop_times.txt"
    label = src.label(name)
    st = src.read(name, ("trip_id", "arrival_time", "departure_time", "stop_id",
                         "stop_sequence"))
    trip = _index(src, name, "trip_id", st["trip_id"], trips_all["trip_id"], "trip of trips.txt")
    stop = _index(src, name, "stop_id", st["stop_id"], stops["stop_id"], "stop of stops.txt")
    seq_ok = _array(pc.match_substring_regex(st["stop_sequence"], r"^\d{1,9}$"), bool)
    _bad(label, "stop_sequence", ~seq_ok, st["stop_sequence"], "is not a whole number >= 0")
    seq = _array(pc.cast(st["stop_sequence"], "int64"), np.int64)
    arr = _times(label, "arrival_time", st["arrival_time"])
    dep = _times(label, "departure_time", st["departure_time"])
    arr, dep = np.where(np.isnan(arr), dep, arr), np.where(np.isnan(dep), arr, dep)
    rows = np.flatnonzero(keep_trip[trip])
    rows = rows[np.lexsort((seq[rows], trip[rows]))]
    trip, stop, seq, arr, dep = trip[rows], stop[rows], seq[rows], arr[rows], dep[rows]
    ids = np.asarray(trips_all["trip_id"].to_pylist(), dtype=object)
    same = trip[1:] == trip[:-1]
    dup = np.flatnonzero(same & (seq[1:] == seq[:-1]))
    if dup.size:
        k = int(dup[0])
        raise ScenarioError(label, "stop_sequence", f"trip {ids[trip[k]]!r} has stop_sequence "
                                                    f"{int(seq[k])} twice")
    arr, dep = _fill(label, ids, trip, arr), _fill(label, ids, trip, dep)
    back = np.flatnonzero((dep < arr) | np.r_[same & (arr[1:] < dep[:-1]), False])
    if back.size:
        k = int(back[0])
        raise ScenarioError(label, "arrival_time", f"trip {ids[trip[k]]!r}: times run "
                                                   f"backwards after stop_sequence "
                                                   f"{int(seq[k])}")
    return trip, stop, arr, dep


def _stops(src: _Source):
    """``(columns, lon, lat, parent)`` of ``stops.txt``, checked."""
    import pyarrow as pa
    import pyarrow.compute as pc

    name = "stops.txt"
    stops = src.read(name, ("stop_id",), ("stop_name", "stop_lat", "stop_lon",
                                          "location_type", "parent_station"))
    n = len(stops["stop_id"])
    counts = pc.value_counts(stops["stop_id"])
    twice = [v for v, c in zip(counts.field("values").to_pylist(),
                               counts.field("counts").to_pylist()) if c > 1]
    if twice:
        raise ScenarioError(src.label(name), "stop_id", f"{twice[0]!r} appears twice")
    kind = (np.asarray(stops["location_type"].to_pylist(), dtype=object)
            if "location_type" in stops else np.full(n, "", dtype=object))
    blank_ok = np.isin(kind, ["3", "4"])  # generic nodes and boarding areas need no place
    for c in ("stop_lat", "stop_lon"):
        if c not in stops:
            raise ScenarioError(src.label(name), c, "column is missing")
    lat = _numbers(src, name, "stop_lat", stops["stop_lat"], -90, 90, blank_ok=blank_ok)
    lon = _numbers(src, name, "stop_lon", stops["stop_lon"], -180, 180, blank_ok=blank_ok)
    parent = np.full(n, -1, dtype=np.int64)
    if "parent_station" in stops:
        has = ~_blank(stops["parent_station"])
        if has.any():
            rows = np.flatnonzero(has)
            sub = stops["parent_station"].filter(
                pc.cast(pc.utf8_length(stops["parent_station"]), pa.bool_()))
            idx = pc.index_in(sub, value_set=stops["stop_id"])
            bad = np.zeros(n, dtype=bool)
            bad[rows] = _array(idx.is_null(), bool)
            _bad(src.label(name), "parent_station", bad, stops["parent_station"],
                 "names no stop of stops.txt")
            parent[rows] = _array(idx, np.int64)
    return stops, lon, lat, parent


def _transfers(src: _Source, stops) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(from, to, seconds)`` rows of ``transfers.txt`` kept (see the module's docstring)."""

    name = "transfers.txt"
    if not src.has(name):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    tr = src.read(name, ("from_stop_id", "to_stop_id"),
                  ("transfer_type", "min_transfer_time", "from_trip_id", "to_trip_id",
                   "from_route_id", "to_route_id"))
    n = len(tr["from_stop_id"])
    keep = np.ones(n, dtype=bool)
    for c in ("from_trip_id", "to_trip_id", "from_route_id", "to_route_id"):
        if c in tr:
            keep &= _blank(tr[c])
    if "transfer_type" in tr:
        keep &= np.isin(np.asarray(tr["transfer_type"].to_pylist(), dtype=object),
                        ["", "0", "1", "2"])
    if not keep.all():
        log.info("%s: %d rows of other transfer types or naming trips or routes left out",
                 src.label(name), int((~keep).sum()))
    a = _index(src, name, "from_stop_id", tr["from_stop_id"], stops["stop_id"],
               "stop of stops.txt")
    b = _index(src, name, "to_stop_id", tr["to_stop_id"], stops["stop_id"], "stop of stops.txt")
    secs = (_numbers(src, name, "min_transfer_time", tr["min_transfer_time"], 0, 86400,
                     blank_ok=np.ones(n, dtype=bool)) if "min_transfer_time" in tr
            else np.full(n, np.nan))
    return a[keep], b[keep], secs[keep]


def read_gtfs(path: str | Path, service_date: dt.date) -> Feed:
    """The feed at ``path`` (a GTFS zip or folder) for ``service_date``, checked (module
    docstring); ScenarioError, one line naming the file, for anything wrong."""
    path = Path(path)
    src = _Source(path)
    services = _services(src, service_date)
    stops, lon, lat, parent = _stops(src)
    routes = src.read("routes.txt", ("route_id",))
    trips = src.read("trips.txt", ("route_id", "service_id", "trip_id"))
    route = _index(src, "trips.txt", "route_id", trips["route_id"], routes["route_id"],
                   "route of routes.txt")
    before = _services(src, service_date - dt.timedelta(days=1), required=False)
    sids = trips["service_id"].to_pylist()
    on = np.fromiter((sid in services for sid in sids), dtype=bool, count=len(sids))
    prev = np.fromiter((sid in before for sid in sids), dtype=bool, count=len(sids))
    trip, stop, arr, dep = _calls(src, stops, trips, on | prev)
    late = np.zeros(len(sids), dtype=bool)
    late[trip[dep >= DAY]] = True  # the day before's trips still running after midnight
    kept, day, calls = [], [], []
    for offset, mask in ((0, on), (-1, prev & late)):
        rows = np.flatnonzero(mask[trip])
        uniq, counts = np.unique(trip[rows], return_counts=True)
        uniq = uniq[counts >= 2]
        row = np.full(len(sids), -1, dtype=np.int64)
        row[uniq] = sum(k.size for k in kept) + np.arange(uniq.size)
        rows = rows[row[trip[rows]] >= 0]
        calls.append((row[trip[rows]], stop[rows], arr[rows] + offset * DAY,
                      dep[rows] + offset * DAY))
        kept.append(uniq)
        day.append(np.full(uniq.size, offset, dtype=np.int64))
    kept_rows = np.concatenate(kept)
    c_trip, c_stop, c_arr, c_dep = (np.concatenate(x) for x in zip(*calls))
    t_from, t_to, t_secs = _transfers(src, stops)
    feed = Feed(source=str(path), service_date=service_date,
                stop_ids=np.asarray(stops["stop_id"].to_pylist(), dtype=object),
                stop_names=np.asarray((stops.get("stop_name") or stops["stop_id"]).to_pylist(),
                                      dtype=object),
                stop_lon=lon, stop_lat=lat, stop_parent=parent,
                route_ids=np.asarray(routes["route_id"].to_pylist(), dtype=object),
                trip_ids=np.asarray(trips["trip_id"].to_pylist(), dtype=object)[kept_rows],
                trip_route=route[kept_rows], trip_day=np.concatenate(day), call_trip=c_trip,
                call_stop=c_stop, call_arrival=c_arr, call_departure=c_dep,
                transfer_from=t_from, transfer_to=t_to, transfer_seconds=t_secs)
    log.info("%r", feed)
    return feed


def load_feed(path: str | Path, service_date: dt.date) -> Feed:
    """:func:`read_gtfs`, read once per (resolved path, modification time, day): the scenario's
    check and the run share one read; an edited feed is read again."""
    path = Path(path).resolve()
    try:
        mtime = os.stat(path).st_mtime_ns
    except OSError:
        mtime = -1  # read_gtfs says what is wrong
    return _cached(str(path), mtime, service_date)


@functools.lru_cache(maxsize=4)
def _cached(path: str, mtime: int, service_date: dt.date) -> Feed:
    return read_gtfs(path, service_date)


def feed_path(source: str, base: Path) -> Path:
    """The feed a scenario names: a shipped one (``"nyc_subway"``) or a path relative to
    ``base`` (the scenario's folder)."""
    if source in SHIPPED:
        folder, name = SHIPPED[source]
        return Path(__file__).resolve().parents[1] / "data" / folder / name
    p = Path(source).expanduser()
    return p if p.is_absolute() else base / p
