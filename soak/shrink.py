"""Shrinking a failing case to a minimal one: a delta-debugger over the scenario's tables and
keys, the rows of its files (the demand, the fleet, the breakdowns) and the fleet's size.

A step is kept when the smaller case still fails with one of the failures the original had
(an invariant it broke, its crash's exception type, or a hang); every step runs the case once,
so a shrink costs a few dozen to a few hundred short runs. The result is written as a
regression case (``tests/soak_cases/<name>/``: the scenario and its files), which
``tests/soak/test_soak_cases.py`` runs."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from soak.generate import Case
from soak.runner import Outcome, run_case

log = logging.getLogger(__name__)
#: sections a scenario needs; the others may go whole
KEPT = {"name", "seed", "duration", "world", "tasks", "fleet", "dispatch"}
#: keys whose removal changes what the scenario is, not how much of it there is
PINNED = {("tasks", "source"), ("tasks", "trace"), ("dispatch", "planner"),
          ("world", "network"), ("world", "size"), ("world", "cell"), ("world", "blocks")}


def unused_files(case: Case) -> Case:
    """``case`` without the files its scenario no longer names."""
    text = case.text()
    case.files = {f: rows for f, rows in case.files.items() if f'"{f}"' in text}
    case.blobs = {f: data for f, data in case.blobs.items() if f'"{f}"' in text}
    return case


def _still_fails(want: set[str], directory: Path, limit: float) -> Callable[[Case], bool]:
    def test(case: Case) -> bool:
        got = run_case(case, directory, limit=limit)
        return bool(got.signature() & want)
    return test


def _drop_rows(case: Case, test, name: str, keep_one: bool = True) -> Case:
    """ddmin over the rows of file ``name``: remove chunks, halving their size."""
    header, rows = case.files[name]
    n = max(1, len(rows) // 2)
    while n >= 1 and len(rows) > (1 if keep_one else 0):
        i, changed = 0, False
        while i < len(rows):
            trial = rows[:i] + rows[i + n:]
            if trial or not keep_one:
                c = case.copy()
                c.files[name] = (header, trial)
                if test(c):
                    rows, case, changed = trial, c, True
                    continue
            i += n
        if not changed:
            n //= 2
    return case


def _drop_column(case: Case, test, name: str) -> Case:
    header = case.files[name][0]
    for col in list(header[3:] if name == "trips.csv" else header[2:]):
        if col not in header:
            continue
        j = header.index(col)
        c = case.copy()
        h, r = c.files[name]
        c.files[name] = (h[:j] + h[j + 1:], [row[:j] + row[j + 1:] for row in r])
        if test(c):
            case = c
            header = case.files[name][0]
    return case


def _drop_keys(case: Case, test) -> Case:
    for section in [k for k in list(case.doc) if k not in KEPT]:
        c = case.copy()
        c.doc.pop(section)
        if test(c):
            case = c

    def walk(path: tuple[str, ...]) -> None:
        nonlocal case
        table = case.doc
        for p in path:
            table = table[p]
        for key in list(table):
            if (path[:1] + (key,)) in PINNED or (not path and key in ("name", "seed")):
                continue
            if isinstance(table[key], dict):
                walk(path + (key,))
            if not path and key in KEPT:
                continue
            c = case.copy()
            t = c.doc
            for p in path:
                t = t[p]
            if key not in t:
                continue
            t.pop(key)
            if test(c):
                case = c
                table = case.doc
                for p in path:
                    table = table[p]
    walk(())
    return case


def _fewer_agents(case: Case, test) -> Case:
    fleet = case.doc.get("fleet", {})
    while isinstance(fleet.get("agents"), int) and fleet["agents"] > 1:
        c = case.copy()
        c.doc["fleet"]["agents"] -= 1
        if not test(c):
            break
        case, fleet = c, c.doc["fleet"]
    return case


def shrink(case: Case, failed: Outcome, directory: Path, *, limit: float = 60.0,
           rounds: int = 2) -> Case:
    """The smallest case found that still fails as ``failed`` did (``directory``: where the
    trials run)."""
    test = _still_fails(failed.signature(), directory, limit)
    for _ in range(rounds):
        before = (case.text(), repr(case.files))
        for name in ("trips.csv", "failures.csv", "fleet.csv", "stations.csv"):
            if name in case.files:
                case = _drop_rows(case, test, name)
        case = _fewer_agents(case, test)
        case = _drop_keys(case, test)
        for name in ("trips.csv", "fleet.csv"):
            if name in case.files:
                case = _drop_column(case, test, name)
        if (case.text(), repr(case.files)) == before:
            break
    return case


def write_regression(case: Case, failed: Outcome, cases_dir: Path, name: str) -> Path:
    """Write ``case`` as ``cases_dir/name/scenario.toml`` (and its files), with a first
    comment line that says what it broke."""
    folder = cases_dir / name
    path = unused_files(case.copy()).write(folder)
    what = ", ".join(sorted(failed.signature()))
    path.write_text(f"# soak regression: {what}\n" + path.read_text(encoding="utf-8"),
                    encoding="utf-8")
    return path
