"""The contract of fleet-sizing strategies (``dispatch.sizers`` plugins, ``[fleet] sizing``):
what a strategy sees (:class:`SizingView`) and what it answers (:class:`Sizer`).

Every ``interval`` seconds of a run the kernel (:class:`dispatch.fleet.shifts.Shifts`) shows the
strategy the fleet: how many vehicles are on duty, how many of them carry a plan now, the
share of their on-duty seconds spent on a plan since the last look, the share of the requests
released since then that went unserved, how many more wait at their depots within their
shift. The strategy answers how many vehicles it wants on duty; the
kernel brings vehicles of the idle pool in at their depots (lowest id first) or sends idle
ones home to their depots (highest id first), within the bounds the strategy keeps.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class SizingView:
    """The fleet at ``time``: ``on_duty`` vehicles in service (``busy`` of them with a plan),
    ``pool`` more at their depots within their shift (they may join), ``utilization``: the
    share of the on-duty vehicle-seconds since the last look spent on a plan (nan before
    any), and ``unserved``: the requests rejected or expired since the last look, as a share
    of those released meanwhile (nan: none released)."""

    time: float
    on_duty: int
    busy: int
    pool: int
    utilization: float
    rng: np.random.Generator
    unserved: float = float("nan")


class Sizer(ABC):
    """A fleet-sizing strategy. ``passive``: it never changes the fleet (the kernel never
    calls it; ``fixed``). ``interval``: seconds between two looks. ``initial(view)``: how
    many vehicles are on duty when the run starts (of those whose shift has begun);
    ``size(view)``: how many it wants on duty now."""

    name: ClassVar[str] = ""
    passive: ClassVar[bool] = False
    interval: float = 900.0

    def initial(self, view: SizingView) -> int:
        """Vehicles on duty at the start (default: every one whose shift has begun)."""
        return view.on_duty + view.pool

    @abstractmethod
    def size(self, view: SizingView) -> int:
        """The number of vehicles wanted on duty now."""
