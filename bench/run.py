"""Running the bench: the runs of the chosen instances and allocators on the sweep runner (a
process pool or Ray, resumable through its completion markers in ``DIR/runs/``), then one row
per run (:mod:`bench.metrics`) and the files of :mod:`bench.report`.

An allocator that cannot run an instance (it serves other spaces, lacks a capability the
instance needs, rejects the instance's parameters) gets rows with status ``unsupported: …``; a
run that raises gets ``failed: …`` (its traceback in ``DIR/runs/errors/``); a run past the
wall-clock limit of one run (``--time-limit``, :data:`TIME_LIMIT_MIN` minutes) is stopped and
gets ``timeout: …``, and is not tried again by a later call with a limit no longer than the
time it ran; none of them stops the bench.
"""

from __future__ import annotations

import json
import logging
import math
import os
import platform
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.metrics import COLUMNS, run_metrics
from bench.stats import fill_gaps
from bench.suite import REFERENCE, VERSION, Instance, instances, seeds_of
from dispatch.errors import DispatchError
from dispatch.scenario.overrides import key_values

log = logging.getLogger(__name__)

RUNS = "runs"
#: Minutes of wall time one run may take (``--time-limit``): the full suite fits in about two
#: hours on 2 cores only if no allocator spends hours on one instance (``auction`` on the
#: 10,000-vehicle grid day ran 30 simulated minutes in more than 10 wall minutes; one of its
#: decisions there takes minutes)
TIME_LIMIT_MIN = 20.0


class BenchError(ValueError):
    """A wrong input to the bench (an unknown allocator, a bad --param): one line."""


@dataclass
class Plan:
    """What a bench call runs: per instance the allocators, their specs and the rows of the
    allocators that cannot run there."""

    specs: list = field(default_factory=list)  # (instance, allocator, spec)
    unsupported: list[dict] = field(default_factory=list)


def allocators_for(instance: Instance, named: list[str]) -> list[str]:
    """The reference first, then the named allocators, then the other baselines (each once)."""
    out: list[str] = []
    for a in (REFERENCE, *named, *instance.baselines()):
        if a not in out:
            out.append(a)
    return out


def _plugin_name(name: str) -> str:
    """``name`` as ``dispatch new allocator`` takes it (lower-case letters, digits, _), else
    a placeholder."""
    import re

    return name if re.fullmatch(r"[a-z][a-z0-9_]*", name) else "NAME"


def check_allocators(named: list[str], params: dict[str, Any] | None = None) -> None:
    """BenchError naming the first allocator that is not installed, or a named variant
    (``magnnet:paper``) its plugin does not declare, unless ``params`` (``--param``) make it
    (they set its ``variant``)."""
    from dispatch.api.registry import available, base_name, undeclared_variant

    have = available("allocator")
    for name in named:
        if base_name(name) not in have:
            raise BenchError(f"unknown allocator {name!r}; installed: {', '.join(sorted(have))}. "
                             f"Your own: `dispatch new allocator {_plugin_name(name)}` writes a "
                             "plugin package to fill in; pip install -e it, then bench it")
        why = undeclared_variant(name)
        if why is not None and "variant" not in (params or {}):
            raise BenchError(f"allocator {name!r}: {why}; name one of them, or make this one "
                             "with --param KEY=VALUE")


def parse_params(items: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` strings as ``dispatch check --param`` reads them
    (:func:`dispatch.scenario.overrides.key_values`: VALUE as TOML, else a string); BenchError for
    an
    item without a key or an ``=``."""
    try:
        return key_values(items)
    except DispatchError as e:
        raise BenchError(str(e)) from None


def plan(chosen: list[Instance], named: list[str], *, quick: bool, seeds: int | None,
         params: dict[str, Any]) -> Plan:
    """The specs of every (instance, allocator, seed), each allocator checked against the
    instance first."""
    from dispatch.api.registry import base_name, declaration
    from dispatch.errors import DispatchError
    from dispatch.run.plugins import check_runs, make_plugin
    from dispatch.scenario.load import parse_scenario

    out = Plan()
    parsed: dict[str, Any] = {}  # text -> scenario: the allocators without params share one
    for inst in chosen:
        world = inst.world()
        for alloc in allocators_for(inst, named):
            own = params if (params and alloc in named) else None
            text = inst.text(quick, alloc, own)
            if text not in parsed:
                parsed[text] = parse_scenario(tomllib.loads(text), inst.path, text, limits=None)
            sc = parsed[text]
            why = None
            caps = declaration("allocator", base_name(alloc))
            if not caps.serves(sc.world.space):
                why = (f"{alloc} serves {' and '.join(caps.spaces)} spaces, not "
                       f"{sc.world.space}")
            else:
                try:
                    check_runs(sc, sorted({sc.dispatch.planner}), (), [alloc])
                except DispatchError as e:  # a capability the instance needs
                    why = str(e).replace(f"{inst.path}: ", "")
            sizes = None
            if why is None:
                try:
                    sizes = make_plugin("allocator", alloc, sc.dispatch.params_for(alloc)
                                        ).team_sizes
                except DispatchError as e:  # its parameters (--param): the caller's mistake
                    raise BenchError(f"{alloc}: {e}") from None
            for seed in seeds_of(inst, quick, seeds):
                if why is None:
                    spec, = sc.runs(allocator=alloc, seed=seed)
                    why = team_size_refusal(alloc, sizes, spec)
                if why is not None:
                    out.unsupported.append(_row(inst, world, alloc, seed,
                                                f"unsupported: {why}"))
                else:
                    out.specs.append((inst, alloc, spec))
    return out


def team_size_refusal(alloc: str, sizes: tuple[int, ...] | None, spec) -> str | None:
    """Why an allocator that decides only some team sizes (``Allocator.team_sizes``) cannot
    run ``spec``, or None where it can."""
    if sizes is None:
        return None
    n, static = spec.agents, spec.scenario.tasks.source == "static"
    if static and spec.n_static_tasks == n and n in sizes:
        return None
    what = (f"N = {n} agents, M = {spec.n_static_tasks} tasks" if static
            else f"{spec.scenario.tasks.source} tasks")
    return (f"{alloc} decides static problems of N = M in {{{', '.join(map(str, sizes))}}} "
            f"only, not {what}")


def _row(inst: Instance, world: str, alloc: str, seed: int, status: str) -> dict:
    row = dict.fromkeys(COLUMNS, math.nan)
    row.update(world=world, instance=inst.name, allocator=alloc, seed=seed, status=status)
    return row


def machine() -> dict[str, Any]:
    """The machine and software the board was measured on."""
    from importlib.metadata import PackageNotFoundError, version

    versions = {}
    for pkg in ("dispatch-sim", "numpy", "scipy", "simpy", "numba", "networkx", "pyarrow",
                "torch", "ray"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            continue
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = math.nan
    return {"cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "processor": platform.processor() or
            platform.machine(), "load_1min_at_start": load, "versions": versions}


def _read(out: Path, spec, table: str):
    from dispatch.run.resume import partition_dir
    from dispatch.run.runner import read_table

    path = out / table / partition_dir(spec) / "part-0.parquet"
    return read_table(path, spec.partition, table) if path.exists() else None


def _timed_out(out: Path, spec, limit: float) -> str | None:
    """The error message of an earlier run of ``spec`` stopped at a wall-clock limit after at
    least ``limit`` seconds (trying it again would stop again); None if there is none."""
    from dispatch.run.resume import ERRORS, partition_dir

    path = out / ERRORS / partition_dir(spec) / "part-0.parquet"
    if not path.exists():
        return None
    import pyarrow.parquet as pq

    try:
        row = pq.read_table(path, columns=["error_type", "message", "seconds"]).to_pylist()[0]
    except (OSError, IndexError, ValueError):
        return None
    if row["error_type"] == "PastTimeLimit" and row["seconds"] >= limit:
        return row["message"]
    return None


def _wall(out: Path, spec) -> float:
    from dispatch.run.resume import marker_path

    try:
        return float(json.loads(marker_path(out, spec).read_text(encoding="utf-8"))["seconds"])
    except (OSError, ValueError, KeyError, TypeError):
        return math.nan


@dataclass
class BenchResult:
    rows: list[dict]
    counts: dict[str, int]
    seconds: float
    machine: dict


def run_bench(named: list[str], out: Path, *, suite: str = "all", quick: bool = False,
              seeds: int | None = None, params: dict[str, Any] | None = None,
              workers: int | None = None, ray: bool = False,
              only: list[str] | None = None,
              on_done: Callable[[Any], None] | None = None,
              time_limit: float = TIME_LIMIT_MIN * 60.0) -> BenchResult:
    """Run the bench into ``out`` (runs in ``out/runs``; finished ones are reused) and return
    its rows (``bench.csv``'s, in suite order). ``only``: instance names to keep (tests);
    ``time_limit``: wall seconds one run may take (see the module docstring)."""
    from dispatch.run.runner import sweep

    check_allocators(named, params)
    chosen = instances(suite, quick)
    if only is not None:
        unknown = sorted(set(only) - {i.name for i in chosen})
        if unknown:
            raise BenchError(f"no instance {', '.join(unknown)} in the {suite} suite")
        chosen = [i for i in chosen if i.name in only]
    started = time.perf_counter()
    info = machine()
    p = plan(chosen, list(named), quick=quick, seeds=seeds, params=params or {})
    runs = (Path(out) / RUNS).resolve()
    rows = list(p.unsupported)
    counts = {"done": 0, "skipped": 0, "failed": 0, "timeout": 0,
              "unsupported": len(p.unsupported)}
    todo = []
    for inst, alloc, spec in p.specs:
        past = _timed_out(runs, spec, time_limit)
        if past is None:
            todo.append((inst, alloc, spec))
            continue
        counts["timeout"] += 1
        rows.append(_row(inst, inst.world(), alloc, spec.seed, f"timeout: {past}"))
    outcomes = sweep([s for _, _, s in todo], runs, workers=workers, ray=ray,
                     on_done=on_done, time_limit=time_limit) if todo else []
    for (inst, alloc, spec), o in zip(todo, outcomes):
        world = inst.world()
        if o.status == "failed" and o.error.startswith("PastTimeLimit: "):
            counts["timeout"] += 1
            rows.append(_row(inst, world, alloc, spec.seed,
                             "timeout: " + o.error.removeprefix("PastTimeLimit: ")))
            continue
        counts[o.status] += 1
        if o.status == "failed":
            rows.append(_row(inst, world, alloc, spec.seed, f"failed: {o.error}"))
            continue
        row = _row(inst, world, alloc, spec.seed, "ok")
        summary = _read(runs, spec, "summary").to_pylist()[0]
        row.update(run_metrics(summary, _read(runs, spec, "tasks"),
                               _read(runs, spec, "vehicles"), road=world == "road"))
        row["wall_s"] = _wall(runs, spec)
        rows.append(row)
    order = {i.name: k for k, i in enumerate(chosen)}
    alloc_order = {(i.name, a): k for i in chosen
                   for k, a in enumerate(allocators_for(i, list(named)))}
    rows.sort(key=lambda r: (order[r["instance"]], alloc_order[(r["instance"], r["allocator"])],
                             r["seed"]))
    fill_gaps(rows)
    info.update(suite=VERSION, which=suite, quick=quick, allocators=list(named),
                params=params or {}, workers=workers or os.cpu_count(), ray=ray,
                time_limit_s=time_limit, only=[i.name for i in chosen] if only else None)
    return BenchResult(rows, counts, time.perf_counter() - started, info)
