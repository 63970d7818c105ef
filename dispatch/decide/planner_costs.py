"""The planner's side of a decision: whether it uses lazy exact costs, the cost matrix (or
lower bounds) checked for shape and type, exact costs of chosen pairs, the tasks no vehicle
of the fleet can reach, and the costs past a request's deadline (``inf``: :func:`deadlines`;
a request no vehicle reaches in time: :func:`reject_late`)."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from dispatch.errors import DispatchError, PluginError
from dispatch.plan.tasks import TaskBook, TaskState

if TYPE_CHECKING:
    from dispatch.api.contracts import Allocator, Planner
    from dispatch.config.dispatching import DispatchConfig
    from dispatch.decide.tally import Blame
    from dispatch.plan.vehicles import Fleet

log = logging.getLogger(__name__)


def lazy_costs(cfg: DispatchConfig, planner: Planner, allocator: Allocator, plans: bool) -> bool:
    """Whether decisions use lazy exact costs: ``[dispatch] lazy_costs`` asked for, a planner
    that computes lower bounds, an allocator that minimizes the total cost, and no plans
    (insertions are costed exactly); a warning says why where it was asked for and is off."""
    lazy = cfg.lazy_costs
    if lazy and not (planner.lower_bounds and allocator.minimizes_total_cost):
        log.warning("lazy_costs is on but planner %r computes no lower bounds or allocator "
                    "%r does not minimize the total cost: exact costs are used",
                    planner.name, allocator.name)
        lazy = False
    if lazy and plans:
        log.warning("lazy_costs is off: shared rides, max_delay and the added_time "
                    "objective cost insertions exactly")
        lazy = False
    return lazy


class PlannerCosts:
    """The planner's side of a decision, checked: its costs (or lower bounds), the exact costs
    of chosen pairs (lazy costs), and the costs of the busy vehicles (unreachable tasks)."""

    def __init__(self, planner: Planner, lazy: bool, blame: Blame) -> None:
        self.planner, self.lazy, self.blame = planner, lazy, blame

    def _bad_costs(self, cost, want: tuple[int, int]) -> PluginError:
        got = (f"{type(cost).__name__} {cost.shape} {cost.dtype}"
               if isinstance(cost, np.ndarray) else type(cost).__name__)
        return PluginError(f"{self.blame.where('planner', self.planner)}: costs() must return "
                           f"a float array of shape {want} without nan, got {got}")

    def __call__(self, agents, tasks):
        """The planner's ``(cost, exact)`` of a decision: its exact costs (``exact`` None), or
        with lazy costs its lower bounds and which of them are exact; a PluginError naming the
        planner and the decision for an exception or an answer of the wrong type or shape."""
        exact = None  # lazy costs: which entries of ``cost`` are exact (the others are bounds)
        try:
            if self.lazy:
                cost, exact = self.planner.bounds(agents, tasks)
                exact = np.array(exact, dtype=bool) if isinstance(exact, np.ndarray) else exact
            else:
                cost = self.planner.costs(agents, tasks)
        except DispatchError:
            raise
        except Exception as e:  # a plugin's bug: one line naming it and where
            raise self.blame.failed("planner", self.planner, e) from e
        want = (len(agents), len(tasks))
        if not isinstance(cost, np.ndarray) or cost.shape != want or cost.dtype.kind != "f":
            raise self._bad_costs(cost, want)
        if self.lazy and not (isinstance(exact, np.ndarray) and exact.shape == want
                              and exact.dtype == bool):
            raise PluginError(f"{self.blame.where('planner', self.planner)}: bounds() must "
                              f"return a bool array of shape {want} as its second item")
        return cost, exact

    def exact(self, agents, tasks):
        """``compute(rows, cols)``: the planner's exact costs of those pairs (lazy costs)."""
        def compute(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            try:
                values = self.planner.exact(agents, tasks, rows, cols)
            except DispatchError:
                raise
            except Exception as e:  # a plugin's bug: one line naming it and where
                raise self.blame.failed("planner", self.planner, e) from e
            values = np.asarray(values, dtype=float).reshape(-1)
            if values.shape != rows.shape or np.isnan(values).any():
                raise PluginError(f"{self.blame.where('planner', self.planner)}: exact() must "
                                  f"return {rows.size} costs without nan, got {values.shape}")
            return values
        return compute

    def reachable(self, cost: np.ndarray) -> np.ndarray | None:
        """Which columns of ``cost`` have a finite entry, or None when all of them have (the
        usual case, found by one finite sum); a PluginError for a ``nan``."""
        # a finite sum has no inf and no nan (either would make the sum one): every pair
        # servable (a sum that overflows takes the element-wise checks below)
        if math.isfinite(np.add.reduce(cost, axis=None)):
            return None
        finite = np.isfinite(cost)
        if np.isnan(cost).any():
            raise self._bad_costs(cost, cost.shape)
        return finite.any(axis=0)

    def busy(self, agents, tasks) -> np.ndarray:
        """The cost matrix of ``agents`` (busy vehicles) to ``tasks``: the planner's costs, or
        with lazy costs its bounds (an ``inf`` bound is an ``inf`` cost)."""
        return self.planner.bounds(agents, tasks)[0] if self.lazy else \
            self.planner.costs(agents, tasks)


def close_unreachable(book: TaskBook, fleet: Fleet, costs: PlannerCosts, tasks, now: float
                      ) -> None:
    """Close ``tasks`` (none of the decision's vehicles can reach them) that no vehicle of the
    fleet can reach either; vehicles never leave their connected component of free space, so
    a task unreachable from every vehicle's cell stays so."""
    busy = fleet.views(np.flatnonzero([v.busy for v in fleet.vehicles]), now)
    if busy:
        views = tuple(t.view() for t in tasks)  # lazy: an inf bound is an inf cost
        c = costs.busy(busy, views)
        tasks = [t for t, ok in zip(tasks, np.isfinite(c).any(axis=0)) if not ok]
    for t in tasks:
        book.close(t, TaskState.UNREACHABLE)


def reject_late(book: TaskBook, open_tasks: list, cost: np.ndarray, servable: np.ndarray,
                reject: bool = True) -> np.ndarray:
    """``servable`` less the tasks no vehicle can reach in time (no finite cost); of those,
    a task offered for the first time is closed ``rejected`` at once when ``reject`` (see
    :mod:`dispatch.decide.dispatcher`), one offered before waits for its deadline. Without
    ``reject`` (``out_of_reach = "wait"``) every one of them stays open until its deadline:
    a vehicle that frees up near it in time may take it at a later decision."""
    late = servable & ~np.isfinite(cost).any(axis=0)
    if reject:
        for t, bad in zip(open_tasks, late):
            if bad and not t.offered:
                book.close(t, TaskState.REJECTED)
    return servable & ~late


def deadlines(cost: np.ndarray, deadline: np.ndarray, now: float) -> np.ndarray:
    """``cost`` with ``inf`` where a vehicle would reach the pickup after the request's
    deadline (``now + cost <= deadline``, to 1e-9 s)."""
    return np.where(now + cost <= deadline + 1e-9, cost, np.inf)
