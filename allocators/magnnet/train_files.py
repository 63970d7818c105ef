"""What the MAGNNET trainers write besides their checkpoints: the training log as Parquet and
matplotlib for the curves (shared by the imitation trainers and the PPO trainer)."""

from __future__ import annotations

import logging
from pathlib import Path

log = logging.getLogger(__name__)


def write_log(rows, out: Path) -> None:
    """``log.parquet``: one column per key any row has (null where a row lacks it)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    keys = sorted({k for r in rows for k in r})
    pq.write_table(pa.table({k: [r.get(k) for r in rows] for k in keys}), out / "log.parquet")


def pyplot():
    """matplotlib's pyplot on the headless Agg backend, or None (logged) when it is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning("matplotlib missing: no figures")
        return None
    return plt
