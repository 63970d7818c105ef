"""Where a sweep's runs execute: a local pool of spawned processes or Ray tasks, each run a call
of the task the sweep hands in (:func:`dispatch.run.runner.run_partition`), its
:class:`Outcome` streamed back as it finishes. A worker that dies is recorded as a failed run;
SIGTERM stops the workers instead of orphaning them."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from dispatch.config.scenario import RunSpec
from dispatch.errors import DispatchError
from dispatch.run.resume import record_failure

#: a sweep's task: ``(spec, out, time_limit) -> Outcome`` (a top-level function: spawn-safe)
Task = Callable[[RunSpec, str, "float | None"], "Outcome"]


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


class SweepTerminated(SystemExit):
    """Raised in a sweep when its process gets SIGTERM (exit status 143, as the signal's
    default), so that ``finally`` blocks run: the pool's workers are stopped, not orphaned."""


@contextmanager
def sigterm_exits():
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


def exit_with_parent(parent: int) -> None:
    """Pool worker initializer: a daemon thread ends this worker when its parent is gone (a
    parent killed with SIGKILL runs no cleanup; its workers must not go on writing)."""
    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def stop_workers(pool) -> None:
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


def crashed(out: Path, spec: RunSpec, e: BaseException) -> Outcome:
    """A run whose worker died (no Python exception came back from it)."""
    msg = f"worker died: {type(e).__name__}: {e}"
    record_failure(out, spec, type(e).__name__, msg, "", 0.0)
    return Outcome(spec, "failed", error=msg)


def on_pool(todo, out: Path, workers: int, task: Task, time_limit: float | None = None
            ) -> Iterator[tuple[int, Outcome]]:
    """``task(spec, out, time_limit)`` of each ``(i, spec)`` of ``todo`` on a spawn-context
    process pool, ``workers`` runs in flight at a time, yielding ``(i, outcome)`` as they end;
    if a worker dies the runs it held are recorded as failed and a fresh pool takes the rest."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    pending = deque(todo)
    while pending:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(pending)), mp_context=ctx,
                                   initializer=exit_with_parent, initargs=(os.getpid(),))
        running: dict = {}
        try:
            broken = False
            while (pending or running) and not broken:
                while pending and len(running) < workers:
                    i, spec = pending.popleft()
                    running[pool.submit(task, spec, str(out), time_limit)] = (i, spec)
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    i, spec = running.pop(fut)
                    try:
                        yield i, fut.result()
                    except BrokenProcessPool as e:
                        broken = True
                        yield i, crashed(out, spec, e)
            for i, spec in running.values():  # the pool broke under them
                yield i, crashed(out, spec, BrokenProcessPool("the process pool broke"))
        except BaseException:  # SIGTERM, Ctrl-C, the consumer stopped: no orphan workers
            stop_workers(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def on_ray(todo, out: Path, workers: int, address: str | None, task: Task,
           time_limit: float | None = None) -> Iterator[tuple[int, Outcome]]:
    """One Ray task of ``task`` per run (local Ray with ``workers`` CPUs, or the cluster at
    ``address``), yielding ``(i, outcome)`` as they end."""
    try:
        import ray
    except ImportError as e:
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
        remote = ray.remote(num_cpus=1, max_retries=0)(task)
        refs = {remote.remote(spec, str(out), time_limit): (i, spec) for i, spec in todo}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                i, spec = refs[ref]
                try:
                    yield i, ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a dead worker, a lost node
                    yield i, crashed(out, spec, e)
    finally:
        if started:
            ray.shutdown()
