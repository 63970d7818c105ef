"""Running runs: one (:func:`run_one`), one after another (:func:`execute`), or as a resumable
sweep (:func:`sweep`) on a local process pool or on Ray (:mod:`dispatch.run.pools`).

Every run, whatever the number of runs, is streamed by a :class:`~dispatch.output.parquet.Recorder`
into its own Hive partition of ``out`` (``<table>/scenario=…/allocator=…/planner=…/n_agents=…/
seed=…/part-0.parquet``, so two scenarios can share one folder; a scenario that declares
repositioning, a ``[reposition]`` table or sweep, has a ``reposition=…`` level after
``planner=…``, and its run ids name the repositioner after the planner; one that sweeps its
batch window has a ``batch_window=…`` level before ``n_agents=…`` and ``__bw<seconds>`` in its
run ids: the levels and ids follow :data:`dispatch.config.runkeys.RUN_KEYS`; chunk files
``_inflight-NNNNN.parquet.chunk`` while it runs) and, once all of its tables are written, gets a
completion marker; a sweep skips the runs whose marker says they are complete and records a run
that raises in the ``errors`` table, then goes on (:mod:`dispatch.run.resume`).

Every run (of a sweep or of :func:`execute`) starts from cold caches (no world or planner cache
of an earlier run in the same process), so its wall-clock columns mean the same whatever the
number of workers and the order of the runs: every allocator pays for its own cost matrices.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dispatch.config.runkeys import key_names
from dispatch.config.scenario import RunSpec, safe_name
from dispatch.output.legs import schema_of
from dispatch.output.parquet import REQUEST_ID, Recorder, json_meta, request_id_type
from dispatch.run.pools import Outcome, on_pool, on_ray, sigterm_exits
from dispatch.run.resume import (clear_partition, is_complete, legacy_variant, read_summary,
                                 record_failure, write_marker)
from dispatch.run.time_limit import PastTimeLimit, time_limit_of

log = logging.getLogger(__name__)

DEFAULT_FLUSH_ROWS = 10_000


class RunResult:
    """One finished run: its spec, its summary row (a dict), the folder it was written to and
    its files (``{table: path of part-0.parquet}``). :attr:`tables` reads them back."""

    def __init__(self, spec: RunSpec, summary: dict, out: Path, files: dict[str, Path]) -> None:
        self.spec = spec
        self.summary = summary
        self.out = Path(out)
        self.files = dict(files)
        self._tables: dict[str, pa.Table] | None = None
        self._tmp: tempfile.TemporaryDirectory | None = None  # set by run_one(out=None)

    def __repr__(self) -> str:
        return f"RunResult({self.spec.run_id!r}, out={str(self.out)!r})"

    @property
    def tables(self) -> dict[str, pa.Table]:
        """Every table of the run (cached), read back from its file with the partition columns
        put back: ``tables[name]`` has exactly the columns of ``SCHEMAS[name]``, in order."""
        if self._tables is None:
            self._tables = {name: read_table(path, self.spec.partition, name)
                            for name, path in self.files.items()}
        return self._tables


def read_table(path: Path, partition: dict[str, Any], name: str) -> pa.Table:
    """One table file of a run with the ``partition`` columns (left out of the files) put
    back where ``SCHEMAS[name]`` has them (an optional table's, :data:`OPTIONAL_SCHEMAS`; columns
    a run added to a table, :meth:`Recorder.add_table`, after them)."""
    table = pq.read_table(path)
    schema = schema_of(name)
    for k, v in partition.items():
        if k in schema.names and k not in table.column_names:
            field = schema.field(k)
            i = schema.get_field_index(k)
            table = table.add_column(i, field, pa.array([v] * table.num_rows, field.type))
    return table.select([*schema.names, *(c for c in table.column_names
                                          if c not in schema.names)])


def run_metadata(spec: RunSpec) -> dict[str, str]:
    """The schema metadata every file of a run carries (besides version and run id): the
    scenario text, the seed, the run's partition (``dispatch.spec``) and the names of every
    run key (``dispatch.run_keys``, :data:`dispatch.config.runkeys.RUN_KEYS`: readers learn from it
    which columns name a run)."""
    meta = {"dispatch.scenario": spec.scenario.text, "dispatch.seed": str(spec.seed),
            "dispatch.spec": json_meta(spec.partition),
            "dispatch.run_keys": json_meta(key_names())}
    trips = spec.scenario.tasks.trips
    if trips is not None and trips.dropped:  # trips of the trace left out before the run
        meta["dispatch.trips_dropped"] = json_meta({r: n for r, n in trips.dropped})
    return meta


def make_recorder(spec: RunSpec, out: Path, *, flush_rows: int = DEFAULT_FLUSH_ROWS) -> Recorder:
    """The recorder of ``spec`` writing into its partition of ``out`` (its ``request_id``
    columns typed as its trips' ids are)."""
    return Recorder(Path(out), spec.run_id, run_metadata(spec), spec.partition,
                    flush_rows=flush_rows,
                    types={REQUEST_ID: request_id_type(spec.scenario.tasks.trips)})


def run_one(spec: RunSpec, out: Path | None = None, *,
            flush_rows: int = DEFAULT_FLUSH_ROWS, progress=None) -> RunResult:
    """Simulate one run, streaming its tables into its partition of ``out``.

    With ``out=None`` the files go to a temporary folder owned by the returned result (removed
    when it is garbage collected). On an exception the recorder is aborted (chunk files
    written so far stay, readable) and the exception propagates. ``progress``: see
    :class:`dispatch.run.sim.Simulation`."""
    from dispatch.run.sim import Simulation

    tmp = None
    if out is None:
        tmp = tempfile.TemporaryDirectory(prefix=f"dispatch-{spec.run_id}-")
        out = Path(tmp.name)
    recorder = make_recorder(spec, out, flush_rows=flush_rows)
    try:
        summary = Simulation(spec, recorder, progress).run()
        files = recorder.finish()
    except BaseException:
        recorder.abort()
        if tmp is not None:
            tmp.cleanup()
        raise
    result = RunResult(spec, summary, Path(out), files)
    result._tmp = tmp  # a TemporaryDirectory removes its folder when garbage collected
    return result


def default_out(spec: RunSpec) -> Path:
    """``runs/<scenario name>``, the name made safe as one folder name (no separators, no
    ``..``, no absolute path): results never land outside ``runs/``."""
    return Path("runs") / safe_name(spec.scenario.name)


def execute(
    specs: list[RunSpec],
    out: Path,
    *,
    on_done: Callable[[Any], None] | None = None,
    flush_rows: int = DEFAULT_FLUSH_ROWS,
    progress=None,
) -> list[dict]:
    """Run every spec in order into its partition of ``out`` (the layout of a sweep, markers
    included, so that ``dispatch sweep`` over the folder skips these runs). Each run starts
    from cold caches, as in :func:`sweep`; an exception stops here (no errors table).
    Returns the summaries in the order of ``specs``."""
    summaries = []
    for spec in specs:
        result, _ = _run_and_mark(spec, Path(out), flush_rows, progress)
        summaries.append(result.summary)
        log.info("%s: total cost %.2f s", spec.run_id, result.summary["total_cost"])
        if on_done is not None:
            on_done(result)
    return summaries


# ----------------------------------------------------------------------------- sweeps


def _run_and_mark(spec: RunSpec, out: Path, flush_rows: int = DEFAULT_FLUSH_ROWS,
                  progress=None) -> tuple[RunResult, dict[str, int]]:
    """Clear ``spec``'s partition of ``out``, run it there from cold caches and write its
    completion marker; returns the result and the marker's files (relative path: size)."""
    started = time.perf_counter()
    clear_partition(out, spec)
    old = legacy_variant(spec)
    if old is not None:  # the same run as an older version wrote it: the folder holds it once
        clear_partition(out, old)
    _cold_start()
    result = run_one(spec, out, flush_rows=flush_rows, progress=progress)
    seconds = time.perf_counter() - started
    files = {str(p.relative_to(out)): p.stat().st_size for p in result.files.values()}
    write_marker(out, spec, seconds, files)
    return result, files


def run_partition(spec: RunSpec, out: str | Path, time_limit: float | None = None) -> Outcome:
    """Run one spec of a sweep into its partition of ``out`` and mark it complete; an
    exception is recorded in the errors table and returned as a failed :class:`Outcome`
    (a run past ``time_limit`` wall seconds: :class:`dispatch.run.time_limit.PastTimeLimit`).
    This is what pool workers and Ray tasks execute (a top-level function: spawn-safe)."""
    out = Path(out)
    started = time.perf_counter()
    try:
        if time_limit is None:
            result, files = _run_and_mark(spec, out)
        else:
            with time_limit_of(time_limit) as progress:
                result, files = _run_and_mark(spec, out, progress=progress)
    except (Exception, PastTimeLimit) as e:  # noqa: BLE001 - any failure of one run is
        seconds = time.perf_counter() - started  # recorded, not raised
        log.warning("%s failed: %s: %s", spec.run_id, type(e).__name__, e)
        tb = traceback.format_exc()
        record_failure(out, spec, type(e).__name__, str(e), tb, seconds)
        return Outcome(spec, "failed", error=f"{type(e).__name__}: {e}", seconds=seconds,
                       traceback=tb)
    seconds = time.perf_counter() - started
    return Outcome(spec, "done", summary={"run_id": spec.run_id, **result.summary},
                   seconds=seconds, files=sorted(files))


def _cold_start() -> None:
    """Forget the worlds (and the planner caches kept on their grids) of earlier runs in this
    process, so that a run's timing columns (cost_seconds, alloc_seconds, …) do not depend on
    which runs the same worker happened to do before it: a sweep gives the same kind of
    measurement on 1 process, K processes or Ray."""
    from dispatch.space.world import world_for

    world_for.cache_clear()


def sweep(
    specs: list[RunSpec],
    out: Path,
    *,
    workers: int | None = None,
    ray: bool = False,
    address: str | None = None,
    overwrite: bool = False,
    on_done: Callable[[Outcome], None] | None = None,
    time_limit: float | None = None,
) -> list[Outcome]:
    """Run ``specs`` into the Hive-partitioned folder ``out``, skipping complete runs.

    ``workers``: processes of the local pool (default: the CPU count; 1 runs in this process)
    or CPUs of a local Ray instance. ``ray``: run every run as a Ray task, on the cluster at
    ``address`` or on a local Ray started here (workers of a cluster need this package
    installed and ``out`` on a file system they share). ``overwrite``: run complete runs again too.
    ``on_done`` is called in this process as each run finishes or is skipped.
    ``time_limit``: wall seconds a run may take; one past it stops and fails with
    :class:`dispatch.run.time_limit.PastTimeLimit` (a timer in the worker's main thread, else the
    next progress tick, every 1/500 of the simulated duration). Returns the outcomes in the
    order of ``specs``.
    """
    out = Path(out).resolve()
    outcomes: dict[int, Outcome] = {}
    todo: list[tuple[int, RunSpec]] = []
    for i, spec in enumerate(specs):
        old = legacy_variant(spec)
        done = None if overwrite else spec if is_complete(out, spec) else \
            old if old is not None and is_complete(out, old) else None
        if done is not None:
            try:  # a run of an older layout reads as this one (its name, its window)
                summary = {**read_summary(out, done), **spec.keys}
                outcomes[i] = Outcome(spec, "skipped", summary=summary)
            except (OSError, pa.ArrowException, IndexError):
                done = None
        if done is None:  # (run by _run_and_mark, which clears an older copy)
            todo.append((i, spec))
            continue
        if on_done is not None:
            on_done(outcomes[i])
    if todo:
        workers = workers or os.cpu_count() or 1
        if ray:
            stream = on_ray(todo, out, workers, address, run_partition, time_limit)
        elif workers == 1:
            stream = ((i, run_partition(spec, out, time_limit)) for i, spec in todo)
        else:
            stream = on_pool(todo, out, workers, run_partition, time_limit)
        with sigterm_exits():
            try:
                for i, outcome in stream:
                    outcomes[i] = outcome
                    if on_done is not None:
                        on_done(outcome)
            finally:
                stream.close()  # (every stream is a generator: a pool's stops its workers now)
    return [outcomes[i] for i in range(len(specs))]
