"""Running a list of runs (one, or a sweep's expansion) and writing their Parquet output."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from dispatch.recorder import write_run
from dispatch.scenario import RunSpec
from dispatch.sim import RunResult, Simulation

log = logging.getLogger(__name__)


def run_one(spec: RunSpec) -> RunResult:
    """Simulate one run and return its summary and tables (nothing written)."""
    return Simulation(spec).run()


def default_out(spec: RunSpec) -> Path:
    return Path("runs") / spec.scenario.name


def execute(
    specs: list[RunSpec],
    out: Path,
    *,
    partitioned: bool | None = None,
    on_done: Callable[[RunResult], None] | None = None,
) -> list[dict]:
    """Run every spec in order, writing each run's tables as soon as it finishes.

    ``partitioned`` chooses the Hive layout (default: when there is more than one run).
    Returns the summaries in the order of ``specs``.
    """
    if partitioned is None:
        partitioned = len(specs) > 1
    summaries = []
    for spec in specs:
        result = run_one(spec)
        write_run(result.tables, out, spec.partition if partitioned else None)
        summaries.append(result.summary)
        log.info("%s: total cost %.2f s", spec.run_id, result.summary["total_cost"])
        if on_done is not None:
            on_done(result)
    return summaries
