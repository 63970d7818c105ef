"""Running runs: one after another (:func:`execute`), or as a resumable sweep (:func:`sweep`)
on a local process pool or on Ray.

A sweep writes every run into its own Hive partition of ``out`` (``<table>/allocator=…/
planner=…/n_agents=…/seed=…/part-0.parquet``) and, once all of its tables are written, a
completion marker ``out/_runs/<partition>/done.json`` (written atomically) that lists the files
and their sizes. Rerunning the sweep skips every run whose marker is there, names the same
scenario text and whose files are all present with those sizes; any other run (never started,
killed half-way, failed, or its files touched since) is cleared and run again. A run that raises
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
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dispatch import __version__
from dispatch.recorder import SCHEMAS, write_atomic, write_run
from dispatch.scenario import RunSpec

log = logging.getLogger(__name__)

MARKERS = "_runs"
ERRORS = "errors"
ERRORS_SCHEMA = pa.schema([("run_id", pa.string()), ("scenario", pa.string()),
                           ("error_type", pa.string()), ("message", pa.string()),
                           ("traceback", pa.string()), ("seconds", pa.float64())])


@dataclass
class RunResult:
    spec: RunSpec
    summary: dict
    tables: dict


def run_one(spec: RunSpec):
    """Simulate one run and return its RunResult (nothing written)."""
    from dispatch.recorder import Recorder
    from dispatch.sim import Simulation

    rec = Recorder(spec.run_id, {})
    summary = Simulation(spec, rec).run()
    return RunResult(spec, summary, rec.tables())


def default_out(spec: RunSpec) -> Path:
    return Path("runs") / spec.scenario.name


def execute(
    specs: list[RunSpec],
    out: Path,
    *,
    partitioned: bool | None = None,
    on_done: Callable[[Any], None] | None = None,
) -> list[dict]:
    """Run every spec in order, writing each run's tables as soon as it finishes.

    ``partitioned`` chooses the Hive layout (default: when there is more than one run). Each run
    starts from cold caches, as in :func:`sweep`.
    Returns the summaries in the order of ``specs``.
    """
    if partitioned is None:
        partitioned = len(specs) > 1
    summaries = []
    for spec in specs:
        _cold_start()
        result = run_one(spec)
        write_run(result.tables, out, spec.partition if partitioned else None)
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

    @property
    def run_id(self) -> str:
        return self.spec.run_id


def partition_dir(spec: RunSpec) -> Path:
    return Path(*(f"{k}={v}" for k, v in spec.partition.items()))


def marker_path(out: Path, spec: RunSpec) -> Path:
    return Path(out) / MARKERS / partition_dir(spec) / "done.json"


def _digest(spec: RunSpec) -> str:
    return hashlib.sha256(spec.scenario.text.encode()).hexdigest()


def is_complete(out: Path, spec: RunSpec) -> bool:
    """Whether ``spec``'s partition was finished by a sweep of the same scenario text and all
    of its files are still there, whole."""
    try:
        marker = json.loads(marker_path(out, spec).read_text(encoding="utf-8"))
        if marker["run_id"] != spec.run_id or marker["scenario_sha256"] != _digest(spec):
            return False
        for rel, size in marker["files"].items():
            if (Path(out) / rel).stat().st_size != size:
                return False
        return bool(marker["files"])
    except (OSError, ValueError, KeyError, TypeError):
        return False


def clear_partition(out: Path, spec: RunSpec) -> None:
    """Remove a run's marker (first), then every file of its partition in every table."""
    marker_path(out, spec).unlink(missing_ok=True)
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
    table = pa.Table.from_pylist(
        [{"run_id": spec.run_id, "scenario": spec.scenario.name, "error_type": error_type,
          "message": message, "traceback": tb, "seconds": seconds}],
        schema=ERRORS_SCHEMA.with_metadata(meta))
    write_atomic(table, Path(out) / ERRORS / partition_dir(spec) / "part-0.parquet")


def run_partition(spec: RunSpec, out: str | Path) -> Outcome:
    """Run one spec of a sweep into its partition of ``out`` and mark it complete; an
    exception is recorded in the errors table and returned as a failed :class:`Outcome`.
    This is what pool workers and Ray tasks execute (a top-level function: spawn-safe)."""
    out = Path(out)
    started = time.perf_counter()
    clear_partition(out, spec)
    try:
        _cold_start()
        result = run_one(spec)
        paths = write_run(result.tables, out, spec.partition)
    except Exception as e:  # noqa: BLE001 - any failure of one run is recorded, not raised
        seconds = time.perf_counter() - started
        log.warning("%s failed: %s: %s", spec.run_id, type(e).__name__, e)
        record_failure(out, spec, type(e).__name__, str(e), traceback.format_exc(), seconds)
        return Outcome(spec, "failed", error=f"{type(e).__name__}: {e}", seconds=seconds)
    seconds = time.perf_counter() - started
    files = {str(p.relative_to(out)): p.stat().st_size for p in paths}
    _write_json_atomic({"run_id": spec.run_id, "scenario_sha256": _digest(spec),
                        "version": __version__, "seconds": seconds, "files": files},
                       marker_path(out, spec))
    return Outcome(spec, "done", summary={"run_id": spec.run_id, **result.summary},
                   seconds=seconds, files=sorted(files))


def _cold_start() -> None:
    """Forget the worlds (and the planner caches kept on their grids) of earlier runs in this
    process, so that a run's timing columns (cost_seconds, alloc_seconds, …) do not depend on
    which runs the same worker happened to do before it: a sweep gives the same kind of
    measurement on 1 process, K processes or Ray."""
    from dispatch.sim import world_for

    world_for.cache_clear()


def foreign_runs(out: Path, specs: list[RunSpec]) -> list[str]:
    """Run ids of complete partitions in ``out`` written from another scenario text than
    ``specs``' (another scenario, or an earlier version of this one): readers of ``out`` will
    see them next to this sweep's runs."""
    texts = {_digest(s) for s in specs}
    found = []
    for m in sorted((Path(out) / MARKERS).rglob("done.json")):
        try:
            marker = json.loads(m.read_text(encoding="utf-8"))
            if marker["scenario_sha256"] not in texts:
                found.append(marker["run_id"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return found


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
) -> list[Outcome]:
    """Run ``specs`` into the Hive-partitioned folder ``out``, skipping complete runs.

    ``workers``: processes of the local pool (default: the CPU count; 1 runs in this process)
    or CPUs of a local Ray instance. ``ray``: run every run as a Ray task, on the cluster at
    ``address`` or on a local Ray started here (workers of a cluster need this package
    installed and ``out`` on a file system they share). ``force``: redo complete runs too.
    ``on_done`` is called in this process as each run finishes or is skipped. Returns the
    outcomes in the order of ``specs``.
    """
    out = Path(out).resolve()
    outcomes: dict[int, Outcome] = {}
    todo: list[tuple[int, RunSpec]] = []
    for i, spec in enumerate(specs):
        if not force and is_complete(out, spec):
            try:
                outcomes[i] = Outcome(spec, "skipped", summary=read_summary(out, spec))
            except (OSError, pa.ArrowException, IndexError):
                todo.append((i, spec))
                continue
            if on_done is not None:
                on_done(outcomes[i])
        else:
            todo.append((i, spec))
    if todo:
        workers = workers or os.cpu_count() or 1
        if ray:
            stream = _on_ray(todo, out, workers, address)
        elif workers == 1:
            stream = ((i, run_partition(spec, out)) for i, spec in todo)
        else:
            stream = _on_pool(todo, out, workers)
        for i, outcome in stream:
            outcomes[i] = outcome
            if on_done is not None:
                on_done(outcome)
    return [outcomes[i] for i in range(len(specs))]


def _crashed(out: Path, spec: RunSpec, e: BaseException) -> Outcome:
    """A run whose worker died (no Python exception came back from it)."""
    msg = f"worker died: {type(e).__name__}: {e}"
    record_failure(out, spec, type(e).__name__, msg, "", 0.0)
    return Outcome(spec, "failed", error=msg)


def _on_pool(todo, out: Path, workers: int) -> Iterator[tuple[int, Outcome]]:
    """A spawn-context process pool, ``workers`` runs in flight at a time; if a worker dies
    the runs it held are recorded as failed and a fresh pool takes the rest."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    pending = deque(todo)
    while pending:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(pending)), mp_context=ctx)
        running: dict = {}
        try:
            broken = False
            while (pending or running) and not broken:
                while pending and len(running) < workers:
                    i, spec = pending.popleft()
                    running[pool.submit(run_partition, spec, str(out))] = (i, spec)
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
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _on_ray(todo, out: Path, workers: int, address: str | None) -> Iterator[tuple[int, Outcome]]:
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
        refs = {task.remote(spec, str(out)): (i, spec) for i, spec in todo}
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
