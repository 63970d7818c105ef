"""Recording a run into Parquet tables.

Each table has a fixed schema (below), so an empty table is still a valid, typed file. Files are
written to a temporary name and renamed into place, so a reader never sees half a file. The
schema metadata of every file holds the scenario text, the seed, the run id and the package
version; ``obstacles`` also holds the world's size and cell size so a run can be redrawn.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dispatch import __version__

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
        ("tasks_unreachable", _I), ("tasks_cancelled", _I), ("tasks_failed", _I), ("sim_time", _F),
        ("comm_delay", _F), ("agent_seconds", _F), ("distance", _F), ("empty_distance", _F),
        ("occupied_distance", _F),
    ]),
    "tasks": pa.schema([
        ("run_id", _S), ("task_id", _I), ("kind", _S), ("x", _F), ("y", _F), ("z", _F),
        ("dropoff_x", _F), ("dropoff_y", _F), ("dropoff_z", _F), ("released_at", _F),
        ("max_wait", _F), ("snap_m", _F), ("dropoff_snap_m", _F), ("assigned_at", _F),
        ("agent_id", _I), ("cost", _F), ("picked_up_at", _F), ("completed_at", _F),
        ("state", _S), ("conflicted", _B), ("closed_at", _F),
    ]),
    "assignments": pa.schema([
        ("run_id", _S), ("decision", _I), ("round", _I), ("agent_id", _I), ("task_id", _I),
        ("cost", _F), ("won", _B), ("alloc_seconds", _F),
    ]),
    "decisions": pa.schema([
        ("run_id", _S), ("decision", _I), ("t", _F), ("n_idle", _I), ("n_tasks", _I),
        ("n_assigned", _I), ("rounds", _I), ("messages", _I), ("conflicts", _I),
        ("total_cost", _F), ("cost_seconds", _F), ("decide_seconds", _F),
        ("hops", _I), ("comm_delay", _F), ("agent_seconds", _F), ("comm_components", _I),
    ]),
    "events": pa.schema([
        ("run_id", _S), ("t", _F), ("event", _S), ("agent_id", _I), ("task_id", _I),
        ("x", _F), ("y", _F), ("z", _F),
    ]),
    "vehicles": pa.schema([
        ("run_id", _S), ("agent_id", _I), ("kind", _S), ("speed", _F), ("x0", _F), ("y0", _F),
        ("z0", _F), ("distance", _F), ("empty_distance", _F), ("occupied_distance", _F),
        ("busy_seconds", _F), ("tasks_completed", _I),
        # execution with reservations (0 otherwise): wait episodes, routes replaced by a
        # higher-priority vehicle, seconds spent standing on the way (see dispatch.reservations)
        ("waits", _I), ("replans", _I), ("wait_seconds", _F),
    ]),
    "obstacles": pa.schema([
        ("run_id", _S), ("x0", _F), ("y0", _F), ("z0", _F), ("x1", _F), ("y1", _F), ("z1", _F),
    ]),
}

#: Columns that hold wall-clock measurements: they differ between identical runs.
TIMING_COLUMNS = {"alloc_seconds", "cost_seconds", "decide_seconds", "first_decision_seconds",
                  "agent_seconds"}


class Recorder:
    """Collects rows per table in memory (column lists) and writes them as Parquet."""

    def __init__(self, run_id: str, metadata: dict[str, str]) -> None:
        self.run_id = run_id
        self.metadata = {"dispatch.version": __version__, "dispatch.run_id": run_id, **metadata}
        self.table_metadata: dict[str, dict[str, str]] = {}
        self._cols = {name: {f.name: [] for f in schema} for name, schema in SCHEMAS.items()}

    def add(self, table: str, **row: Any) -> None:
        """Append one row; ``run_id`` is filled in; every other column must be given."""
        cols = self._cols[table]
        row["run_id"] = self.run_id
        if row.keys() != cols.keys():
            missing, extra = cols.keys() - row.keys(), row.keys() - cols.keys()
            raise KeyError(f"{table} row: missing {sorted(missing)}, unexpected {sorted(extra)}")
        for k, v in row.items():
            cols[k].append(v)

    def columns(self, table: str) -> dict[str, list]:
        """The rows recorded so far, as column lists (read-only by convention)."""
        return self._cols[table]

    def rows(self, table: str) -> int:
        return len(self._cols[table]["run_id"])

    def table(self, name: str) -> pa.Table:
        meta = {**self.metadata, **self.table_metadata.get(name, {})}
        schema = SCHEMAS[name].with_metadata({k: str(v) for k, v in meta.items()})
        return pa.Table.from_pydict(self._cols[name], schema=schema)

    def tables(self) -> dict[str, pa.Table]:
        return {name: self.table(name) for name in SCHEMAS}


def write_atomic(table: pa.Table, path: Path) -> None:
    """Write ``table`` to ``path`` through a temporary file and an atomic rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    pq.write_table(table, tmp, compression="zstd")
    os.replace(tmp, path)


def write_run(tables: dict[str, pa.Table], out: Path, partition: dict[str, Any] | None) -> list[Path]:
    """Write one run's tables under ``out``.

    Without ``partition``: ``out/<table>.parquet``. With it (a sweep): the Hive layout
    ``out/<table>/k1=v1/k2=v2/.../part-0.parquet``, the partition columns left out of the files
    (readers add them back from the path, as Hive does).
    """
    written = []
    for name, table in tables.items():
        if partition is None:
            path = out / f"{name}.parquet"
        else:
            sub = Path(*(f"{k}={v}" for k, v in partition.items()))
            path = out / name / sub / "part-0.parquet"
            drop = [k for k in partition if k in table.column_names]
            table = table.drop_columns(drop)
        write_atomic(table, path)
        written.append(path)
    return written


def json_meta(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True)
