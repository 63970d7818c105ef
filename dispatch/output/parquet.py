"""Recording a run into Parquet tables, streamed to disk as the run goes.

Each table has a fixed schema (below), so an empty table is still a valid, typed file. One
layout whatever the number of runs: ``OUT/<table>/allocator=…/planner=…/n_agents=…/seed=…/
part-0.parquet`` (Hive; the partition columns live in the path, not in the files). While a run
goes, rows are flushed every ``flush_rows`` rows into whole chunk files
``_inflight-NNNNN.parquet.chunk`` next to it (ignored by Hive readers, readable one by one after
a crash; lz4, cheap to write and read back); at the end they are merged into ``part-0.parquet``
(zstd). Every file is written to a temporary name and renamed into place, so a reader never
sees half a file. The schema metadata of every file holds the scenario text,
the seed, the run id and the package version; ``obstacles`` also holds the world's size and
cell size so a run can be redrawn.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dispatch import __version__
from dispatch.config.runkeys import format_value
from dispatch.output.stale import remove_stale_temps

# pyarrow's default allocator (jemalloc or mimalloc) keeps what a chunk write or the final merge
# freed: measured with benchmarks/memory.py, 40-65 MB more peak memory per run than the C
# allocator, which gives it back. A run writes Parquet all along, so its peak matters more than
# the allocator's speed here.
pa.set_memory_pool(pa.system_memory_pool())

#: chunk files are read back once, at the merge, which compresses the final file with zstd:
#: lz4 is several times cheaper to write and read than compressing every row twice with zstd
CHUNK_CODEC = "lz4"

_S, _I, _F, _B = pa.string(), pa.int64(), pa.float64(), pa.bool_()

SCHEMAS: dict[str, pa.Schema] = {
    "summary": pa.schema([
        ("run_id", _S), ("scenario", _S), ("allocator", _S), ("planner", _S),
        ("n_agents", _I), ("n_tasks", _I), ("seed", _I), ("space", _S), ("total_cost", _F),
        ("conflict_free_rate", _F), ("alloc_seconds", _F), ("tasks_completed", _I),
        ("tasks_unfinished", _I), ("makespan", _F),
        ("n_uav", _I), ("n_ugv", _I), ("decisions", _I), ("rounds", _I), ("messages", _I),
        ("conflicts", _I), ("cost_seconds", _F), ("decide_seconds", _F),
        ("first_decision_cost", _F), ("first_decision_seconds", _F), ("realized_travel", _F),
        ("wait_time_mean", _F), ("tasks_expired", _I), ("tasks_rejected", _I),
        ("tasks_unreachable", _I), ("tasks_cut_off", _I), ("tasks_failed", _I),
        ("sim_time", _F), ("comm_delay", _F), ("agent_seconds", _F),
        ("distance", _F), ("empty_distance", _F), ("occupied_distance", _F),
        # [faults]: vehicle breakdowns; tasks re-opened by one; of those, passengers transferred
        ("failures", _I), ("tasks_reassigned", _I), ("tasks_transferred", _I),
        # [dispatch] reassign: times a vehicle driving to a pickup gave its task up for another
        # decision's answer (each a `reassign` event)
        ("reassignments", _I),
        # [reposition]: the repositioner (stay: idle vehicles wait), the drives it started
        # toward a target and their metres (part of empty_distance)
        ("reposition", _S), ("repositions", _I), ("reposition_distance", _F),
        # [dispatch] batch_window (a run key: swept by [sweep] batch_window)
        ("batch_window", _F),
        # tasks that had a vehicle when they closed: total_cost / tasks_assigned is the mean
        # planned cost of an assignment (the dynamic benchmark's per-task cost)
        ("tasks_assigned", _I),
        # what the allocator says it ran (JSON object of strings; see dispatch.run.plugins.describe)
        ("allocator_info", _S),
        # shared rides: passenger-metres; occupancy = passenger_distance / distance (MATSim
        # DRT's); share of completed rides shared; mean delay (drop-off - release - direct
        # time, s) and detour ratio (in-vehicle time / direct time) over completed trips
        ("passenger_distance", _F), ("occupancy", _F), ("shared_rate", _F),
        ("delay_mean", _F), ("detour_ratio", _F),
        # [dispatch] objective: what a pair's cost (total_cost's terms) measures
        ("objective", _S),
        # prebooking: booked requests accepted (promises), and of those not completed
        ("promises", _I), ("promises_broken", _I),
        # offers riders may decline (dispatch.api.acceptor): requests closed `declined`, offers
        # made,
        # fares of the completed rides (0 without [pricing])
        ("tasks_declined", _I), ("offers", _I), ("revenue", _F),
        # shifts and sizing (dispatch.fleet.shifts): on-duty vehicle-hours, completed requests per
        # vehicle-hour, vehicles that reached their depot after their shift's end and grace
        ("vehicle_hours", _F), ("riders_per_vehicle_hour", _F), ("shift_overruns", _I),
        # [fleet.energy] (nan, and 0 charges and strandings, without): the fleet's kWh drawn
        # and charged, charges started (plug-ins), vehicles stranded (battery empty), the
        # lowest state of charge a vehicle reached and the fleet's mean at the end (0-1),
        # seconds the fleet queued at stations, the part of kwh_drawn the auxiliary load
        # (idle_kwh_per_hour, idle or driving) drew: the rest is driving (dispatch.output.energy)
        ("kwh_drawn", _F), ("kwh_charged", _F), ("charges", _I), ("strandings", _I),
        ("soc_min", _F), ("soc_end_mean", _F), ("queue_seconds", _F), ("kwh_auxiliary", _F),
        # meeting points (dispatch.decide.meeting): mean metres walked per completed ride (to board
        # plus from alighting; 0 door to door), candidate points found, and points within a
        # radius left out by [tasks] meeting_points
        ("walk_mean", _F), ("meeting_points", _I), ("meeting_cut", _I),
    ]),
    "tasks": pa.schema([
        # request_id: the user's id of the task's request (a trace row's id as written, or its
        # row number; generated demand: its draw number), to join results to the trips; int64,
        # or string where a trace's ids are not all integers (see request_id_type)
        ("run_id", _S), ("task_id", _I), ("request_id", _I), ("kind", _S), ("x", _F),
        ("y", _F), ("z", _F), ("dropoff_x", _F), ("dropoff_y", _F), ("dropoff_z", _F),
        ("released_at", _F), ("max_wait", _F), ("snap_m", _F), ("dropoff_snap_m", _F),
        ("assigned_at", _F), ("agent_id", _I), ("cost", _F),
        ("picked_up_at", _F), ("completed_at", _F), ("state", _S), ("conflicted", _B),
        ("closed_at", _F),
        # times it went back to open after a breakdown; of those, with the passenger aboard
        ("reassigned", _I), ("transfers", _I),
        # shared rides: riders; free-flow seconds pickup -> drop-off; the request's delay
        # limit; whether another request was on board during its ride
        ("passengers", _I), ("direct_time", _F), ("max_delay", _F), ("shared", _B),
        # prebooking: when it was booked (nan: not booked); accepted when booked (a promise)
        ("booked_at", _F), ("promised", _B),
        # offers riders may decline (dispatch.api.acceptor): offers made to the rider (0 without an
        # acceptor that declines or [pricing]) and the last offer's fare (nan without [pricing])
        ("offers", _I), ("fare", _F),
        # meeting points (dispatch.decide.meeting): where the rider boarded and alighted (the pickup
        # and drop-off door to door; nan: never handed out) and the metres walked
        ("board_x", _F), ("board_y", _F), ("alight_x", _F), ("alight_y", _F),
        ("walk_to_board_m", _F), ("walk_from_alight_m", _F),
    ]),
    "assignments": pa.schema([
        ("run_id", _S), ("decision", _I), ("round", _I), ("agent_id", _I), ("task_id", _I),
        ("request_id", _I), ("cost", _F), ("won", _B), ("alloc_seconds", _F),
    ]),
    "decisions": pa.schema([
        ("run_id", _S), ("decision", _I), ("t", _F), ("n_idle", _I), ("n_tasks", _I),
        ("n_assigned", _I), ("rounds", _I), ("messages", _I), ("conflicts", _I),
        ("total_cost", _F), ("cost_seconds", _F), ("decide_seconds", _F),
        ("hops", _I), ("comm_delay", _F), ("agent_seconds", _F), ("comm_components", _I),
        # open tasks the candidate cut left out of the decision (dispatch.decide.candidates)
        ("n_cut", _I),
    ]),
    "events": pa.schema([
        # request_id: the task's (null where the row is about no task: task_id -1)
        ("run_id", _S), ("t", _F), ("event", _S), ("agent_id", _I), ("task_id", _I),
        ("request_id", _I), ("x", _F), ("y", _F), ("z", _F),
    ]),
    "vehicles": pa.schema([
        ("run_id", _S), ("agent_id", _I), ("kind", _S), ("speed", _F), ("x0", _F), ("y0", _F),
        ("z0", _F), ("distance", _F),
        # metres driven without / with a passenger or load aboard (distance is their sum)
        ("empty_distance", _F), ("occupied_distance", _F),
        ("busy_seconds", _F), ("tasks_completed", _I),
        # execution with reservations (0 otherwise): wait episodes, routes replaced by a
        # higher-priority vehicle, seconds spent standing on the way (see
        # dispatch.plan.traffic)
        ("waits", _I), ("replans", _I), ("wait_seconds", _F),
        # breakdowns ([faults]) and seconds out of service
        ("failures", _I), ("down_seconds", _F),
        # seats; passenger-metres (metres times passengers on board)
        ("capacity", _I), ("passenger_distance", _F),
        # [fleet.energy] (nan without): kWh drawn (driving + auxiliary) and charged, seconds
        # plugged in and queued at stations, lowest and final state of charge (0-1)
        ("kwh_drawn", _F), ("kwh_charged", _F), ("charge_seconds", _F), ("queue_seconds", _F),
        ("soc_min", _F), ("soc_end", _F),
        # shifts (dispatch.fleet.shifts): its shift (0, inf: none), its on-duty hours, and how late
        # it reached its depot after its shift's end and grace (0: in time)
        ("shift_start", _F), ("shift_end", _F), ("vehicle_hours", _F), ("overrun_seconds", _F),
        # [fleet.breaks] (0 without): seconds its driver spent on breaks
        # (dispatch.plan.breaks)
        ("break_seconds", _F),
    ]),
    # [fleet.energy]: every vehicle's state of charge (0-1) every [fleet.energy] sample
    # seconds from 0 (no rows without energy)
    "soc": pa.schema([("run_id", _S), ("t", _F), ("agent_id", _I), ("soc", _F)]),
    # [chargers] with [fleet.energy]: one row per station (no rows without)
    "chargers": pa.schema([
        ("run_id", _S), ("station_id", _S), ("node", _I), ("x", _F), ("y", _F), ("plugs", _I),
        ("kw", _F), ("kwh_delivered", _F), ("busy_plug_hours", _F), ("visits", _I),
        ("queued_visits", _I), ("queue_seconds", _F), ("mean_queue", _F),
    ]),
    "obstacles": pa.schema([
        ("run_id", _S), ("x0", _F), ("y0", _F), ("z0", _F), ("x1", _F), ("y1", _F), ("z1", _F),
    ]),
}

#: the column of the user's request ids, in every table about requests; its type is a run's
#: own (:func:`request_id_type`): the schemas above give the integer one
REQUEST_ID = "request_id"


def request_id_type(trips) -> pa.DataType:
    """The type of a run's ``request_id`` columns: string where its trips' ids are strings
    (``trips``: :class:`dispatch.files.traces.Trips`, None for generated demand), else int64
    (integer ids, a trace's row numbers, generated demand's draw numbers)."""
    ids = None if trips is None else trips.ids
    return _S if ids is not None and ids.dtype == object else _I


#: Columns that hold wall-clock measurements: they differ between identical runs.
TIMING_COLUMNS = {"alloc_seconds", "cost_seconds", "decide_seconds", "first_decision_seconds",
                  "agent_seconds"}


def partition_path(partition: dict[str, Any]) -> Path:
    """The Hive folders of a partition: ``k1=v1/k2=v2/...`` (``.`` when empty; a float
    without a needless ``.0``: ``batch_window=30``)."""
    return Path(*(f"{k}={format_value(v)}" for k, v in partition.items()))


CHUNK_PREFIX = "_inflight-"
#: not ".parquet": a glob such as `**/*.parquet` (DuckDB, polars) must not pick up a chunk
CHUNK_SUFFIX = ".parquet.chunk"
FINAL_NAME = "part-0.parquet"


class Recorder:
    """Streams one run's rows into ``out/<table>/<k1=v1>/.../part-0.parquet``.

    Rows are buffered per table as column lists; once a table holds ``flush_rows`` rows they
    are written as a complete chunk file ``_inflight-NNNNN.parquet.chunk`` in the table's partition
    folder (temporary name, then a rename), so memory stays bounded and a run killed half-way
    leaves whole, readable chunks (names starting with ``_`` are skipped by Hive readers).
    :meth:`finish` streams the chunks and the remainder into ``part-0.parquet`` (atomically)
    and removes the chunks. The ``partition`` columns are left out of the files (readers put
    them back from the path); a row whose value of such a column differs from the partition's
    is an error.
    """

    def __init__(self, out: Path, run_id: str, metadata: dict[str, str],
                 partition: dict[str, Any], *, flush_rows: int = 10_000,
                 types: dict[str, pa.DataType] | None = None) -> None:
        if flush_rows < 1:
            raise ValueError(f"flush_rows must be >= 1, got {flush_rows}")
        self.out = Path(out)
        #: column name -> this run's type of it in every table that has it (``request_id``:
        #: :func:`request_id_type`); the others as :data:`SCHEMAS` gives them
        self.types = dict(types or {})
        self.run_id = run_id
        self.partition = dict(partition)
        self.flush_rows = flush_rows
        self.metadata = {"dispatch.version": __version__, "dispatch.run_id": run_id, **metadata}
        self.table_metadata: dict[str, dict[str, str]] = {}
        #: this run's tables (:data:`SCHEMAS`, and those :meth:`add_table` adds or widens);
        #: buffered rows per table: tuples in schema order without ``run_id`` (the first column)
        self.schemas: dict[str, pa.Schema] = {}
        self._rows: dict[str, list[tuple]] = {}
        self._names: dict[str, tuple[str, ...]] = {}
        self._columns: dict[str, Callable[[list], dict]] = {}  # see appender()
        self._chunks: dict[str, list[Path]] = {}
        self._written: dict[str, int] = {}
        self._closed = False
        self._open: list[tuple[pq.ParquetWriter, Path]] = []  # writers of finish(), if any
        for name, schema in SCHEMAS.items():
            self.add_table(name, schema)

    def add_table(self, name: str, schema: pa.Schema) -> None:
        """Write the table ``name`` of ``schema`` (an optional one, dispatch.output.legs, or one
        widened before its first row); chunks of an earlier run killed half-way are removed."""
        self.schemas[name], self._names[name] = schema, tuple(schema.names[1:])
        self._rows[name], self._chunks[name], self._written[name] = [], [], 0
        if self.leaf(name).is_dir():
            for stale in self.leaf(name).glob(f"{CHUNK_PREFIX}*{CHUNK_SUFFIX}"):
                stale.unlink()

    # ------------------------------------------------------------------ paths, schemas
    def leaf(self, table: str) -> Path:
        """The folder of ``table``'s files for this run."""
        return self.out / table / partition_path(self.partition)

    def file_schema(self, table: str) -> pa.Schema:
        """``table``'s schema in the files: without the partition columns, with metadata."""
        schema = self.schemas[table]
        for k, typ in self.types.items():
            if k in schema.names:
                schema = schema.set(schema.get_field_index(k), pa.field(k, typ))
        for k in self.partition:
            if k in schema.names:
                schema = schema.remove(schema.get_field_index(k))
        meta = {**self.metadata, **self.table_metadata.get(table, {})}
        return schema.with_metadata({k: str(v) for k, v in meta.items()})

    # ------------------------------------------------------------------ rows
    def add(self, table: str, **row: Any) -> None:
        """Append one row; ``run_id`` is filled in; every other column must be given."""
        names = self._names[table]
        try:
            if len(row) != len(names):
                raise KeyError
            values = tuple([row[k] for k in names])
        except KeyError:
            row["run_id"] = self.run_id
            cols = self.schemas[table].names
            missing, extra = set(cols) - row.keys(), row.keys() - set(cols)
            raise KeyError(f"{table} row: missing {sorted(missing)}, unexpected {sorted(extra)}")
        self.append(table, values)

    def append(self, table: str, values: tuple) -> None:
        """Append one row given as a tuple of every column but ``run_id``, in the schema's
        order (the fast path of :meth:`add`, for the event stream)."""
        if self._closed:
            raise RuntimeError(f"recorder of {self.run_id} is closed (finish or abort)")
        rows = self._rows[table]
        rows.append(values)
        if len(rows) >= self.flush_rows:
            self.flush(table)

    def appender(self, table: str, columns: Callable[[list], dict] | None = None
                 ) -> Callable[[Any], None]:
        """``append(values)`` for one table: :meth:`append` with the table bound (the event
        stream's recorder calls it several times per trip). With ``columns`` the items appended
        may be anything: when they are written, ``columns(items)`` turns the list of them into
        the table's columns (a dict: every column but ``run_id``, each a sequence of Python
        values or a numpy array), so the work per row can be done once per chunk, vectorized."""
        rows_of, limit = self._rows, self.flush_rows
        rows_of[table]  # KeyError now for an unknown table
        if columns is not None:
            self._columns[table] = columns

        def append(values: tuple) -> None:
            if self._closed:
                raise RuntimeError(f"recorder of {self.run_id} is closed (finish or abort)")
            rows = rows_of[table]
            rows.append(values)
            if len(rows) >= limit:
                self.flush(table)

        return append

    def buffered(self, table: str) -> int:
        """Rows of ``table`` held in memory (not yet in a chunk file); below ``flush_rows``."""
        return len(self._rows[table])

    def written(self, table: str) -> int:
        """Rows of ``table`` already in chunk files."""
        return self._written[table]

    def chunks(self, table: str) -> list[Path]:
        """The chunk files of ``table`` written so far (removed by :meth:`finish`)."""
        return list(self._chunks[table])

    def _take(self, table: str) -> pa.Table:
        """The buffered rows of ``table`` as a file-schema table; the buffer is emptied."""
        rows = self._rows[table]
        names = self._names[table]
        columns = self._columns.get(table)
        if columns is not None:
            cols = dict(columns(rows))
            if sorted(cols) != sorted(names) or any(len(c) != len(rows) for c in cols.values()):
                raise ValueError(f"{table}: columns() gave {sorted(cols)} for {len(rows)} rows, "
                                 f"expected {', '.join(names)}")
        elif rows and set(map(len, rows)) != {len(names)}:
            raise ValueError(f"{table} row has {len(next(r for r in rows if len(r) != len(names)))}"
                             f" values, expected {len(names)} ({', '.join(names)})")
        else:
            cols = dict(zip(names, zip(*rows))) if rows else {k: () for k in names}
        cols["run_id"] = ConstantColumn(self.run_id, len(rows))
        for k, v in self.partition.items():
            if k in cols and any(x != v for x in cols[k]):
                bad = next(x for x in cols[k] if x != v)
                raise ValueError(f"{table} row has {k}={bad!r}, but the run's partition is "
                                 f"{k}={v!r}")
        schema = self.file_schema(table)
        data = pa.Table.from_arrays([arrow_column(cols[f.name], f.type) for f in schema],
                                    schema=schema)
        self._rows[table] = []
        return data

    def flush(self, table: str | None = None) -> None:
        """Write the buffered rows of ``table`` (of every table if None) as a chunk file."""
        for name in self.schemas if table is None else (table,):
            if not self._rows[name]:
                continue
            data = self._take(name)
            path = self.leaf(name) / f"{CHUNK_PREFIX}{len(self._chunks[name]):05d}{CHUNK_SUFFIX}"
            # a chunk is read once, by finish(): no statistics, dictionaries for the strings
            # only (the final file is written with the defaults); twice as fast to write
            write_atomic(data, path, CHUNK_CODEC, write_statistics=False,
                         use_dictionary=[f.name for f in data.schema if f.type == _S])
            self._chunks[name].append(path)
            self._written[name] += data.num_rows

    # ------------------------------------------------------------------ the end
    def finish(self) -> dict[str, Path]:
        """Merge every table's chunks and remaining rows into its ``part-0.parquet`` (written
        to a temporary name, then renamed: atomic), remove the chunks and return the files.
        An empty table gives a valid, typed file with no rows."""
        if self._closed:
            raise RuntimeError(f"recorder of {self.run_id} is closed (finish or abort)")
        files = {}
        for name in self.schemas:
            schema = self.file_schema(name)
            rest = self._take(name)
            path = self.leaf(name) / FINAL_NAME
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
            writer = pq.ParquetWriter(tmp, schema, compression="zstd")
            self._open.append((writer, tmp))
            rows = 0
            for chunk in self._chunks[name]:
                with pq.ParquetFile(chunk) as f:  # (pq.read_table would import pandas)
                    part = f.read().replace_schema_metadata(schema.metadata)
                writer.write_table(part)
                rows += part.num_rows
            if rest.num_rows or rows == 0:
                writer.write_table(rest)
            writer.close()
            self._open.pop()
            os.replace(tmp, path)
            for chunk in self._chunks[name]:
                chunk.unlink(missing_ok=True)
            self._chunks[name] = []
            files[name] = path
        self._closed = True
        return files

    def abort(self) -> None:
        """After an exception: write what is buffered as chunks (best effort), close and
        remove a half-written final file, and leave every chunk where it is. Idempotent."""
        if self._closed:
            return
        self._closed = True
        for writer, tmp in self._open:
            try:
                writer.close()
            except Exception:  # noqa: BLE001 - already failing; keep the first error
                pass
            tmp.unlink(missing_ok=True)
        self._open = []
        for name in self.schemas:
            try:
                self.flush(name)
            except Exception:  # noqa: BLE001 - e.g. a row of the wrong type: drop the rest
                self._rows[name] = []


class ConstantColumn(tuple):
    """A column of ``n`` times the same value (``run_id``): a tuple, that also says so."""

    def __new__(cls, value, n: int):
        out = super().__new__(cls, (value,) * n)
        out.value = value
        return out


#: Python values a float (int) column is built from as numbers: numpy's doubles (int64s) are
#: those numbers exactly, as ``pa.array`` converts them
_FLOATS, _INTS = {float, np.float64}, {int, np.int64}


def arrow_column(values, typ: pa.DataType) -> pa.Array:
    """``values`` (a sequence of Python scalars) as an Arrow array of type ``typ``: the same
    array as ``pa.array(values, typ)``. Columns of plain floats (numpy doubles among them),
    ints (numpy int64s among them), bools or strings are built from numpy buffers: several
    times faster, and without ``pa.array``'s import of pandas (about half a second the first
    time, inside a run). Anything else (None, other numpy scalars, ints in a float column,
    values out of range) goes through ``pa.array``, which converts or rejects it as it always
    did."""
    if isinstance(values, pa.Array) and values.type == typ:
        return values  # (built by a table's columns(): the request ids of events)
    n = len(values)
    if isinstance(values, np.ndarray) and values.ndim == 1 and (
            (typ == _F and values.dtype == np.float64) or (typ == _I and values.dtype == np.int64)):
        return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(np.ascontiguousarray(values))])
    if isinstance(values, ConstantColumn) and typ == _S and type(values.value) is str:
        one = values.value.encode()
        offsets = np.arange(n + 1, dtype=np.int64) * len(one)
        if offsets[-1] < 2**31:
            return pa.StringArray.from_buffers(n, pa.py_buffer(offsets.astype(np.int32)),
                                               pa.py_buffer(one * n))
    kinds = set(map(type, values))
    try:
        if typ == _F and kinds <= _FLOATS:
            buf = np.fromiter(values, np.float64, n)
        elif typ == _I and kinds <= _INTS:
            buf = np.fromiter(values, np.int64, n)
        elif typ == _B and kinds <= {bool}:
            buf = np.packbits(np.fromiter(values, np.bool_, n), bitorder="little")
        elif typ == _S and kinds <= {str}:
            data = [v.encode() for v in values]
            offsets = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(np.fromiter(map(len, data), np.int64, n), out=offsets[1:])
            if offsets[-1] >= 2**31:
                raise OverflowError("string column too large for 32-bit offsets")
            return pa.StringArray.from_buffers(n, pa.py_buffer(offsets.astype(np.int32)),
                                               pa.py_buffer(b"".join(data)))
        else:
            return pa.array(values, typ)
    except OverflowError:  # an int beyond int64: pa.array says so its own way
        return pa.array(values, typ)
    return pa.Array.from_buffers(typ, n, [None, pa.py_buffer(buf)])


def write_atomic(table: pa.Table, path: Path, compression: str = "zstd", **options) -> None:
    """Write ``table`` to ``path`` through a temporary file and an atomic rename (``options``:
    more keywords of ``pyarrow.parquet.write_table``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    pq.write_table(table, tmp, compression=compression, **options)
    os.replace(tmp, path)
    remove_stale_temps(path)


def json_meta(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True)
