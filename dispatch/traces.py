"""Input files of a scenario: trip traces and fleet start files, validated row by row.

A **trace** (CSV or Parquet) holds one trip per row: its release time ``t`` (or
``release_time``, seconds; or ``departure_time``, a date-time read as seconds from the
scenario's ``[tasks] start``), its pickup and, optionally, its drop-off, and an optional
``max_wait`` and ``max_delay`` (seconds; blank: the scenario's) and ``passengers`` (a whole
number >= 1; blank: 1). Other columns (``request_id``, ...) are ignored. Where things are, by
space:

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

import codecs
import csv
import io
import math
import operator
import os
import stat
from dataclasses import dataclass, fields, replace
from datetime import date, datetime
from pathlib import Path

import numpy as np

from dispatch.errors import ScenarioError

TIME_COLUMNS = ("t", "release_time", "departure_time")
#: the time column given as date-times (seconds from ``[tasks] start``)
DATETIME_COLUMN = "departure_time"
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
    #: trips of the file left out, as ``(reason, count)`` pairs (before ``[tasks] start``;
    #: farther than ``[tasks] max_snap`` from the network): stored with the results
    dropped: tuple[tuple[str, int], ...] = ()

    def __len__(self) -> int:
        return len(self.t)

    def subset(self, keep: np.ndarray, reason: str) -> Trips:
        """The trips where ``keep`` (a boolean mask) holds, the others counted under
        ``reason`` in :attr:`dropped` (every per-trip array is cut alike)."""
        keep = np.asarray(keep, dtype=bool)
        n_out = int(keep.size - keep.sum())
        if n_out == 0:
            return self
        cut = {f.name: getattr(self, f.name)[keep] for f in fields(self)
               if isinstance(getattr(self, f.name), np.ndarray)
               and getattr(self, f.name).shape[:1] == keep.shape}
        return replace(self, **cut, dropped=self.dropped + ((reason, n_out),))


#: byte order marks of encodings other than UTF-8 (longest first: UTF-32 LE starts as UTF-16 LE)
BOMS = ((codecs.BOM_UTF32_LE, "UTF-32 LE"), (codecs.BOM_UTF32_BE, "UTF-32 BE"),
        (codecs.BOM_UTF16_LE, "UTF-16 LE"), (codecs.BOM_UTF16_BE, "UTF-16 BE"))


def check_file(path: Path, max_bytes: int | None, what: str = "file") -> int:
    """Stat ``path`` before reading it: it must exist, be a regular file (not a device, a
    FIFO or a folder) and hold at most ``max_bytes`` (None: no bound). Returns its size."""
    try:
        st = os.stat(path)
    except OSError as e:
        reason = "cannot be read: file not found" if isinstance(e, FileNotFoundError) else \
            f"cannot be read ({e.strerror or e})"
        raise ScenarioError(path, "<file>", reason) from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a device, pipe or socket"
        raise ScenarioError(path, "<file>", f"is {kind}, not a regular {what}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise ScenarioError(path, "<file>", f"is {st.st_size / 2**20:.1f} MiB; a {what} of "
                                            f"more than {max_bytes / 2**20:.0f} MiB is refused "
                                            "(use --force to read it anyway)")
    return st.st_size


def read_bytes(path: Path, max_bytes: int | None, what: str = "file") -> bytes:
    """The bytes of a regular file checked by :func:`check_file` (read at most the size it
    had, plus one byte: a file that grows meanwhile is refused, not read without end)."""
    size = check_file(path, max_bytes, what)
    try:
        with open(path, "rb") as fh:
            data = fh.read(size + 1 if max_bytes is None else max(size, max_bytes) + 1)
    except OSError as e:
        raise ScenarioError(path, "<file>", f"cannot be read ({e.strerror or e})") from None
    if max_bytes is not None and len(data) > max_bytes:
        raise ScenarioError(path, "<file>", f"grew past {max_bytes / 2**20:.0f} MiB while read")
    return data


def decode_text(path: Path, data: bytes) -> str:
    """UTF-8 text (a UTF-8 byte order mark is dropped); one-line errors for a UTF-16/32 file
    (named by its byte order mark) and for bytes that are not UTF-8."""
    for bom, name in BOMS:
        if data.startswith(bom):
            raise ScenarioError(path, "<encoding>", f"is {name} text (it starts with the byte "
                                                    f"order mark {bom.hex(' ').upper()}); save "
                                                    "it as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise ScenarioError(path, "<encoding>", f"is not UTF-8 text (byte 0x{data[e.start]:02X} "
                                                f"on line {line}, offset {e.start}); save it "
                                                "as UTF-8") from None


#: rows converted at a time while a CSV file is read (the cells of one chunk are held as
#: strings; the file's columns only as numbers)
CHUNK_ROWS = 32_768
#: what :meth:`Table.read` makes of a column: numbers (a blank cell is an error), numbers where
#: a blank cell is nan, or the cells as read (date-times: parsed by the caller)
NUMBER, NUMBER_OR_BLANK, CELLS = "number", "number_or_blank", "cells"


def _cell_number(path: Path, name: str, i: int, v, blank_ok: bool) -> float:
    """One cell as a float (nan for a blank one where ``blank_ok``); a bad one names its
    1-based data row (``i`` is 0-based)."""
    if blank_ok and (v is None or (isinstance(v, str) and not v.strip())):
        return math.nan
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ScenarioError(path, f"row {i + 1}", f"{name} is not a number ({v!r})") from None
    if not math.isfinite(f):
        raise ScenarioError(path, f"row {i + 1}", f"{name} is not finite ({v!r})")
    return f


class Columns:
    """The columns :meth:`Table.read` converted: numbers as float arrays, cells as lists. A
    column's first bad cell is kept (not raised) until the column is asked for, so that the
    error a reader sees is the one of the first column it checks, whatever the rows' order."""

    def __init__(self, path: Path, n: int, numbers: dict[str, np.ndarray],
                 cells: dict[str, list], errors: dict[str, ScenarioError]) -> None:
        self.path, self.n = path, n
        self._numbers, self._cells, self._errors = numbers, cells, errors

    def numbers(self, names) -> np.ndarray:
        """The named columns as a float array ``(rows, len(names))``; the first bad cell of the
        first column (in ``names``' order) that has one raises its ScenarioError."""
        for name in names:
            if name in self._errors:
                raise self._errors[name]
        if not names:
            return np.empty((self.n, 0))
        return np.column_stack([self._numbers[name] for name in names])

    def cells(self, name: str) -> list:
        """The cells of a column read as :data:`CELLS`."""
        return self._cells[name]


class Table:
    """A CSV or Parquet table file, its header read: :attr:`names` are its columns, and
    :meth:`read` converts the columns asked for. A CSV file is read in chunks of rows, so a
    large trace is held as arrays of numbers, never as a string per cell (the parsing rules
    are the ``csv`` module's: blank lines skipped, a short row's missing cells blank, a
    repeated column name meaning its last column)."""

    def __init__(self, path: Path, max_bytes: int | None = None) -> None:
        check_file(path, max_bytes, "table file")
        self.path = path
        suffix = path.suffix.lower()
        if suffix not in (".csv", ".parquet"):
            raise ScenarioError(path, "<file>", "must be a .csv or .parquet file")
        self._arrow = None
        self._rows = None
        try:
            if suffix == ".parquet":
                import pyarrow.parquet as pq

                self._arrow = pq.read_table(path)
                self.names = list(self._arrow.column_names)
            else:
                data = read_bytes(path, max_bytes, "table file")
                decode_text(path, data)  # the encoding checks; the text is read again in rows
                self._rows = csv.reader(io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig",
                                                         newline=""))
                self.names = next(self._rows, None) or []
        except ScenarioError:
            raise
        except Exception as e:  # pyarrow and csv raise several kinds for a malformed file
            raise ScenarioError(path, "<file>", f"cannot be read as a table: {e}") from None

    def read(self, want: dict[str, str]) -> Columns:
        """Read the rows, converting each column of ``want`` (a column of the header, by
        name) as its kind says (:data:`NUMBER`, :data:`NUMBER_OR_BLANK`, :data:`CELLS`). A
        CSV file's rows are read once: ``read({})`` only checks that the rest of the file
        parses."""
        try:
            if self._arrow is not None:
                return self._read_arrow(want)
            return self._read_csv(want)
        except ScenarioError:
            raise
        except Exception as e:  # pyarrow and csv raise several kinds for a malformed file
            raise ScenarioError(self.path, "<file>", f"cannot be read as a table: {e}") from None

    def _read_arrow(self, want: dict[str, str]) -> Columns:
        import pyarrow as pa

        numbers, cells, errors = {}, {}, {}
        n = self._arrow.num_rows
        for name, kind in want.items():
            col = self._arrow.column(name)
            if kind == CELLS:
                cells[name] = col.to_pylist()
                continue
            if (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)) \
                    and col.null_count == 0:
                values = col.to_numpy().astype(np.float64)
                if np.isfinite(values).all():
                    numbers[name] = values
                    continue
            numbers[name] = self._slow(name, col.to_pylist(), 0, kind == NUMBER_OR_BLANK,
                                       errors)
        return Columns(self.path, n, numbers, cells, errors)

    def _slow(self, name: str, values, first: int, blank_ok: bool,
              errors: dict[str, ScenarioError]) -> np.ndarray:
        """Cell by cell (rows ``first``, ``first + 1``, ...); a bad cell is nan, the column's
        first one kept in ``errors``."""
        out = np.empty(len(values))
        for i, v in enumerate(values, first):
            try:
                out[i - first] = _cell_number(self.path, name, i, v, blank_ok)
            except ScenarioError as e:
                errors.setdefault(name, e)
                out[i - first] = math.nan
        return out

    def _read_csv(self, want: dict[str, str]) -> Columns:
        # DictReader's rules: the last column of a repeated name; None past a short row's end
        where = {name: max(j for j, h in enumerate(self.names) if h == name) for name in want}
        parts: dict[str, list] = {name: [] for name in want}
        errors: dict[str, ScenarioError] = {}
        dedup: dict = {}
        n = 0
        chunk: list[list[str]] = []
        for row in self._rows:
            if not row:
                continue  # a blank line (csv.DictReader skips them too)
            chunk.append(row)
            if len(chunk) == CHUNK_ROWS:
                self._convert(chunk, n, want, where, parts, errors, dedup)
                n += len(chunk)
                chunk = []
        if chunk:
            self._convert(chunk, n, want, where, parts, errors, dedup)
            n += len(chunk)
        numbers = {name: np.concatenate(p) if p else np.empty(0) for name, p in parts.items()
                   if want[name] != CELLS}
        cells = {name: [v for p in parts[name] for v in p] for name in want
                 if want[name] == CELLS}
        return Columns(self.path, n, numbers, cells, errors)

    def _convert(self, chunk: list[list[str]], first: int, want: dict[str, str],
                 where: dict[str, int], parts: dict[str, list],
                 errors: dict[str, ScenarioError], dedup: dict) -> None:
        width = min(map(len, chunk))
        for name, kind in want.items():
            j = where[name]
            values = list(map(operator.itemgetter(j), chunk)) if j < width else \
                [r[j] if j < len(r) else None for r in chunk]
            if kind == CELLS:
                parts[name].append([dedup.setdefault(v, v) for v in values])
                continue
            try:  # the usual case: every cell a finite number
                got = np.fromiter(map(float, values), np.float64, len(values))
                fine = bool(np.isfinite(got).all())
            except (TypeError, ValueError):
                fine = False
            if not fine:
                got = self._slow(name, values, first, kind == NUMBER_OR_BLANK, errors)
            parts[name].append(got)


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
            s0 = start
            if (d.tzinfo is None) != (s0.tzinfo is None):
                if d.tzinfo is None:
                    d = d.replace(tzinfo=s0.tzinfo)
                else:
                    s0 = s0.replace(tzinfo=d.tzinfo)
            got = (d - s0).total_seconds()
            if key is not None:
                seen[key] = got
        out[i] = got
    return out


def read_trace(path: Path, space: str, size: tuple[float, float, float] | None,
               max_bytes: int | None = None, *, start: datetime | None = None) -> Trips:
    """Read and validate a trip trace for a ``space`` (``"voxel"``: ``size`` is the world's);
    a file of more than ``max_bytes`` is refused before it is read. A ``departure_time``
    column (date-times) needs ``start``: times are seconds from it, and trips departing before
    it are left out (counted in :attr:`Trips.dropped`)."""
    table = Table(path, max_bytes)
    columns = set(table.names)
    tcol = next((c for c in TIME_COLUMNS if c in columns), None)
    layout = next((lay for lay in LAYOUTS[space] if all(c in columns for c in lay[1])), None)
    if tcol is None or layout is None:
        if len(LAYOUTS[space]) == 1:
            wanted = [c for c in LAYOUTS[space][0][1] if c not in columns]
        else:
            wanted = [" or ".join("(" + ", ".join(lay[1]) + ")" for lay in LAYOUTS[space])]
        missing = ([] if layout else wanted) + (
            [] if tcol else ["release_time (or t, or departure_time)"])
        raise _after_rows(table, ScenarioError(path, "<header>",
                                               f"missing column(s): {', '.join(missing)}"))
    name, pick, drop = layout
    has_dest = all(c in columns for c in drop)
    if not has_dest and any(c in columns for c in drop):
        raise _after_rows(table, ScenarioError(path, "<header>",
                                               f"drop-off needs all of {', '.join(drop)}"))
    if tcol == DATETIME_COLUMN and start is None:
        raise _after_rows(table, ScenarioError(
            path, DATETIME_COLUMN, "holds date-times: set [tasks] start (e.g. start = "
            "\"2014-12-21T00:00\") in the scenario, the time the run's second 0 stands for"))
    if tcol != DATETIME_COLUMN and start is not None:
        raise _after_rows(table, ScenarioError(
            path, tcol, "gives times in seconds; [tasks] start is only used with a "
            f"{DATETIME_COLUMN} column of date-times"))
    optional = [c for c in ("max_wait", "max_delay", "passengers") if c in columns]
    cols = table.read({tcol: CELLS if tcol == DATETIME_COLUMN else NUMBER,
                       **{c: NUMBER for c in pick + (drop if has_dest else ())},
                       **{c: NUMBER_OR_BLANK for c in optional}})
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
    del cols
    early = t < 0 if tcol == DATETIME_COLUMN else np.zeros(len(t), dtype=bool)

    def check_row(i: int) -> None:
        """Raise the first error of row ``i`` (0-based), if it has one."""
        if max_delay[i] < 0:
            raise ScenarioError(path, f"row {i + 1}", f"max_delay {max_delay[i]} is negative")
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
                  passengers[order].astype(np.int64), max_delay[order])
    if early.any():
        trips = trips.subset(~early[order], f"departed before tasks.start ({start.isoformat()})")
    if early.any() and not len(trips):
        raise ScenarioError(path, DATETIME_COLUMN, f"no trip departs at or after tasks.start "
                                                   f"({start.isoformat()})")
    return trips


def _after_rows(table: Table, error: ScenarioError) -> ScenarioError:
    """``error``, once the rest of ``table`` is read (a file that does not parse says so
    before a header's error does)."""
    table.read({})
    return error


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
    :attr:`dispatch.space.Space.start_nodes` says) and the file has a ``node`` column, ``a``
    is a node id (``b``, ``c`` nan); else ``(a, b, c)`` metres, ``c`` from a ``z`` column or
    ``default_z`` (:attr:`dispatch.space.Space.start_z`)."""
    if path.suffix.lower() != ".csv":
        raise ScenarioError(path, "<file>", "a fleet start file must be a .csv file")
    table = Table(path, max_bytes)
    columns = set(table.names)
    if "vehicle_id" not in columns:
        raise _after_rows(table, ScenarioError(path, "<header>", "missing column vehicle_id"))
    if nodes and "node" in columns:
        where = ("node",)
    elif "x" in columns and "y" in columns:
        where = ("x", "y") + (("z",) if "z" in columns else ())
    else:
        want = "node or x, y" if nodes else "x, y (and z)"
        raise _after_rows(table, ScenarioError(path, "<header>", f"missing column(s): {want}"))
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
