"""Repositioning: what idle vehicles do between trips (the ``dispatch.repositioners`` plugins).

Repositioners
    Subclass :class:`Repositioner` and implement :meth:`Repositioner.reposition`. Every
    ``[reposition] interval`` simulated seconds the kernel hands it a read-only
    :class:`RepositionView` (the time, the idle vehicles and where they are, the requests
    released in the last ``[reposition] horizon`` seconds, the space for travel times, a seeded
    generator) and it returns the moves it wants: ``{vehicle id: target node}``. It must name
    only vehicles of the view, only nodes of the network, must not mutate the view, and draws
    randomness only from ``view.rng``; the kernel stops the run with a
    :class:`~dispatch.errors.PluginError` naming it otherwise. Constructor keyword arguments
    come from the scenario's ``[reposition.<name>]`` table; reject unknown or bad ones with
    ``TypeError`` / ``ValueError`` (one line: the scenario check reports it).
    A repositioner that never moves anyone sets ``passive = True``: the kernel then never calls
    it (``stay``, the default, is one: idle vehicles wait where they are).

What the kernel does with a move
    The move is a reposition stop of the vehicle's plan (:data:`dispatch.plan.stops.REPOSITION`),
    driven by the operator like any stop (:meth:`dispatch.plan.operator.Operator.reposition`): the
    vehicle drives the fastest path to the target node (empty: its metres count in
    ``empty_distance`` and in the summary's ``reposition_distance``). It stays *idle* all the
    way: the dispatcher may give it a trip at any moment, which cuts the move, and it then
    drives to the pickup from where it is (part-way along an edge included); a later move may
    re-target it. Its arrival wakes the dispatcher (a request it could not reach in time before
    may be within reach). Events: a ``reposition`` (vehicle; at the target node), then a
    ``depart`` with task -1 (at where it starts); on arrival an ``idle`` at the target. A
    breakdown stops it like any drive.

Repositioning moves vehicles on road networks only: a scenario that pairs a non-passive
repositioner with a voxel world fails validation (:attr:`Repositioner.spaces`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

if TYPE_CHECKING:
    from dispatch.api.space import Space

def _readonly(a, dtype) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class RepositionView:
    """What a repositioner sees at one call (read-only; arrays are not writable).

    Idle vehicles (row ``i`` of each array; vehicles driving to a repositioning target are
    idle too): ``vehicle_ids[i]``; ``nodes[i]`` the node it stands on or, part-way along an
    edge, the node it reaches next; ``remaining[i]`` the seconds left to that node (0 on a
    node); ``targets[i]`` the node it is repositioning to (``-1``: it stands still);
    ``vehicle_pos[i]`` its ``(x, y, z)`` in metres.

    Requests released in the last ``horizon`` seconds (``t - horizon < released <= t``), in
    release order: ``request_times``, ``request_nodes`` (pickup nodes), ``request_pos``.

    ``space`` is the road network (node coordinates ``space.xy``; travel times through
    :meth:`travel_times`); ``rng`` is the only source of randomness a repositioner may use.
    """

    time: float
    horizon: float
    vehicle_ids: np.ndarray
    nodes: np.ndarray
    remaining: np.ndarray
    targets: np.ndarray
    vehicle_pos: np.ndarray
    request_times: np.ndarray
    request_nodes: np.ndarray
    request_pos: np.ndarray
    space: Space  # the road network (dispatch.space.roads.RoadNetwork)
    rng: np.random.Generator

    @property
    def n_vehicles(self) -> int:
        return int(self.vehicle_ids.size)

    @property
    def moving(self) -> np.ndarray:
        """Boolean mask of the idle vehicles already driving to a repositioning target."""
        return self.targets >= 0

    def travel_times(self, rows: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """``(len(rows), len(nodes))`` fastest driving seconds from the idle vehicles
        ``rows`` (indices into the arrays above) to each node of ``nodes``: the seconds left to
        their next node plus the network's shortest time from there (one Dijkstra per distinct
        node of the smaller side)."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1)
        nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
        if rows.size == 0 or nodes.size == 0:
            return np.zeros((rows.size, nodes.size))
        src, src_inv = np.unique(self.nodes[rows], return_inverse=True)
        dst, dst_inv = np.unique(nodes, return_inverse=True)
        if dst.size <= src.size:
            t = self.space.distances_to(dst)[:, src].T  # (src, dst)
        else:
            t = self.space.distances_from(src)[:, dst]
        return t[np.ix_(src_inv, dst_inv)] + self.remaining[rows][:, None]


class Repositioner(ABC):
    """Base class of repositioner plugins (see the module docstring for the contract)."""

    name: ClassVar[str] = ""
    #: The kinds of space (:attr:`dispatch.api.space.Space.kind`) it serves.
    spaces: ClassVar[tuple[str, ...]] = ("road",)
    #: True for a repositioner that never moves a vehicle: the kernel does not call it.
    passive: ClassVar[bool] = False

    @abstractmethod
    def reposition(self, view: RepositionView) -> Mapping[int, int]:
        """The moves to make now: ``{vehicle id: target node}`` (empty: none)."""


__all__ = ["RepositionView", "Repositioner"]
