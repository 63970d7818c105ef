"""``[dispatch]``: how a decision is taken (the allocator, the planner, the batch window, what a
pair costs, when a booked request enters), as data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: ``[dispatch] out_of_reach``: what becomes of a request no vehicle reaches in time at its
#: first offer (:func:`dispatch.decide.planner_costs.reject_late`)
OUT_OF_REACH = ("reject", "wait")


@dataclass(frozen=True)
class DispatchConfig:
    allocator: str = "hungarian"
    planner: str = "astar"
    batch_window: float = 0.0  # seconds the dispatcher waits after a wake-up to batch events
    max_rounds: int = 1000  # decision-round limit for decentralized allocators
    #: decisions also consider vehicles still driving to a pickup (roads; see
    #: dispatch.decide.dispatcher)
    reassign: bool = False
    #: decide on the planner's lower bounds and compute exact costs only for the pairs an
    #: optimal answer needs (see dispatch.decide.lazy); used when the planner and allocator support
    #: it
    lazy_costs: bool = False
    #: what a pair's cost is: "pickup_time" (seconds until the pickup) or "added_time" (how
    #: much longer the vehicle's whole plan gets; see dispatch.plan.stops)
    objective: str = "pickup_time"
    #: the ``[dispatch.allocator_params]`` table: keyword arguments of the allocator's
    #: constructor (every allocator of a sweep), and ``[dispatch.allocator_params.<name>]``
    #: tables for one allocator or a named variant (``"magnnet:paper"``)
    allocator_params: tuple[tuple[str, Any], ...] = ()
    #: the ``[dispatch.planner_params]`` table: keyword arguments of the planner's constructor
    planner_params: tuple[tuple[str, Any], ...] = ()
    #: ``[dispatch.allocator_params.<name>]`` tables: parameters of one allocator (``magnnet``)
    #: or of a named variant (``"magnnet:paper"``), over the flat ones (see :meth:`params_for`)
    allocator_tables: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    #: when a booked request enters dispatch: "at_booking" (when it is booked) or "lead"
    #: (prebook_lead seconds before its departure, not before its booking); dispatch.decide.prebook
    prebook: str = "at_booking"
    #: seconds before its departure a booked request enters dispatch with prebook = "lead"
    #: (unset: the [tasks] prebook_lead)
    prebook_lead: float | None = None
    #: what becomes of a request that, at its first offer, no vehicle of the decision can
    #: reach before its deadline: "reject" (closed ``rejected`` at once) or "wait" (it stays
    #: open: a vehicle that frees up or drives near it may still take it before its deadline,
    #: else it expires); see dispatch.decide.planner_costs.reject_late
    out_of_reach: str = "reject"

    def params_for(self, allocator: str) -> tuple[tuple[str, Any], ...]:
        """The constructor arguments of ``allocator`` (a name, or ``name:variant``): the flat
        ``[dispatch.allocator_params]`` keys, then its own table's, then its variant's."""
        tables = dict(self.allocator_tables)
        base = allocator.partition(":")[0]
        merged = dict(self.allocator_params)
        merged.update(tables.get(base, ()))
        if base != allocator:
            merged.update(tables.get(allocator, ()))
        return tuple(sorted(merged.items()))
