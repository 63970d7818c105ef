"""One run's tables, read for the replay: the run's Parquet files found and read one by one,
so that a damaged file is named in the error, and the run chosen among a folder's runs.

A results folder (``dispatch run`` or ``dispatch sweep``; Hive layout) keeps each run's rows
of a table in one leaf folder ``<table>/k=v/.../part-0.parquet`` whose schema metadata names
the run (``dispatch.run_id``). Reads with pyarrow only; nothing of ``dispatch``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from analysis.io import NoResultsError, find_sources, legacy_values

#: the tables the replay reads (a missing one reads as empty)
TABLES = ("summary", "tasks", "vehicles", "events", "decisions", "assignments", "soc",
          "chargers", "obstacles", "legs")


class ReplayInputError(ValueError):
    """A results folder the replay cannot use: said in one line naming the folder or file."""


@dataclass
class RunFiles:
    """The files of one run: table name -> its Parquet files; the run's schema metadata."""

    run_id: str
    root: Path
    files: dict[str, list[Path]] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)


def _schema(path: Path) -> pa.Schema:
    try:
        return pq.read_schema(path)
    except (pa.ArrowInvalid, OSError) as e:
        raise ReplayInputError(f"{path}: not a readable Parquet file "
                               f"({' '.join(str(e).split())})") from None


def _parquet_files(table_dir: Path) -> list[Path]:
    out = []
    for root, dirs, files in os.walk(table_dir):
        dirs[:] = sorted(d for d in dirs if not d.startswith(("_", ".")))
        out += [Path(root) / f for f in sorted(files)
                if f.endswith(".parquet") and not f.startswith(("_", "."))]
    return out


def find_runs(folder: str | os.PathLike) -> dict[str, RunFiles]:
    """The runs under ``folder`` (a results folder or a folder holding some), by run id."""
    folder = Path(folder)
    try:
        sources = find_sources(folder)
    except NoResultsError as e:
        raise ReplayInputError(str(e)) from None
    runs: dict[str, RunFiles] = {}
    for src in sources:
        if src.kind != "hive":
            raise ReplayInputError(f"{src.path}: results of an older version (flat "
                                   "<table>.parquet files); the replay reads the Hive layout "
                                   "of dispatch run / dispatch sweep")
        for table in TABLES:
            for path in _parquet_files(src.path / table):
                meta = {k.decode(): v.decode() for k, v in
                        (_schema(path).metadata or {}).items()}
                rid = meta.get("dispatch.run_id")
                if rid is None:
                    raise ReplayInputError(f"{path}: no dispatch.run_id in its metadata "
                                           "(not written by dispatch)")
                run = runs.setdefault(rid, RunFiles(rid, src.path))
                run.files.setdefault(table, []).append(path)
                if table == "summary":
                    run.metadata = meta
    runs = {k: v for k, v in runs.items() if "summary" in v.files}
    if not runs:
        raise ReplayInputError(f"{folder}: no run (no summary/.../part-0.parquet below it)")
    return runs


def choose_run(folder: str | os.PathLike, run_id: str | None) -> RunFiles:
    """The run ``run_id`` of ``folder``, or its only run; a one-line error otherwise."""
    runs = find_runs(folder)
    if run_id is None:
        if len(runs) > 1:
            ids = sorted(runs)
            more = f", ... ({len(ids)} runs)" if len(ids) > 4 else ""
            raise ReplayInputError(f"{folder}: holds {len(ids)} runs; choose one with --run "
                                   f"({', '.join(ids[:4])}{more})")
        return next(iter(runs.values()))
    if run_id not in runs:
        raise ReplayInputError(f"{folder}: no run {run_id!r} (runs: "
                               f"{', '.join(sorted(runs)[:4])}{', ...' if len(runs) > 4 else ''})")
    return runs[run_id]


def read_table(run: RunFiles, table: str, won_only: bool = False) -> pd.DataFrame:
    """One table of the run (empty DataFrame where the run has none); ``won_only``: of the
    assignments, only the rows that won."""
    frames = []
    for path in run.files.get(table, []):
        try:
            t = pq.read_table(path, filters=[("won", "==", True)] if won_only else None)
        except (pa.ArrowInvalid, OSError) as e:
            raise ReplayInputError(f"{path}: not a readable Parquet file "
                                   f"({' '.join(str(e).split())})") from None
        frames.append(t.to_pandas())
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    if "run_id" in df.columns:
        df = df.loc[df["run_id"] == run.run_id].reset_index(drop=True)
    return legacy_values(df)  # (an older run's "cancelled": cut_off)


def transit_of(legs: pd.DataFrame, ox: float, oy: float, arr) -> dict | None:
    """The page's riders off the fleet (a run with ``[transit]``: its ``legs`` table): the
    stations the legs name (``sx``, ``sy``, ``sid``) and each train or walk leg (``mode`` 1
    train, 2 walk; ``t0``, ``t1``; from ``x0``, ``y0`` to ``x1``, ``y1``), sorted by start, and
    the longest leg's seconds (``span``); positions relative to ``(ox, oy)``, arrays made by
    ``arr(values, dtype)``. None without legs. The page draws a rider on a train or on foot as
    a dot moving in a straight line from stop to stop."""
    if legs is None or not len(legs):
        return None
    at = pd.concat([legs[["from_stop_id", "from_x", "from_y"]].set_axis(["s", "x", "y"], axis=1),
                    legs[["to_stop_id", "to_x", "to_y"]].set_axis(["s", "x", "y"], axis=1)])
    at = at.dropna(subset=["s"]).drop_duplicates("s").sort_values("s")
    off = legs.loc[legs["mode"] != "fleet"].sort_values("start", kind="stable")
    code = off["mode"].map({"train": 1, "walk": 2}).to_numpy()
    return {"sid": [str(s) for s in at["s"]], "sx": arr(at["x"] - ox, np.float32),
            "sy": arr(at["y"] - oy, np.float32), "mode": arr(code, np.uint8),
            "t0": arr(off["start"], np.float64), "t1": arr(off["end"], np.float64),
            "x0": arr(off["from_x"] - ox, np.float32), "y0": arr(off["from_y"] - oy, np.float32),
            "x1": arr(off["to_x"] - ox, np.float32), "y1": arr(off["to_y"] - oy, np.float32),
            "span": float((off["end"] - off["start"]).max()) if len(off) else 0.0}
