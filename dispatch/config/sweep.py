"""``[sweep]``: the lists of run-key values a scenario expands to, as data (the run keys:
:mod:`dispatch.config.runkeys`)."""

from __future__ import annotations

from dataclasses import dataclass

from dispatch.config.runkeys import RUN_KEYS


@dataclass(frozen=True)
class SweepConfig:
    allocator: tuple[str, ...] = ()
    planner: tuple[str, ...] = ()
    agents: tuple[int, ...] = ()
    seed: tuple[int, ...] = ()
    #: dispatch.batch_window values: a run key (a partition and a part of the run id)
    batch_window: tuple[float, ...] = ()
    reposition: tuple[str, ...] = ()

    @property
    def declared(self) -> bool:
        return any(getattr(self, k.sweep) for k in RUN_KEYS if k.sweep)
