"""Running runs: one (:func:`run_one`), one after another (:func:`execute`), or as a resumable
sweep (:func:`sweep`) on a local process pool or on Ray.

Every run, whatever the number of runs, is streamed by a :class:`~dispatch.output.parquet.Recorder`
into its own Hive partition of ``out`` (``<table>/scenario=…/allocator=…/planner=…/n_agents=…/
seed=…/part-0.parquet``, so two scenarios can share one folder; a scenario that declares
repositioning, a ``[reposition]`` table or sweep, has a ``reposition=…`` level after
``planner=…``, and its run ids name the repositioner after the planner; one that sweeps its
batch window has a ``batch_window=…`` level before ``n_agents=…`` and ``__bw<seconds>`` in its
run ids: the levels and ids follow :data:`dispatch.config.runkeys.RUN_KEYS`; chunk files
``_inflight-NNNNN.parquet.chunk`` while it runs) and, once all of its tables are written, gets a
completion marker ``out/_runs/<partition>/done.json`` (written
atomically) that lists the files and their sizes. Rerunning a sweep (or a sweep over the output
of ``dispatch run``) skips every run whose marker is there, names the same run of the same
scenario and whose files are all present with those sizes; any other run (never started,
killed half-way, failed, or its files touched since) is cleared and run again. "The same run"
is :func:`run_digest`: the scenario's settings outside ``[sweep]`` (parsed, so comments and
layout do not count) and the run's own point (allocator, planner, repositioner, N, seed,
batch window). Adding a value to a sweep list therefore runs only the new runs, and removing
one leaves its runs in the folder (:func:`foreign_runs` does not count them as another
scenario's). A folder written before the batch window was a run key (each window a scenario
``<name>-batch30s``, :func:`legacy_variant`) resumes too: its complete runs count as this
sweep's, the others are cleared and redone in the new layout. A run that raises
is recorded in the ``errors`` table (same partition layout: run_id, scenario, error_type,
message, traceback, seconds) and the sweep goes on; its error partition is removed once it
succeeds. Folders starting with ``_`` are ignored by pyarrow, DuckDB's and polars' Hive readers.

Every run (of a sweep or of :func:`execute`) starts from cold caches (no world or planner cache
of an earlier run in the same process), so its wall-clock columns mean the same whatever the
number of workers and the order of the runs: every allocator pays for its own cost matrices.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import signal
import tempfile
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dispatch import __version__
from dispatch.config.runkeys import RUN_KEYS, key_names, point_settings
from dispatch.config.scenario import RunSpec
from dispatch.output.parquet import SCHEMAS, Recorder, json_meta, partition_path, write_atomic
from dispatch.run.time_limit import PastTimeLimit, time_limit_of

log = logging.getLogger(__name__)

MARKERS = "_runs"
ERRORS = "errors"
ERRORS_SCHEMA = pa.schema([("run_id", pa.string()), ("scenario", pa.string()),
                           ("error_type", pa.string()), ("message", pa.string()),
                           ("traceback", pa.string()), ("seconds", pa.float64())])


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
    back where ``SCHEMAS[name]`` has them."""
    table = pq.read_table(path)
    schema = SCHEMAS[name]
    for k, v in partition.items():
        if k in schema.names and k not in table.column_names:
            field = schema.field(k)
            i = schema.get_field_index(k)
            table = table.add_column(i, field, pa.array([v] * table.num_rows, field.type))
    return table.select(schema.names)


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
    """The recorder of ``spec`` writing into its partition of ``out``."""
    return Recorder(Path(out), spec.run_id, run_metadata(spec), spec.partition,
                    flush_rows=flush_rows)


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
    from dispatch.config.scenario import safe_name

    return Path("runs") / safe_name(spec.scenario.name)


def holds_results(out: Path, spec: RunSpec) -> bool:
    """Whether ``out`` already holds results (complete or not) of ``spec``'s partition (or
    of the partition an older version wrote the same run into, :func:`legacy_variant`)."""
    old = legacy_variant(spec)
    for run in (spec,) if old is None else (spec, old):
        if marker_path(out, run).exists():
            return True
        if any((Path(out) / table / partition_dir(run)).is_dir()
               and any((Path(out) / table / partition_dir(run)).iterdir())
               for table in ("summary", ERRORS)):
            return True
    return False


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


@dataclass
class Outcome:
    """What became of one run of a sweep. ``status``: ``done`` (run now), ``skipped`` (complete
    from an earlier sweep) or ``failed`` (``error`` says why; recorded in the errors table)."""

    spec: RunSpec
    status: str
    summary: dict | None = None
    error: str = ""
    seconds: float = 0.0
    files: list[str] = field(default_factory=list)
    traceback: str = ""  # of a failed run (also in the errors table); -v / --debug print it

    @property
    def run_id(self) -> str:
        return self.spec.run_id


def partition_dir(spec: RunSpec) -> Path:
    return partition_path(spec.partition)


def marker_path(out: Path, spec: RunSpec) -> Path:
    return Path(out) / MARKERS / partition_dir(spec) / "done.json"


def _digest(spec: RunSpec) -> str:
    """SHA-256 of the whole scenario text (the markers' ``scenario_sha256``)."""
    return hashlib.sha256(spec.scenario.text.encode()).hexdigest()


#: Keys a sweep (or a run's point) sets: left out of a scenario's base settings
_POINT_KEYS = point_settings()


def _base_settings(text: str) -> dict | None:
    """The settings of a scenario text without its ``[sweep]`` and without the keys a run's
    point overrides (None: the text does not parse)."""
    import tomllib

    try:
        doc = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, TypeError):
        return None
    for table, keys in _POINT_KEYS.items():
        t = doc if not table else doc.get(table)
        if isinstance(t, dict):
            for k in keys:
                t.pop(k, None)
    return doc


def _sha(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def base_digest(text: str) -> str | None:
    """SHA-256 of :func:`_base_settings` (None: the text does not parse)."""
    doc = _base_settings(text)
    return None if doc is None else _sha(doc)


def run_digest(spec: RunSpec, text: str | None = None) -> str | None:
    """What identifies a run's results: SHA-256 of the base settings of ``text`` (default:
    the spec's scenario text) and the spec's point. Two scenario texts that differ only in
    their ``[sweep]`` lists, comments or the values a sweep overrides give their common runs
    the same digest. None: the text does not parse."""
    doc = _base_settings(spec.scenario.text if text is None else text)
    if doc is None:
        return None
    keys = spec.keys
    return _sha({"base": doc, "run_id": spec.run_id,
                 **{k.digest: keys[k.name] for k in RUN_KEYS if k.digest}})


def _stored_text(out: Path, partition: Path) -> str | None:
    """The scenario text a finished run was made from (its summary file's metadata)."""
    try:
        meta = pq.read_schema(Path(out) / "summary" / partition / "part-0.parquet").metadata
        return meta[b"dispatch.scenario"].decode()
    except (OSError, KeyError, TypeError, AttributeError, pa.ArrowException):
        return None


def is_complete(out: Path, spec: RunSpec) -> bool:
    """Whether ``spec``'s partition was finished by a sweep of the same run (the same scenario
    text, or one whose :func:`run_digest` for this run is the same) and all of its files are
    still there, whole."""
    try:
        marker = json.loads(marker_path(out, spec).read_text(encoding="utf-8"))
        if marker["run_id"] != spec.run_id:
            return False
        if marker["scenario_sha256"] != _digest(spec):  # another text: is it the same run?
            want = run_digest(spec)
            got = marker.get("run_sha256")
            if got is None:  # a marker written before run digests: ask the run's own text
                text = _stored_text(out, partition_dir(spec))
                got = None if text is None else run_digest(spec, text)
            if want is None or got != want:
                return False
        for rel, size in marker["files"].items():
            if (Path(out) / rel).stat().st_size != size:
                return False
        return bool(marker["files"])
    except (OSError, ValueError, KeyError, TypeError):
        return False


def clear_partition(out: Path, spec: RunSpec) -> None:
    """Remove a run's marker (first), then every file of its partition in every table (and a
    marker half-written by a process killed meanwhile)."""
    marker = marker_path(out, spec)
    marker.unlink(missing_ok=True)
    if marker.parent.is_dir():
        for f in marker.parent.glob(f".{marker.name}.tmp-*"):
            f.unlink(missing_ok=True)
    for table in (*SCHEMAS, ERRORS):
        leaf = Path(out) / table / partition_dir(spec)
        if leaf.is_dir():
            for f in leaf.iterdir():
                if f.is_file():
                    f.unlink()


def _write_json_atomic(obj: dict, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=1, sort_keys=True), encoding="utf-8")
    os.replace(tmp, path)


def record_failure(out: Path, spec: RunSpec, error_type: str, message: str, tb: str,
                   seconds: float) -> None:
    """Write the run's row of the ``errors`` table (its own partition)."""
    meta = {"dispatch.version": __version__, "dispatch.run_id": spec.run_id,
            "dispatch.scenario": spec.scenario.text, "dispatch.seed": str(spec.seed)}
    schema = ERRORS_SCHEMA  # the partition columns live in the path, not in the file
    for k in spec.partition:
        if k in schema.names:
            schema = schema.remove(schema.get_field_index(k))
    row = {"run_id": spec.run_id, "scenario": spec.scenario.name, "error_type": error_type,
           "message": message, "traceback": tb, "seconds": seconds}
    table = pa.Table.from_pylist([{k: row[k] for k in schema.names}],
                                 schema=schema.with_metadata(meta))
    write_atomic(table, Path(out) / ERRORS / partition_dir(spec) / "part-0.parquet")


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
    _write_json_atomic({"run_id": spec.run_id, "scenario_sha256": _digest(spec),
                        "run_sha256": run_digest(spec),
                        "base_sha256": base_digest(spec.scenario.text),
                        "version": __version__, "seconds": seconds, "files": files},
                       marker_path(out, spec))
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


def foreign_runs(out: Path, specs: list[RunSpec]) -> list[str]:
    """Run ids of complete partitions in ``out`` written from another scenario than
    ``specs``' (another scenario, or another version of this one: other settings outside
    ``[sweep]``): readers of ``out`` will see them next to this sweep's runs. Runs of the same
    scenario with another sweep list (a value since dropped from it) are not foreign."""
    texts = {_digest(s) for s in specs}
    bases = {base_digest(t) for t in {s.scenario.text for s in specs}} - {None}
    found = []
    root = Path(out) / MARKERS
    for m in sorted(root.rglob("done.json")):
        try:
            marker = json.loads(m.read_text(encoding="utf-8"))
            if marker["scenario_sha256"] in texts:
                continue
            base = marker.get("base_sha256")
            if base is None:  # a marker written before base digests
                text = _stored_text(out, m.parent.relative_to(root))
                base = None if text is None else base_digest(text)
            if base is None or base not in bases:
                found.append(marker["run_id"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return found


def legacy_variant(spec: RunSpec) -> RunSpec | None:
    """The run as versions before the batch window was a run key wrote it (None for a
    scenario that does not sweep its window): a scenario of its own, ``<name>-immediate`` (0
    s) or ``<name>-batch<w>s``, without a ``batch_window=`` level or run-id part. A sweep
    over such a folder takes its complete runs as this spec's (same text or same
    :func:`run_digest`, as for any run) and clears the others, so that the folder holds each
    run once; :mod:`analysis.io` reads them as scenario ``<name>`` with their window."""
    if not spec.names_batch_window:
        return None
    sc, w = spec.scenario, spec.batch_window
    name = f"{sc.name}-{'immediate' if w == 0 else f'batch{w:g}s'}"
    return replace(spec, scenario=replace(sc, name=name,
                                          sweep=replace(sc.sweep, batch_window=())))


def read_summary(out: Path, spec: RunSpec) -> dict:
    """The summary row of a finished partition, with its partition columns put back."""
    path = Path(out) / "summary" / partition_dir(spec) / "part-0.parquet"
    row = pq.read_table(path).to_pylist()[0]
    return {**row, **spec.partition}


def sweep(
    specs: list[RunSpec],
    out: Path,
    *,
    workers: int | None = None,
    ray: bool = False,
    address: str | None = None,
    force: bool = False,
    on_done: Callable[[Outcome], None] | None = None,
    time_limit: float | None = None,
) -> list[Outcome]:
    """Run ``specs`` into the Hive-partitioned folder ``out``, skipping complete runs.

    ``workers``: processes of the local pool (default: the CPU count; 1 runs in this process)
    or CPUs of a local Ray instance. ``ray``: run every run as a Ray task, on the cluster at
    ``address`` or on a local Ray started here (workers of a cluster need this package
    installed and ``out`` on a file system they share). ``force``: redo complete runs too.
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
        done = None if force else spec if is_complete(out, spec) else \
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
            stream = _on_ray(todo, out, workers, address, time_limit)
        elif workers == 1:
            stream = ((i, run_partition(spec, out, time_limit)) for i, spec in todo)
        else:
            stream = _on_pool(todo, out, workers, time_limit)
        with _sigterm_exits():
            try:
                for i, outcome in stream:
                    outcomes[i] = outcome
                    if on_done is not None:
                        on_done(outcome)
            finally:
                stream.close()  # (every stream is a generator: a pool's stops its workers now)
    return [outcomes[i] for i in range(len(specs))]


class SweepTerminated(SystemExit):
    """Raised in a sweep when its process gets SIGTERM (exit status 143, as the signal's
    default), so that ``finally`` blocks run: the pool's workers are stopped, not orphaned."""


@contextmanager
def _sigterm_exits():
    """While in the block (in the main thread), SIGTERM raises :class:`SweepTerminated`
    instead of ending the process at once; the previous handler is put back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, _frame):
        raise SweepTerminated(128 + signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _exit_with_parent(parent: int) -> None:
    """Pool worker initializer: a daemon thread ends this worker when its parent is gone (a
    parent killed with SIGKILL runs no cleanup; its workers must not go on writing)."""
    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _stop_workers(pool) -> None:
    """Terminate the processes of a ProcessPoolExecutor now (SIGTERM, then SIGKILL for any
    still alive after 5 s): their runs are abandoned half-way, to be redone by a rerun."""
    procs = list((pool._processes or {}).values())  # (None once the pool is shut down)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    deadline = time.monotonic() + 5.0
    for proc in procs:
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)


def _crashed(out: Path, spec: RunSpec, e: BaseException) -> Outcome:
    """A run whose worker died (no Python exception came back from it)."""
    msg = f"worker died: {type(e).__name__}: {e}"
    record_failure(out, spec, type(e).__name__, msg, "", 0.0)
    return Outcome(spec, "failed", error=msg)


def _on_pool(todo, out: Path, workers: int, time_limit: float | None = None
             ) -> Iterator[tuple[int, Outcome]]:
    """A spawn-context process pool, ``workers`` runs in flight at a time; if a worker dies
    the runs it held are recorded as failed and a fresh pool takes the rest."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    pending = deque(todo)
    while pending:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(pending)), mp_context=ctx,
                                   initializer=_exit_with_parent, initargs=(os.getpid(),))
        running: dict = {}
        try:
            broken = False
            while (pending or running) and not broken:
                while pending and len(running) < workers:
                    i, spec = pending.popleft()
                    running[pool.submit(run_partition, spec, str(out), time_limit)] = (i, spec)
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    i, spec = running.pop(fut)
                    try:
                        yield i, fut.result()
                    except BrokenProcessPool as e:
                        broken = True
                        yield i, _crashed(out, spec, e)
            for i, spec in running.values():  # the pool broke under them
                yield i, _crashed(out, spec, BrokenProcessPool("the process pool broke"))
        except BaseException:  # SIGTERM, Ctrl-C, the consumer stopped: no orphan workers
            _stop_workers(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _on_ray(todo, out: Path, workers: int, address: str | None,
            time_limit: float | None = None) -> Iterator[tuple[int, Outcome]]:
    """One Ray task per run (local Ray with ``workers`` CPUs, or the cluster at ``address``)."""
    try:
        import ray
    except ImportError as e:
        from dispatch.errors import DispatchError

        raise DispatchError("--ray needs Ray: pip install 'dispatch-sim[ray]'") from e
    started = False
    if not ray.is_initialized():
        opts = {"include_dashboard": False, "log_to_driver": False}
        if address:
            ray.init(address=address, **opts)
        else:
            ray.init(num_cpus=workers, **opts)
        started = True
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(run_partition)
        refs = {task.remote(spec, str(out), time_limit): (i, spec) for i, spec in todo}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                i, spec = refs[ref]
                try:
                    yield i, ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a dead worker, a lost node
                    yield i, _crashed(out, spec, e)
    finally:
        if started:
            ray.shutdown()
