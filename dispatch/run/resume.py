"""What a results folder holds of a sweep's runs: completion markers, run digests and the
``errors`` table, so that a rerun skips what is done and redoes the rest.

Once all of a run's tables are written (:mod:`dispatch.run.runner`), it gets a completion marker
``out/_runs/<partition>/done.json`` (written atomically) that lists the files and their sizes.
Rerunning a sweep (or a sweep over the output of ``dispatch run``) skips every run whose marker
is there, names the same run of the same scenario and whose files are all present with those
sizes; any other run (never started, killed half-way, failed, or its files touched since) is
cleared and run again. "The same run" is :func:`run_digest`: the scenario's settings outside
``[sweep]`` (parsed, so comments and layout do not count) and the run's own point (allocator,
planner, repositioner, N, seed, batch window). Adding a value to a sweep list therefore runs
only the new runs, and removing one leaves its runs in the folder (:func:`foreign_runs` does
not count them as another scenario's). A folder written before the batch window was a run key
(each window a scenario ``<name>-batch30s``, :func:`legacy_variant`) resumes too: its complete
runs count as this sweep's, the others are cleared and redone in the new layout. A run that
raises is recorded in the ``errors`` table (same partition layout: run_id, scenario,
error_type, message, traceback, seconds); its error partition is removed once it succeeds.
Folders starting with ``_`` are ignored by pyarrow, DuckDB's and polars' Hive readers.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import replace
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from dispatch import __version__
from dispatch.config.runkeys import RUN_KEYS, point_settings
from dispatch.config.scenario import RunSpec
from dispatch.output.legs import OPTIONAL_SCHEMAS
from dispatch.output.parquet import SCHEMAS, partition_path, write_atomic

MARKERS = "_runs"
ERRORS = "errors"
ERRORS_SCHEMA = pa.schema([("run_id", pa.string()), ("scenario", pa.string()),
                           ("error_type", pa.string()), ("message", pa.string()),
                           ("traceback", pa.string()), ("seconds", pa.float64())])


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
    for table in (*SCHEMAS, *OPTIONAL_SCHEMAS, ERRORS):
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


def write_marker(out: Path, spec: RunSpec, seconds: float, files: dict[str, int]) -> None:
    """Mark ``spec``'s partition of ``out`` complete: its digests, the wall ``seconds`` the run
    took and its ``files`` (path relative to ``out``: size in bytes)."""
    _write_json_atomic({"run_id": spec.run_id, "scenario_sha256": _digest(spec),
                        "run_sha256": run_digest(spec),
                        "base_sha256": base_digest(spec.scenario.text),
                        "version": __version__, "seconds": seconds, "files": files},
                       marker_path(out, spec))


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
    with pq.ParquetFile(path) as f:  # (pq.read_table would import pyarrow.dataset and pandas)
        row = f.read().to_pylist()[0]
    return {**row, **spec.partition}


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
