"""The soak's runs: ``runs`` cases of one seed, each run and checked (:mod:`soak.runner`), the
outcomes appended to ``OUT/results.jsonl`` one line a run as each ends, so a soak killed at any
moment leaves a readable file and, started again with the same arguments, skips the runs it
holds and ends with the same results.

Each run's scenario (``OUT/runs/<seed>_<index>/scenario.toml`` and its files) stays beside its
result; a run's tables are kept only where it failed (a crash, a hang or a violation)."""

from __future__ import annotations

import json
import logging
import os
import shutil
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from soak.generate import Case, draw
from soak.invariants import INVARIANTS
from soak.known import known
from soak.runner import Outcome, run_case

log = logging.getLogger(__name__)
STATUSES = ("ok", "refused", "violations", "crash", "hang")


@dataclass
class Tally:
    """What a soak found: runs per status and per world, runs breaking each invariant (and of
    those, runs explained by an expected failure, :mod:`soak.known`), refusal messages, and
    each failing run's id and first message."""

    status: Counter = field(default_factory=Counter)
    worlds: Counter = field(default_factory=Counter)
    broken: Counter = field(default_factory=Counter)
    known: Counter = field(default_factory=Counter)
    refusals: Counter = field(default_factory=Counter)
    failures: list = field(default_factory=list)

    def add(self, row: dict) -> None:
        self.status[row["status"]] += 1
        self.worlds[row["world"]] += 1
        if row["status"] == "refused":
            self.refusals[row["message"].split(": ", 2)[-1][:100]] += 1
        for name in sorted(set(row.get("broken", []))):
            self.broken[name] += 1
        for name in sorted(set(row.get("known", []))):
            self.known[name] += 1
        if row["status"] in ("crash", "hang") or set(row.get("broken", ())) - set(
                row.get("known", ())):
            self.failures.append((row["run"], row.get("first") or row["message"]))

    @property
    def runs(self) -> int:
        return sum(self.status.values())

    @property
    def unexplained(self) -> int:
        """Runs that failed for a reason no expected failure names."""
        return len(self.failures)

    def rows(self) -> list[tuple[str, int, int]]:
        """``(invariant, runs breaking it, of those explained by an expected failure)``, every
        invariant and then the crashes and hangs."""
        out = [(n, self.broken[n], self.known[n]) for n in INVARIANTS]
        return out + [("crash", self.status["crash"], 0), ("hang", self.status["hang"], 0)]


def row_of(run: str, case: Case, got: Outcome) -> dict:
    """The ``results.jsonl`` line of one run."""
    broken = sorted({n for n, _ in got.violations})
    return {"run": run, "world": case.world, "status": got.status, "message": got.message,
            "seconds": round(got.seconds, 3), "broken": broken,
            "known": [n for n in broken if known(case, n)],
            "first": got.violations[0][1] if got.violations else ""}


def _read_results(results: Path) -> dict[str, dict]:
    """The rows of ``results`` by run. A line cut by a kill is left out (that run runs
    again) and the file is rewritten without it (a temporary name, then a rename), so the
    lines appended next start on a line of their own."""
    done: dict[str, dict] = {}
    if not results.exists():
        return done
    text = results.read_text(encoding="utf-8")
    kept = []
    for line in text.splitlines():
        try:
            row = json.loads(line)
            done[row["run"]] = row
            kept.append(line)
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
    whole = "".join(line + "\n" for line in kept)
    if whole != text:
        tmp = results.with_name(f".{results.name}.tmp-{os.getpid()}")
        tmp.write_text(whole, encoding="utf-8")
        os.replace(tmp, results)
    return done


def soak(runs: int, seed: int, out: Path, *, world: str | None = None, limit: float = 60.0,
         twice_every: int = 10, on_run: Callable[[dict], None] | None = None) -> Tally:
    """Run cases ``0 .. runs - 1`` of ``seed`` into ``out``; every ``twice_every``-th run
    twice (the same seed must give the same tables). Runs already in ``out/results.jsonl``
    are read, not run again. ``on_run(row)`` after each run."""
    out.mkdir(parents=True, exist_ok=True)
    results = out / "results.jsonl"
    done = _read_results(results)
    tally = Tally()
    with results.open("a", encoding="utf-8") as fh:
        for index in range(runs):
            run = f"{seed}_{index}"
            row = done.get(run)
            if row is None:
                case = draw(seed, index, world)
                folder = out / "runs" / run
                got = run_case(case, folder, limit=limit,
                               twice=twice_every > 0 and index % twice_every == 0)
                row = row_of(run, case, got)
                if not got.failed:
                    shutil.rmtree(folder / "out", ignore_errors=True)
                fh.write(json.dumps(row) + "\n")
                fh.flush()
            tally.add(row)
            if on_run is not None:
                on_run(row)
    return tally
