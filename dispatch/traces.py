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


def _read_columns(path: Path, max_bytes: int | None = None) -> dict[str, list]:
    check_file(path, max_bytes, "table file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            return pq.read_table(path).to_pydict()
        if suffix == ".csv":
            text = decode_text(path, read_bytes(path, max_bytes, "table file"))
            reader = csv.DictReader(io.StringIO(text, newline=""))
            data = list(reader)
            names = reader.fieldnames or []
            return {n: [r.get(n) for r in data] for n in names}
    except ScenarioError:
        raise
    except Exception as e:  # pyarrow and csv raise several kinds for a malformed file
        raise ScenarioError(path, "<file>", f"cannot be read as a table: {e}") from None
    raise ScenarioError(path, "<file>", "must be a .csv or .parquet file")


def _numbers(path: Path, columns: dict[str, list], names, *, blank_ok: bool = False) -> np.ndarray:
    """The named columns as a float array ``(rows, len(names))``; bad values name their row."""
    n = len(columns[names[0]]) if names else 0
    out = np.empty((n, len(names)))
    for j, name in enumerate(names):
        for i, v in enumerate(columns[name]):
            if blank_ok and (v is None or (isinstance(v, str) and not v.strip())):
                out[i, j] = math.nan
                continue
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ScenarioError(path, f"row {i + 1}", f"{name} is not a number ({v!r})") from None
            if not math.isfinite(f):
                raise ScenarioError(path, f"row {i + 1}", f"{name} is not finite ({v!r})")
            out[i, j] = f
    return out


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
    columns = _read_columns(path, max_bytes)
    tcol = next((c for c in TIME_COLUMNS if c in columns), None)
    layout = next((lay for lay in LAYOUTS[space] if all(c in columns for c in lay[1])), None)
    if tcol is None or layout is None:
        if len(LAYOUTS[space]) == 1:
            wanted = [c for c in LAYOUTS[space][0][1] if c not in columns]
        else:
            wanted = [" or ".join("(" + ", ".join(lay[1]) + ")" for lay in LAYOUTS[space])]
        missing = ([] if layout else wanted) + (
            [] if tcol else ["release_time (or t, or departure_time)"])
        raise ScenarioError(path, "<header>", f"missing column(s): {', '.join(missing)}")
    name, pick, drop = layout
    has_dest = all(c in columns for c in drop)
    if not has_dest and any(c in columns for c in drop):
        raise ScenarioError(path, "<header>", f"drop-off needs all of {', '.join(drop)}")
    if tcol == DATETIME_COLUMN:
        if start is None:
            raise ScenarioError(path, DATETIME_COLUMN, "holds date-times: set [tasks] start "
                                "(e.g. start = \"2014-12-21T00:00\") in the scenario, the "
                                "time the run's second 0 stands for")
        t = _seconds_since(path, columns[tcol], start)
    else:
        if start is not None:
            raise ScenarioError(path, tcol, "gives times in seconds; [tasks] start is only used "
                                            f"with a {DATETIME_COLUMN} column of date-times")
        t = _numbers(path, columns, (tcol,))[:, 0]
    origin = _numbers(path, columns, pick)
    dest = _numbers(path, columns, drop) if has_dest else None
    max_wait = (_numbers(path, columns, ("max_wait",), blank_ok=True)[:, 0]
                if "max_wait" in columns else np.full(len(t), math.nan))
    max_delay = (_numbers(path, columns, ("max_delay",), blank_ok=True)[:, 0]
                 if "max_delay" in columns else np.full(len(t), math.nan))
    passengers = (_numbers(path, columns, ("passengers",), blank_ok=True)[:, 0]
                  if "passengers" in columns else np.ones(len(t)))
    early = t < 0 if tcol == DATETIME_COLUMN else np.zeros(len(t), dtype=bool)
    for i in range(len(t)):
        if early[i]:
            continue  # before start: left out below, not checked
        if max_delay[i] < 0:
            raise ScenarioError(path, f"row {i + 1}", f"max_delay {max_delay[i]} is negative")
        p = passengers[i]
        if p != p:
            passengers[i] = 1.0
        elif p < 1 or p != int(p) or p > 2**31:
            raise ScenarioError(path, f"row {i + 1}", f"passengers = {p} is not a whole "
                                                      f"number >= 1")
        if t[i] < 0:
            raise ScenarioError(path, f"row {i + 1}", f"release time {t[i]} is negative")
        if max_wait[i] <= 0:
            raise ScenarioError(path, f"row {i + 1}", f"max_wait {max_wait[i]} is not > 0")
        if size is not None:
            for cols, values in ((pick, origin[i]), (drop, dest[i] if has_dest else ())):
                for c, v, s in zip(cols, values, size):
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
    columns = _read_columns(path, max_bytes)
    if "vehicle_id" not in columns:
        raise ScenarioError(path, "<header>", "missing column vehicle_id")
    if nodes and "node" in columns:
        pos = _numbers(path, columns, ("node",))
    elif "x" in columns and "y" in columns:
        pos = _numbers(path, columns, ("x", "y") + (("z",) if "z" in columns else ()))
    else:
        want = "node or x, y" if nodes else "x, y (and z)"
        raise ScenarioError(path, "<header>", f"missing column(s): {want}")
    ids = _numbers(path, columns, ("vehicle_id",))[:, 0]
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
    columns = _read_columns(path, max_bytes)
    if "capacity" not in columns:
        return ()
    seats = _numbers(path, columns, ("capacity",), blank_ok=True)[:, 0]
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
