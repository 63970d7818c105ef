"""Reading results: a results folder (of ``dispatch run`` or ``dispatch sweep``), or a folder of
those.

Layout (``kind == "hive"``), the same for one run and for many: one folder per table,
``<table>/scenario=…/allocator=…/planner=…/n_agents=…/seed=…/part-0.parquet``; the partition
columns live in the path (Hive), not in the files. Folders written before the scenario was a
partition (``<table>/allocator=…/…``, the scenario in the summary files) are read too. Files whose names start with ``_`` or ``.`` (chunks of a
run still going or killed half-way, temporary files) are not read.

Results of older versions, where a single run wrote ``<table>.parquet`` files
(``kind == "flat"``), are read too.

A scenario that declares repositioning (``[reposition]``) has one more level,
``…/planner=…/reposition=…/n_agents=…``; every other layout, older ones included, has none,
and its runs read as ``reposition = "stay"`` (idle vehicles waited where they were, the only
behaviour before repositioners existed). A scenario that sweeps its batch window (``[sweep]
batch_window``) has a ``batch_window=…`` level before ``n_agents=…``; every summary has a
``batch_window`` column. Folders written before the batch window was a run key named each
window a scenario of its own (``<name>-immediate``, ``<name>-batch30s``): their runs read as
scenario ``<name>`` with their window, found from the scenario text their files carry (as is
the window of a run of an older version that did not sweep it).

Which columns name a run is the writer's to say: every file of a run lists them in its
``dispatch.run_keys`` metadata (:attr:`Results.run_keys`); folders written before that read
with :data:`paired.compare.FALLBACK_RUN_KEYS`.

:func:`open_results` takes any number of such folders (or folders that contain them) and gives
one :class:`Results`, whose :meth:`Results.table` returns a pandas DataFrame in which every
table carries the run's keys (``scenario``, ``allocator``, ``planner``, ``reposition``,
``batch_window``, ``n_agents``, ``seed``) whatever the layout. Only pyarrow and pandas are needed: no torch, no PyBullet, not even the
``dispatch`` package.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from paired.compare import FALLBACK_RUN_KEYS, KEY_DEFAULTS, RUN_KEYS_ATTR

TABLES = ("summary", "tasks", "assignments", "decisions", "events", "vehicles", "obstacles")
#: The columns that name a run in folders that do not list theirs (the writer's list, from the
#: files, is :attr:`Results.run_keys`); every table returned by :meth:`Results.table` has them.
RUN_KEYS = FALLBACK_RUN_KEYS
#: Run keys that older results lack, and the value they had.
DEFAULT_KEYS = KEY_DEFAULTS
#: Partition keys read with a fixed type (not inferred from the folder names): a scenario named
#: like a number ("2024") is a string, a batch window of 30 s the float 30.
PARTITION_TYPES = {"scenario": pa.string(), "batch_window": pa.float64()}


class NoResultsError(FileNotFoundError):
    """A path holds no results folder."""


@dataclass(frozen=True)
class Source:
    """One results folder: ``kind`` is ``"hive"`` (``<table>/k=v/…/part-0.parquet``) or
    ``"flat"`` (``<table>.parquet``, one run, as older versions wrote)."""

    kind: str
    path: Path

    def has(self, table: str) -> bool:
        if self.kind == "flat":
            return (self.path / f"{table}.parquet").is_file()
        return (self.path / table).is_dir()

    def dataset(self, table: str) -> ds.Dataset:
        """The table as a pyarrow dataset; the files are read with one unified schema (files
        written by older versions may lack newer columns: those read as null)."""
        if self.kind == "flat":
            return ds.dataset(self.path / f"{table}.parquet", format="parquet")
        d = ds.dataset(self.path / table, format="parquet", partitioning="hive")
        part = d.partitioning
        names = part.schema.names if part is not None else []
        fixed = {k: t for k, t in PARTITION_TYPES.items()
                 if k in names and part.schema.field(k).type != t}
        if fixed:
            ps = part.schema
            for k, t in fixed.items():
                ps = ps.set(names.index(k), pa.field(k, t))
            part = ds.partitioning(ps, flavor="hive")
            d = ds.dataset(self.path / table, format="parquet", partitioning=part)
        schemas = [f.physical_schema for f in d.get_fragments()]
        unified = pa.unify_schemas([_text_ids(s, schemas) for s in (d.schema, *schemas)])
        if unified.equals(d.schema):
            return d
        return ds.dataset(self.path / table, format="parquet", partitioning=part,
                          schema=unified)


def _text_ids(schema: pa.Schema, schemas: list[pa.Schema]) -> pa.Schema:
    """``schema`` with its ``request_id`` a string where ``schemas`` (a table's files) hold
    both types: runs of integer ids beside runs of string ids read as strings (the integers in
    decimal, as the traces wrote them)."""
    types = {s.field("request_id").type for s in schemas if "request_id" in s.names}
    if len(types) < 2 or "request_id" not in schema.names:
        return schema
    return schema.set(schema.get_field_index("request_id"), pa.field("request_id", pa.string()))


def _kind(path: Path) -> str | None:
    if (path / "summary").is_dir():
        return "hive"
    if (path / "summary.parquet").is_file():
        return "flat"
    return None


def find_sources(path: str | os.PathLike) -> list[Source]:
    """The results folders at or below ``path`` (a results folder is not searched further;
    folders named ``_…``, ``.…`` or ``key=value`` are skipped)."""
    path = Path(path)
    if not path.exists():
        raise NoResultsError(f"{path}: no such file or directory")
    if path.is_file() and path.suffix == ".parquet":
        path = path.parent
    kind = _kind(path)
    if kind is not None:
        return [Source(kind, path)]
    found = []
    for root, dirs, _files in os.walk(path):
        dirs[:] = sorted(d for d in dirs if not d.startswith(("_", ".")) and "=" not in d)
        here = Path(root)
        kind = _kind(here)
        if kind is not None:
            found.append(Source(kind, here))
            dirs[:] = []
    return found


def open_results(*paths: str | os.PathLike) -> Results:
    """Open one or more results folders (see the module docstring)."""
    sources: list[Source] = []
    for p in paths:
        sources += find_sources(p)
    if not sources:
        raise NoResultsError(
            f"no results in {', '.join(map(str, paths))}: expected a results folder "
            "(summary/scenario=…/allocator=…/…/part-0.parquet, as dispatch run and dispatch sweep "
            "write) "
            "or a folder holding such folders")
    return Results(sources)


@dataclass(frozen=True)
class Duplicate:
    """A run found in two results folders: read from ``kept``, not from ``dropped``."""

    run_id: str
    kept: Path
    dropped: Path


class Results:
    """Tables of one or more results folders, read on demand. A run (by its run id) found in
    several folders is read from the first only (:attr:`duplicates` lists the others)."""

    def __init__(self, sources: list[Source]) -> None:
        seen: set[Path] = set()
        self.sources = []  # a folder named twice (or inside another one named) is read once
        for src in sources:
            real = src.path.resolve()
            if real not in seen:
                seen.add(real)
                self.sources.append(src)
        self._summary = None
        self._owner: dict[str, int] | None = None
        self._duplicates: list[Duplicate] = []
        self._dropped: set[tuple[str, str]] = set()
        self._run_keys: list[str] | None = None
        #: run id -> the scenario name its files were written under, where it was a
        #: batch-window variant's (``<name>-batch30s``; read as ``<name>``)
        self._stored_names: dict[str, str] = {}

    @property
    def duplicates(self) -> list[Duplicate]:
        """Runs found in more than one folder: each is read from the first folder that holds
        it (in the order given) and not from the others, so it counts once."""
        self._owners()
        return list(self._duplicates)

    def _owners(self) -> dict[str, int]:
        """run id -> index of the first source whose summary holds it (read once). A run id
        in a later source is the same run (not read again) when its summary file carries the
        same scenario text and seed; another run that happens to share the id (a scenario of
        the same name, edited) is read as before."""
        if self._owner is None:
            owner: dict[str, int] = {}
            dups: list[Duplicate] = []
            idents: dict[int, dict[str, tuple]] = {}

            def ident(i: int, rid: str) -> tuple | None:
                if i not in idents:
                    idents[i] = _run_identities(self.sources[i])
                return idents[i].get(rid)

            for i, src in enumerate(self.sources):
                if not src.has("summary"):
                    continue
                ids = src.dataset("summary").to_table(columns=["run_id"]).column("run_id")
                for rid in ids.to_pylist():
                    if rid not in owner:
                        owner[rid] = i
                    elif owner[rid] != i:
                        first = ident(owner[rid], rid)
                        if first is not None and first == ident(i, rid):
                            dups.append(Duplicate(rid, self.sources[owner[rid]].path,
                                                  src.path))
            self._owner, self._duplicates = owner, dups
            self._dropped = {(d.run_id, str(d.dropped)) for d in dups}
        return self._owner

    def __repr__(self) -> str:
        return f"Results({[str(s.path) for s in self.sources]})"

    # ------------------------------------------------------------------ tables
    def table(self, name: str, *, columns: list[str] | None = None,
              run_id: str | list[str] | None = None):
        """One table of every source, as a pandas DataFrame with the run keys (``scenario``,
        ``allocator``, ``planner``, ``n_agents``, ``seed``) added from the summary where the
        files lack them. ``columns`` and ``run_id`` (one id or a list) are pushed down to the
        Parquet reader. A table that no source has gives an empty DataFrame."""
        import pandas as pd

        flt = None
        if run_id is not None:
            ids = [run_id] if isinstance(run_id, str) else list(run_id)
            flt = ds.field("run_id").isin(ids)
        frames = []
        for src in self.sources:
            if not src.has(name):
                continue
            d = src.dataset(name)
            renames = _legacy_renames(name, src, d.schema.names)
            old = {new: o for o, new in renames.items()}
            want = None
            if columns is not None:
                # a summary's scenario and window always: an older run's are read together
                extra = ("scenario", "batch_window") if name == "summary" else ()
                want = [old.get(c, c) for c in dict.fromkeys([*columns, "run_id", *extra])
                        if old.get(c, c) in d.schema.names]
            df = d.to_table(columns=want, filter=flt).to_pandas()
            if self._has_duplicates() and "run_id" in df.columns:
                here = str(src.path)
                mine = [(r, here) not in self._dropped for r in df["run_id"]]
                df = df.loc[mine]
                df = df.reset_index(drop=True)
            df = _normalise(df.rename(columns=renames) if renames else df)
            if name == "summary":
                df = self._windows(df, src)
                for k, v in DEFAULT_KEYS.items():
                    if k not in df.columns:
                        df[k] = v
            else:
                df = self._with_keys(df)
            if columns is not None:
                df = df[[c for c in dict.fromkeys([*columns, *self.run_keys, "run_id"])
                         if c in df.columns]]
            frames.append(df)
        if not frames:
            return pd.DataFrame(columns=list(columns or []))
        frames = [f for f in frames if len(f)] or frames[:1]
        out = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
        out.attrs[RUN_KEYS_ATTR] = list(self.run_keys)
        return out

    @property
    def summary(self):
        """The summary table (cached), one row per run."""
        if self._summary is None:
            self._summary = self.table("summary")
        return self._summary

    @property
    def run_keys(self) -> list[str]:
        """The columns that name a run, in order: the ``dispatch.run_keys`` lists of the
        summary files (their union, in the order the writers gave), the keys of older folders
        (:data:`paired.compare.FALLBACK_RUN_KEYS`) where a file does not list them."""
        if self._run_keys is None:
            found: dict[str, None] = {}
            for src in self.sources:
                if not src.has("summary"):
                    continue
                for frag in src.dataset("summary").get_fragments():
                    meta = frag.physical_schema.metadata or {}
                    raw = meta.get(b"dispatch.run_keys")
                    try:
                        keys = json.loads(raw) if raw is not None else FALLBACK_RUN_KEYS
                    except ValueError:
                        keys = FALLBACK_RUN_KEYS
                    found.update(dict.fromkeys(map(str, keys)))
            self._run_keys = list(found) or list(FALLBACK_RUN_KEYS)
        return self._run_keys

    def _windows(self, df, src: Source):
        """The summary rows of ``src`` with a batch window each: runs written before it was a
        run key (no ``batch_window`` column, or null in it) take theirs from the scenario text
        their file carries, and a batch-window variant (``<name>-batch30s``, one window of
        the text's ``[sweep] batch_window``) reads as scenario ``<name>``."""
        if "run_id" not in df.columns or "scenario" not in df.columns:
            return df
        w = df["batch_window"] if "batch_window" in df.columns else None
        if w is not None and w.notna().all():
            return df
        texts = _run_identities(src)
        names, windows = list(df["scenario"]), [math.nan] * len(df)
        for i, (rid, scen) in enumerate(zip(df["run_id"], df["scenario"])):
            if w is not None and w.iloc[i] == w.iloc[i]:  # not null: written as a run key
                windows[i] = float(w.iloc[i])
                continue
            text = (texts.get(rid) or (None,))[0]
            names[i], windows[i] = legacy_window(str(scen), text)
            if names[i] != scen:
                self._stored_names[rid] = str(scen)
        return df.assign(scenario=names, batch_window=windows)

    def errors(self):
        """The ``errors`` table of sweeps (failed runs), empty when none failed."""
        return self.table("errors")

    def run_ids(self) -> list[str]:
        return list(self.summary["run_id"])

    def run(self, run_id: str) -> dict:
        """Every table of one run, as DataFrames (reads only that run's rows)."""
        if run_id not in set(self.summary["run_id"]):
            raise KeyError(f"no run {run_id!r}; there are {len(self.summary)} runs, e.g. "
                           f"{', '.join(self.summary['run_id'].head(3))}")
        return {name: self.table(name, run_id=run_id) for name in TABLES}

    def metadata(self, run_id: str, table: str = "obstacles") -> dict[str, str]:
        """The Parquet schema metadata of one run's file of ``table`` (scenario text, seed,
        version; the world's size and cell for ``obstacles``)."""
        for src in self.sources:
            if not src.has(table):
                continue
            d = src.dataset(table)
            flt = _run_filter(self.summary, run_id, src, self._stored_names.get(run_id))
            for frag in d.get_fragments(filter=flt):
                meta = frag.physical_schema.metadata or {}
                if meta.get(b"dispatch.run_id", run_id.encode()).decode() == run_id:
                    return {k.decode(): v.decode() for k, v in meta.items()}
        raise KeyError(f"no {table} file for run {run_id!r}")

    def world(self, run_id: str) -> tuple[tuple[float, float, float], float]:
        """The world size (metres) and cell size of a run, from the obstacles metadata."""
        meta = self.metadata(run_id, "obstacles")
        return tuple(json.loads(meta["dispatch.world_size"])), float(meta["dispatch.cell"])

    # ------------------------------------------------------------------ helpers
    def _has_duplicates(self) -> bool:
        return len(self.sources) > 1 and bool(self.duplicates)

    def _with_keys(self, df):
        """``df`` with the run keys it lacks taken from the summary (and the scenario of a
        batch-window variant of an older folder read as the summary reads it)."""
        if "run_id" not in df.columns:
            return df
        summary = self.summary  # reads the stored names of older variants first
        # a key null in some rows (a run of an older layout beside newer ones: no
        # batch_window= level) and an older variant's scenario name: the summary's
        stale = [k for k in self.run_keys if k in df.columns and k in summary.columns
                 and df[k].isna().any()]
        if self._stored_names and "scenario" in df.columns:
            stale.append("scenario")
        df = df.drop(columns=list(dict.fromkeys(stale)))
        missing = [k for k in self.run_keys if k not in df.columns and k in summary.columns]
        if not missing:
            return df
        keys = summary[["run_id", *missing]].drop_duplicates("run_id")
        return df.merge(keys, on="run_id", how="left")


#: Columns renamed since older versions wrote them: table -> {old name: new name}.
RENAMED = {"tasks": {"arrived_at": "picked_up_at"},
           # a request the run's end cut off was called "cancelled" (no rider cancelled it)
           "summary": {"tasks_cancelled": "tasks_cut_off"}}
#: Old value -> new value, by column, of what older versions wrote: the state and the event of
#: a request the run's end cut off
RENAMED_VALUES = {"state": {"cancelled": "cut_off"}, "event": {"cancel": "cut_off"}}


def legacy_values(df):
    """``df`` with the values older versions wrote renamed (:data:`RENAMED_VALUES`)."""
    for col, names in RENAMED_VALUES.items():
        if col in df.columns and len(df) and df[col].isin(list(names)).any():
            df[col] = df[col].replace(names)
    return df


def _legacy_renames(name: str, src: Source, names: list[str]) -> dict[str, str]:
    """Old column name -> new name, for the columns of ``name`` an older version wrote."""
    found = {o: n for o, n in RENAMED.get(name, {}).items() if o in names and n not in names}
    if name == "decisions" and src.kind == "flat" and "n_idle" not in names:
        found["n_agents"] = "n_idle"  # the idle vehicles, not the fleet size (a run key)
    return found


def _normalise(df):
    """Partition columns come back as int32 / categorical: make them int64 / float / str;
    values older versions wrote are renamed (:func:`legacy_values`)."""
    legacy_values(df)
    for k in ("n_agents", "seed"):
        if k in df.columns and str(df[k].dtype) != "int64":
            df[k] = df[k].astype("int64")
    if "batch_window" in df.columns and str(df["batch_window"].dtype) != "float64":
        df["batch_window"] = df["batch_window"].astype("float64")
    for k in ("allocator", "planner", "scenario"):
        if k in df.columns and str(df[k].dtype) == "category":
            df[k] = df[k].astype(str)
    if "reposition" in df.columns:  # a run of an older layout beside newer ones: null
        v = DEFAULT_KEYS["reposition"]
        df["reposition"] = df["reposition"].astype(object).where(df["reposition"].notna(),
                                                                 v).astype(str)
    return df


def _run_identities(src: Source) -> dict[str, tuple]:
    """run id -> (scenario text, seed) of each summary file of ``src`` (schema metadata; runs
    of a flat folder: its one file)."""
    out = {}
    d = src.dataset("summary")
    for frag in d.get_fragments():
        meta = frag.physical_schema.metadata or {}
        rid = meta.get(b"dispatch.run_id")
        if rid is None:
            ids = frag.to_table(columns=["run_id"]).column("run_id").to_pylist()
            rid = ids[0].encode() if len(ids) == 1 else None
        if rid is not None:
            out[rid.decode()] = (meta.get(b"dispatch.scenario"), meta.get(b"dispatch.seed"))
    return out


def _run_filter(summary, run_id: str, src: Source,
                stored_name: str | None = None) -> ds.Expression | None:
    """The partition of ``run_id`` in ``src`` (``stored_name``: the scenario name its folder
    has, where the summary reads another one)."""
    if src.kind == "flat":
        return None
    row = summary.loc[summary["run_id"] == run_id]
    if row.empty:
        return None
    r = row.iloc[0]
    part = src.dataset("summary").partitioning
    expr = None
    for field in part.schema if part is not None else ():  # the run keys of its path
        if field.name not in r.index:
            continue
        v = stored_name if field.name == "scenario" and stored_name else r[field.name]
        cast = (int if pa.types.is_integer(field.type)
                else float if pa.types.is_floating(field.type) else str)
        term = ds.field(field.name) == cast(v)
        expr = term if expr is None else expr & term
    return expr


def legacy_window(scenario: str, text: bytes | str | None) -> tuple[str, float]:
    """The scenario name and batch window of a run written before the batch window was a run
    key, from the scenario text its files carry: a name that is one of the text's ``[sweep]
    batch_window`` variants as older versions named them (``<name>-immediate`` for 0 s,
    ``<name>-batch<w>s``) reads as ``<name>`` with that window; any other run has the text's
    ``[dispatch] batch_window`` (0 without it, or without a readable text)."""
    try:
        doc = tomllib.loads(text.decode() if isinstance(text, bytes) else text or "")
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        return scenario, KEY_DEFAULTS["batch_window"]
    swept = (doc.get("sweep") or {}).get("batch_window") or []
    for w in swept if isinstance(swept, list) else []:
        if isinstance(w, (int, float)) and not isinstance(w, bool):
            suffix = "-immediate" if w == 0 else f"-batch{float(w):g}s"
            if scenario.endswith(suffix) and len(scenario) > len(suffix):
                return scenario[: -len(suffix)], float(w)
    w = (doc.get("dispatch") or {}).get("batch_window", KEY_DEFAULTS["batch_window"])
    ok = isinstance(w, (int, float)) and not isinstance(w, bool)
    return scenario, float(w) if ok else KEY_DEFAULTS["batch_window"]


def read_parquet_metadata(path: str | os.PathLike) -> dict[str, str]:
    """The ``dispatch.*`` schema metadata of one Parquet file."""
    meta = pq.read_schema(path).metadata or {}
    return {k.decode(): v.decode() for k, v in meta.items() if k.startswith(b"dispatch.")}
