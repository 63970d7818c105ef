"""One soak run: a :class:`soak.generate.Case` written to a folder, loaded, run under a
wall-clock limit, and its Parquet tables checked (:mod:`soak.invariants`).

The outcome is one of ``ok``, ``violations`` (the tables break a promise), ``refused`` (the
loader or the run's start refused the scenario with a one-line error: a combination refused by
design), ``crash`` (any other exception: a bug) or ``hang`` (past the wall-clock limit)."""

from __future__ import annotations

import shutil
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from soak import invariants
from soak.generate import Case


@dataclass
class Outcome:
    """What one run of a case gave."""

    status: str  # ok | violations | refused | crash | hang
    violations: list[tuple[str, str]] = field(default_factory=list)
    message: str = ""
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        return self.status in ("violations", "crash", "hang")

    def signature(self) -> set[str]:
        """What failed: the invariants broken, or the crash's exception type, or ``hang``."""
        if self.status == "violations":
            return {name for name, _ in self.violations}
        if self.status == "crash":
            return {"crash:" + self.message.split(":", 1)[0]}
        return {self.status} if self.failed else set()


def _simulate(path: Path, out: Path, limit: float):
    """Check the scenario as ``dispatch run`` does (the file, the resource bounds, the
    plugins and the space), then run it into ``out``."""
    from dispatch.run.parser import parser
    from dispatch.run.prepare import checked_specs
    from dispatch.run.runner import run_one
    from dispatch.run.time_limit import time_limit_of

    with time_limit_of(limit) as tick:
        _, [spec] = checked_specs(parser().parse_args(["run", str(path)]))
        run_one(spec, out, progress=tick)


def run_case(case: Case, directory: Path, *, limit: float = 60.0,
             twice: bool = False) -> Outcome:
    """Write ``case`` into ``directory`` (``scenario.toml`` and its files), run it into
    ``directory/out`` and check its tables; ``twice``: run it again into ``out2`` and check
    that the tables are the same (wall-clock columns aside)."""
    from dispatch.errors import DispatchError
    from dispatch.run.time_limit import PastTimeLimit

    if directory.exists():
        shutil.rmtree(directory)
    path = case.write(directory)
    start = time.perf_counter()
    out = directory / "out"
    try:
        _simulate(path, out, limit)
    except PastTimeLimit as e:
        return Outcome("hang", message=str(e), seconds=time.perf_counter() - start)
    except DispatchError as e:
        return Outcome("refused", message=str(e).replace(str(directory) + "/", ""),
                       seconds=time.perf_counter() - start)
    except Exception as e:  # noqa: BLE001 - a crash is the soak's finding: kept with where
        tb = traceback.extract_tb(e.__traceback__)[-1]
        return Outcome("crash", message=f"{type(e).__name__}: {e} ({tb.filename}:{tb.lineno})",
                       seconds=time.perf_counter() - start)
    tables = invariants.read_tables(out)
    found = invariants.check(case.doc, tables)
    if twice:
        try:
            _simulate(path, directory / "out2", limit)
            diff = invariants.same_tables(tables, invariants.read_tables(directory / "out2"))
        except PastTimeLimit:
            diff = ["the second run hung"]
        found += [("same_seed", f"same seed, other values in: {d}") for d in diff]
        shutil.rmtree(directory / "out2", ignore_errors=True)
    return Outcome("violations" if found else "ok", found,
                   seconds=time.perf_counter() - start)
