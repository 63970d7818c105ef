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
    The move is a reposition stop of the vehicle's plan (:data:`dispatch.stops.REPOSITION`),
    driven by the operator like any stop (:meth:`dispatch.operator.Operator.reposition`): the
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

import logging
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from dispatch.errors import PluginError
from dispatch.legs import as_point

if TYPE_CHECKING:
    import simpy

    from dispatch.events import Event, EventBus
    from dispatch.operator import Operator
    from dispatch.roads import RoadNetwork
    from dispatch.vehicles import Fleet, Vehicle

log = logging.getLogger(__name__)


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
    space: RoadNetwork
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
    #: The kinds of space (:attr:`dispatch.space.Space.kind`) it serves.
    spaces: ClassVar[tuple[str, ...]] = ("road",)
    #: True for a repositioner that never moves a vehicle: the kernel does not call it.
    passive: ClassVar[bool] = False

    @abstractmethod
    def reposition(self, view: RepositionView) -> Mapping[int, int]:
        """The moves to make now: ``{vehicle id: target node}`` (empty: none)."""


# ----------------------------------------------------------------------------- the kernel side


class Repositioning:
    """Calls a non-passive repositioner every ``interval`` seconds and hands its moves to the
    operator (:meth:`dispatch.operator.Operator.reposition`), which drives them as reposition
    stops. ``moves`` counts the moves started; their metres are the operator's
    (:attr:`dispatch.operator.Operator.reposition_distance`)."""

    def __init__(self, env: simpy.Environment, bus: EventBus, fleet: Fleet, operator: Operator,
                 space: RoadNetwork, repositioner: Repositioner, interval: float, horizon: float,
                 rng: np.random.Generator, run_id: str = "") -> None:
        self.env, self.bus, self.fleet, self.operator = env, bus, fleet, operator
        self.space, self.repositioner, self.rng = space, repositioner, rng
        self.interval, self.horizon = interval, horizon
        self.run_id = run_id  # named in error messages
        self.moves = 0
        self._recent: deque[tuple[float, int]] = deque()
        bus.subscribe(self._released, ["release"])
        self.process = env.process(self._loop())

    def _released(self, e: Event) -> None:
        self._recent.append((e.t, int(e.loc)))

    def _loop(self):
        while True:
            yield self.env.timeout(self.interval)
            self.step()

    # ------------------------------------------------------------------ one call
    def view(self) -> RepositionView:
        """The read-only view of now (see :class:`RepositionView`)."""
        now, recent = self.env.now, self._recent
        while recent and recent[0][0] <= now - self.horizon:
            recent.popleft()
        idle = self.fleet.idle()
        locs = [v.location(now) for v in idle]
        points = [as_point(p) for p in locs]
        nodes = [p.node for p in points]
        rem = [max(p.remaining, 0.0) for p in points]
        going = [self.operator.repositioning(v) for v in idle]
        targets = [-1 if node is None else node for node in going]
        rnodes = _readonly([n for _, n in recent], np.int64)
        return RepositionView(
            time=float(now), horizon=self.horizon,
            vehicle_ids=_readonly([v.id for v in idle], np.int64),
            nodes=_readonly(nodes, np.int64), remaining=_readonly(rem, np.float64),
            targets=_readonly(targets, np.int64),
            vehicle_pos=_readonly(self.space.positions(locs), np.float64),
            request_times=_readonly([t for t, _ in recent], np.float64), request_nodes=rnodes,
            request_pos=_readonly(self.space.positions(rnodes), np.float64),
            space=self.space, rng=self.rng)

    def _fail(self, why: str) -> PluginError:
        name = self.repositioner.name or type(self.repositioner).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return PluginError(f"repositioner {name!r}{run}, t = {self.env.now:.6g} s: {why}")

    def step(self) -> None:
        """Ask the repositioner for moves now, check them, and start them (in vehicle id
        order; a move to where the vehicle already is or is already heading is ignored)."""
        view = self.view()
        try:
            moves = self.repositioner.reposition(view)
        except PluginError:
            raise
        except Exception as e:  # noqa: BLE001 - a plugin may raise anything
            raise self._fail(f"reposition() raised {type(e).__name__}: "
                             f"{' '.join(str(e).split())[:300]}") from e
        if not isinstance(moves, Mapping):
            raise self._fail(f"reposition() must return a mapping of vehicle id to node, got "
                             f"{type(moves).__name__}")
        idle = {int(i): k for k, i in enumerate(view.vehicle_ids)}
        checked = []
        for vid, node in moves.items():
            if isinstance(vid, bool) or not isinstance(vid, (int, np.integer)) \
                    or int(vid) not in idle:
                raise self._fail(f"move for vehicle {vid!r}, which is not an idle vehicle of "
                                 f"the view")
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                    or not 0 <= node < self.space.n:
                raise self._fail(f"vehicle {vid} sent to {node!r}, not a node index of the "
                                 f"network (0 .. {self.space.n - 1})")
            checked.append((int(vid), int(node)))
        for vid, node in sorted(checked):
            k = idle[vid]
            here = int(view.nodes[k]) == node and view.remaining[k] <= 0.0
            if int(view.targets[k]) == node or (here and view.targets[k] < 0):
                continue
            self.start(self.fleet.by_id[vid], node)

    def start(self, v: Vehicle, node: int) -> None:
        """Send the idle vehicle ``v`` to ``node`` now (a move it is on ends where it is)."""
        self.moves += 1
        self.operator.reposition(v, node)


def summary_of(r: Repositioning | None) -> dict:
    """The summary columns of repositioning: moves started and their metres."""
    return {"repositions": 0 if r is None else r.moves,
            "reposition_distance": 0.0 if r is None else r.operator.reposition_distance}


__all__ = ["RepositionView", "Repositioner", "Repositioning", "summary_of"]
