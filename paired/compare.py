"""How runs are compared: the allocator order of every table and figure, the instance a run is
paired on, the paired gap to a reference allocator and the names of batch-window variants.

One definition, used by the CLI's tables (:mod:`dispatch.tables`, on summary dicts) and by
:mod:`analysis.metrics` (on DataFrames). Standard library only, and outside both packages: it
imports neither pandas nor ``dispatch`` nor ``analysis``, so the kernel's tables and the
analysis share it without importing each other.

The **gap to Hungarian** of a run is ``(cost - reference cost) / reference cost`` where the
reference is the ``reference`` allocator's run on the same *instance*: the same scenario (a
batch-window variant is a scenario of its own), planner, repositioner, fleet size N and seed
(:data:`INSTANCE`). It is undefined (NaN) without such a run or where the reference costs 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

#: Allocators in the paper's order (Hungarian, the optimum, first); others follow by name.
PREFERRED_ORDER = ("hungarian", "local_hungarian", "magnnet", "auction", "greedy", "fcfs",
                   "random")

#: What makes two runs the same problem instance (everything of a run but its allocator).
INSTANCE = ("scenario", "planner", "reposition", "batch_window", "n_agents", "seed")


def allocator_order(names: Iterable[str]) -> list[str]:
    """Allocators in the paper's order (Hungarian first), then the rest alphabetically; a
    named variant (``magnnet:paper``) right after its allocator."""
    rank = {n: i for i, n in enumerate(PREFERRED_ORDER)}

    def key(name: str) -> tuple:
        base, _, variant = name.partition(":")
        return (rank.get(base, len(rank)), base, variant)

    return sorted({str(n) for n in names}, key=key)


def instance_key(run: Mapping) -> tuple:
    """The instance of one run (a summary row): :data:`INSTANCE`'s values; a missing
    repositioner reads ``stay`` and a missing batch window 0 (older folders)."""
    defaults = {"reposition": "stay", "batch_window": 0.0}
    out = []
    for k in INSTANCE:
        v = run.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            v = defaults.get(k)
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
                cost: str = "total_cost") -> list[float]:
    """Per run (in the order given): its :func:`gap` to the ``reference`` allocator's run on
    the same instance (:func:`instance_key`); the first reference run of an instance counts."""
    runs = list(runs)
    ref: dict[tuple, float] = {}
    for r in runs:
        if r.get("allocator") == reference:
            ref.setdefault(instance_key(r), r.get(cost))
    return [gap(r.get(cost), ref.get(instance_key(r))) for r in runs]


def variant_name(scenario: str) -> str:
    """``imm`` / ``30s`` for a batch-window variant (``<name>-immediate`` /
    ``<name>-batch30s``, see ``Scenario.variants``), else the scenario's name."""
    head, _, tail = str(scenario).rpartition("-")
    if head and tail == "immediate":
        return "imm"
    if head and tail.startswith("batch") and tail.endswith("s"):
        return tail.removeprefix("batch")
    return str(scenario)


def variant_rank(scenario: str) -> tuple:
    """Immediate first, then batch windows by length, then other scenarios by name."""
    v = variant_name(scenario)
    if v == "imm":
        return (0, 0.0, "")
    if v != scenario:
        try:
            return (0, float(v.removesuffix("s")), "")
        except ValueError:
            pass
    return (1, 0.0, str(scenario))
