"""How runs are compared: the allocator order of every table and figure, the instance a run is
paired on, the paired gap to a reference allocator and the label of a batch window.

One definition, used by the CLI's tables (:mod:`dispatch.output.printed`, on summary dicts) and by
:mod:`analysis.metrics` (on DataFrames). Standard library only, and outside both packages: it
imports neither pandas nor ``dispatch`` nor ``analysis``, so the kernel's tables and the
analysis share it without importing each other.

The **gap to Hungarian** of a run is ``(cost - reference cost) / reference cost`` where the
reference is the ``reference`` allocator's run on the same *instance*: the same value of every
run key but the allocator (scenario, planner, repositioner, batch window, fleet size N and seed).
The run keys are the writer's (``dispatch.run_keys`` in every file of a run, which
:class:`analysis.io.Results` reads; the CLI passes its own): :data:`FALLBACK_RUN_KEYS` serve
runs that do not say. It is undefined (NaN) without such a run or where the reference costs 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

#: Allocators in the paper's order (Hungarian, the optimum, first); others follow by name.
PREFERRED_ORDER = ("hungarian", "local_hungarian", "magnnet", "auction", "greedy", "fcfs",
                   "random")

#: The run keys of results that do not list theirs (files written before ``dispatch.run_keys``;
#: :mod:`analysis.io` reads a batch window for them from their scenario text), in order.
FALLBACK_RUN_KEYS = ("scenario", "allocator", "planner", "reposition", "batch_window",
                     "n_agents", "seed")
#: The value of a run key that older results lack: what their runs did.
KEY_DEFAULTS = {"reposition": "stay", "batch_window": 0.0}
#: ``DataFrame.attrs`` key of the run keys a frame's runs were written with (set by
#: :attr:`analysis.io.Results.summary` from the files' ``dispatch.run_keys``).
RUN_KEYS_ATTR = "run_keys"


def instance_keys(run_keys: Sequence[str] | None = None) -> tuple[str, ...]:
    """What makes two runs the same problem instance: every run key (``run_keys``, default
    :data:`FALLBACK_RUN_KEYS`) but the allocator."""
    return tuple(k for k in (run_keys or FALLBACK_RUN_KEYS) if k != "allocator")


#: The instance keys of results that do not list their run keys.
INSTANCE = instance_keys()


def allocator_order(names: Iterable[str]) -> list[str]:
    """Allocators in the paper's order (Hungarian first), then the rest alphabetically; a
    named variant (``magnnet:paper``) right after its allocator."""
    rank = {n: i for i, n in enumerate(PREFERRED_ORDER)}

    def key(name: str) -> tuple:
        base, _, variant = name.partition(":")
        return (rank.get(base, len(rank)), base, variant)

    return sorted({str(n) for n in names}, key=key)


def instance_key(run: Mapping, run_keys: Sequence[str] | None = None) -> tuple:
    """The instance of one run (a summary row): the values of :func:`instance_keys`; a key
    the run lacks (or holds as null) reads :data:`KEY_DEFAULTS`' value (older folders)."""
    out = []
    for k in instance_keys(run_keys):
        v = run.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            v = KEY_DEFAULTS.get(k)
        out.append(float(v) if k == "batch_window" else v)
    return tuple(out)


def gap(cost: float, reference: float) -> float:
    """``(cost - reference) / reference``; NaN where the reference is missing, NaN or <= 0."""
    if reference is None or cost is None:
        return math.nan
    cost, reference = float(cost), float(reference)
    if not reference > 0 or math.isnan(cost):
        return math.nan
    return (cost - reference) / reference


def paired_gaps(runs: Iterable[Mapping], reference: str = "hungarian",
                cost: str = "total_cost", run_keys: Sequence[str] | None = None) -> list[float]:
    """Per run (in the order given): its :func:`gap` to the ``reference`` allocator's run on
    the same instance (:func:`instance_key` over ``run_keys``); the first reference run of an
    instance counts."""
    runs = list(runs)
    ref: dict[tuple, float] = {}
    for r in runs:
        if r.get("allocator") == reference:
            ref.setdefault(instance_key(r, run_keys), r.get(cost))
    return [gap(r.get(cost), ref.get(instance_key(r, run_keys))) for r in runs]


def window_label(seconds: float) -> str:
    """A batch window in a table or a legend: ``imm`` (0 s: every event decided at once), else
    its seconds (``30s``)."""
    w = float(seconds)
    return "imm" if w == 0 else f"{w:g}s"
