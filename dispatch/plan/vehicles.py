"""Vehicles and the fleet: what a vehicle is and has (its plan, its position, its counters),
and the fleet's arrays a decision reads instead of looping over the vehicles.

A vehicle owns its plan (:class:`dispatch.plan.vehicle_plan.Plan`: its stops, their times, the
arrays a decision reads); the operator (:class:`dispatch.plan.operator.Operator`) drives it and
a decision inserts into it. What a
vehicle drove, and with how many on board, is counted in one place (:meth:`Vehicle.drove`).
On roads a vehicle part-way through a leg is interpolated from its route when someone asks
(:meth:`Vehicle.location`); :func:`stop_leg` stops it there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from dispatch.api.problem import AgentView, AgentViews
from dispatch.api.space import Space
from dispatch.locations import Location
from dispatch.plan.en_route import LegTable
from dispatch.plan.idle_places import MOVING, NOT_IDLE, IdlePlaces
from dispatch.plan.kinds import TABLE as KINDS
from dispatch.plan.tasks import Task
from dispatch.plan.vehicle_plan import Plan

if TYPE_CHECKING:
    from dispatch.api.legs import Leg



@dataclass(eq=False)
class Vehicle:
    """A UAV, a UGV or a car. ``loc`` is where it is (on roads: the node it last reached;
    while it drives a leg, :meth:`location` interpolates)."""

    id: int
    kind: str
    speed: float
    start: Location
    busy: bool = False
    #: seats (``[fleet] capacity``); a request of more passengers than this never rides in it
    capacity: int = 1
    #: the plan: stops still to make, in order (:class:`dispatch.plan.vehicle_plan.Plan`); the
    #: operator drives it, decisions insert into it, breakdowns and re-assignments empty it
    plan: Plan = field(init=False, repr=False)
    distance: float = 0.0  # metres travelled
    empty_distance: float = 0.0  # ... without a passenger (to pickups, repositioning)
    occupied_distance: float = 0.0  # ... with one or more on board
    passenger_distance: float = 0.0  # passenger-metres: metres times passengers on board
    serving: Task | None = field(default=None, repr=False)  # in service for that task
    busy_seconds: float = 0.0
    busy_since: float = 0.0
    completed: int = 0
    #: seconds its driver spent on breaks (``[fleet.breaks]``, :mod:`dispatch.plan.breaks`)
    break_seconds: float = 0.0
    #: when its driver's break under way began (None: not on a break); on a break it is
    #: neither idle nor busy, unless its plan holds requests
    break_since: float | None = None
    # ---- roads: when the leg being driven (:attr:`leg`) started
    leg_start: float = 0.0
    # ---- faults (see dispatch.fleet.faults)
    failed: bool = False
    failures: int = 0
    down_seconds: float = 0.0
    down_since: float = 0.0
    proc: Any = field(default=None, repr=False)  # the SimPy process serving its trip
    #: ``[fleet.energy]``: its battery (:class:`dispatch.fleet.battery.Battery`); None without
    #: energy
    battery: Any = field(default=None, repr=False)
    _view: AgentView | None = field(default=None, repr=False)
    #: not in the fleet now (before its shift, on its way home, after it: dispatch.fleet.shifts);
    #: neither idle nor busy, as a failed vehicle
    off_duty: bool = False
    # its shift (dispatch.fleet.shifts.Duty); None: none
    duty: Any = field(default=None, repr=False)
    # ``loc`` and ``leg`` live here; their setters tell the fleet (its arrays stay current)
    _loc: Location = field(default=None, init=False, repr=False)
    _leg: Leg | None = field(default=None, init=False, repr=False)
    _fleet: Fleet | None = field(default=None, init=False, repr=False)
    _slot: int = field(default=-1, init=False, repr=False)
    # ``load``, ``heading`` and ``plan_version`` too: a decision reads them as the fleet's
    # arrays (dispatch.decide.plan_costs.PlanTable), without a Python step per vehicle
    _load: int = field(default=0, init=False, repr=False)
    _heading: Any = field(default=None, init=False, repr=False)
    _plan_version: int = field(default=0, init=False, repr=False)
    _free_at: float = field(default=-math.inf, init=False, repr=False)
    _room: bool = field(default=True, init=False, repr=False)

    def __post_init__(self) -> None:
        self._loc = self.start
        self.plan = Plan(self)

    @property
    def loc(self) -> Location:
        """Where it is (on roads: the node it last reached, or a road point where it stopped
        part-way along an edge)."""
        return self._loc

    @loc.setter
    def loc(self, value: Location) -> None:
        self._loc = value
        if self._fleet is not None:
            self._fleet._moved(self._slot, value)

    @property
    def leg(self) -> Leg | None:
        """Roads: the leg it is driving (None when it stands)."""
        return self._leg

    @leg.setter
    def leg(self, value: Leg | None) -> None:
        self._leg = value
        fleet = self._fleet
        if fleet is not None:
            i = self._slot
            fleet.driving[i] = value is not None
            fleet.driving_or_off_node[i] = value is not None or fleet._off_node[i]
            fleet.leg_version[i] += 1
            if fleet.places is not None:
                fleet.place(i)

    @property
    def load(self) -> int:
        """Passengers on board."""
        return self._load

    @load.setter
    def load(self, value: int) -> None:
        self._load = value
        if self._fleet is not None:
            self._fleet.load[self._slot] = value

    @property
    def heading(self) -> Any:
        """The stop its current drive goes to (None: standing, serving or idle)."""
        return self._heading

    @heading.setter
    def heading(self, value: Any) -> None:
        self._heading = value
        if self._fleet is not None:
            self._fleet.heading_none[self._slot] = value is None

    @property
    def plan_version(self) -> int:
        """Bumped at every change of the plan or of the drive along it."""
        return self._plan_version

    @plan_version.setter
    def plan_version(self, value: int) -> None:
        self._plan_version = value
        if self._fleet is not None:
            self._fleet.plan_version[self._slot] = value

    @property
    def free_at(self) -> float:
        """In service at a stop until then (the stop's task completes at that time)."""
        return self._free_at

    @free_at.setter
    def free_at(self, value: float) -> None:
        self._free_at = value
        if self._fleet is not None:
            self._fleet.free_at[self._slot] = value

    @property
    def room(self) -> bool:
        """A seat is free somewhere in its plan (set by :meth:`Plan.changed`)."""
        return self._room

    @room.setter
    def room(self, value: bool) -> None:
        self._room = value
        if self._fleet is not None:
            self._fleet.room[self._slot] = value

    @property
    def cell(self):
        """The voxel name of :attr:`loc`."""
        return self.loc

    @cell.setter
    def cell(self, value) -> None:
        self.loc = value

    @property
    def flies(self) -> bool:
        return self.kind == "uav"

    def drove(self, metres: float, seconds: float = 0.0) -> None:
        """Count ``metres`` driven (in ``seconds``) with the passengers now on board: the one
        place where a vehicle's distances grow, and where its battery is drawn."""
        if self.battery is not None:
            self.battery.drive(metres, seconds)
        self.distance += metres
        if self.load:
            self.occupied_distance += metres
            self.passenger_distance += metres * self.load
        else:
            self.empty_distance += metres

    def tasks(self) -> list[Task]:
        """The tasks of its plan (the one in service first), each once, in plan order."""
        out = [] if self.serving is None else [self.serving]
        for task in self.plan.tasks():
            if task not in out:
                out.append(task)
        return out

    def location(self, now: float) -> Location:
        """Where it is at ``now``: on a leg, the road point reached by then."""
        if self.leg is not None:
            return self.leg.point_at(now - self.leg_start)
        return self.loc

    def view(self, now: float | None = None) -> AgentView:
        """What a decision at ``now`` sees of it (kept while it stands still: a fleet of idle
        vehicles is viewed at every decision)."""
        if self.leg is not None and now is not None:
            return AgentView(self.id, self.kind, self.location(now), self.speed)  # type: ignore[arg-type]
        v = self._view
        if v is None or v.loc is not self.loc:
            v = self._view = AgentView(self.id, self.kind, self.loc, self.speed)  # type: ignore[arg-type]
        return v


class Fleet:
    """The run's vehicles by id, and the index of the idle ones.

    Besides the vehicles it keeps array state, aligned with :attr:`vehicles` (id order) and
    updated as vehicles change (their ``loc`` / ``leg`` setters and :meth:`refresh` call
    in), so that a decision over the idle vehicles costs numpy operations, not a
    Python loop over the fleet: ``ids``; ``idle_mask``; on roads ``node`` (the node a vehicle
    stands on, or the end of the edge it stopped on part-way), ``remaining`` (seconds left on
    that edge, 0 on a node), ``off_node`` (its location is not a plain node: a road point, or a
    voxel cell) and ``driving`` (it has a leg: its location depends on the time). Where a
    location stands is the space's answer (:meth:`dispatch.api.space.Space.stands`)."""

    def __init__(self, vehicles: list[Vehicle], space: Space) -> None:
        self.vehicles = sorted(vehicles, key=lambda v: v.id)
        self.by_id = {v.id: v for v in self.vehicles}
        n = len(self.vehicles)
        self.ids = np.fromiter((v.id for v in self.vehicles), np.int64, n)
        #: the ids are the positions 0 .. n-1 (the usual fleet): a position is its id
        self._ids_are_slots = bool((self.ids == np.arange(n)).all())
        self.idle_mask = np.ones(n, dtype=bool)
        self.busy_mask = np.zeros(n, dtype=bool)
        #: a free seat somewhere in its plan (kept by Plan.changed)
        self.room = np.ones(n, dtype=bool)
        #: seats; the end of the service it is in (-inf: none), as the vehicles have them
        self.capacity = np.fromiter((v.capacity for v in self.vehicles), np.int64, n)
        self.free_at = np.full(n, -np.inf)
        self.node = np.full(n, -1, dtype=np.int64)
        self.remaining = np.zeros(n)
        self.off_node = np.zeros(n, dtype=bool)
        self.driving = np.zeros(n, dtype=bool)
        #: driving or off a node: where it is needs a look at the vehicle (kept with the two)
        self.driving_or_off_node = np.zeros(n, dtype=bool)
        self._off_node = [False] * n  # off_node, as Python bools (read by the leg setter)
        self._stands = space.stands
        #: bumped at every leg set (the leg setter): which rows of ``legs`` are stale
        self.leg_version = np.zeros(n, dtype=np.int64)
        self.legs = LegTable(n, self.driving, self.leg_version)  # (dispatch.plan.en_route)
        #: each vehicle's ``load``, ``heading is None`` and ``plan_version``, kept by their
        #: setters (dispatch.decide.plan_costs.PlanTable reads them)
        self.load = np.fromiter((v.load for v in self.vehicles), np.int64, n)
        self.heading_none = np.fromiter((v.heading is None for v in self.vehicles), bool, n)
        self.plan_version = np.fromiter((v.plan_version for v in self.vehicles), np.int64, n)
        #: the node arrays hold (the space has nodes)
        self.road = n > 0 and all(space.stands(v.loc) is not None for v in self.vehicles)
        #: the idle vehicles by place (dispatch.plan.idle_places), kept once a decision asks
        #: for them (:meth:`index_places`); None until then
        self.places: IdlePlaces | None = None
        self._space = space
        for i, v in enumerate(self.vehicles):
            v._fleet, v._slot = self, i
            self.driving[i] = v.leg is not None
            self._moved(i, v.loc)

    def __len__(self) -> int:
        return len(self.vehicles)

    def _moved(self, i: int, loc: Location) -> None:
        """Vehicle ``i``'s ``loc`` changed (called by its setter)."""
        at = self._stands(loc)
        if at is None:  # no node (a voxel cell): the arrays are unused
            off = True
        else:
            self.node[i], self.remaining[i], off = at
        self.off_node[i] = off
        self._off_node[i] = off
        self.driving_or_off_node[i] = off or self.vehicles[i]._leg is not None
        if self.places is not None:
            self.place(i)

    def index_places(self) -> IdlePlaces | None:
        """Keep the idle vehicles by place from now on (:attr:`places`; a decision searches
        them nearest first: :mod:`dispatch.decide.nearest`), where the space has nodes and
        promises a top speed between them; None where it does not."""
        if self.places is None and self.road and self._space.top_speed:
            xy = np.asarray(self._space.node_positions, dtype=np.float64)[:, :2]
            self.places = IdlePlaces(xy, len(self.vehicles))
            for i in range(len(self.vehicles)):
                self.place(i)
        return self.places

    def place(self, i: int) -> None:
        """Put vehicle ``i`` where it belongs in :attr:`places`: out unless idle; idle and
        driving, with the moving ones; else in the cell of the node it stands on."""
        places = self.places
        if not self.idle_mask[i]:
            places.put(i, NOT_IDLE)
        elif self.driving[i]:
            places.put(i, MOVING)
        else:
            places.put(i, places.cell_of_node[self.node[i]])

    def idle_index(self) -> np.ndarray:
        """Positions (in :attr:`vehicles`, id order) of the idle vehicles."""
        return self.idle_mask.nonzero()[0]

    def idle(self) -> list[Vehicle]:
        """Idle vehicles in id order."""
        vs = self.vehicles
        return [vs[i] for i in np.flatnonzero(self.idle_mask).tolist()]

    def views(self, index: np.ndarray, now: float, ascending: bool | None = None
              ) -> AgentViews:
        """The vehicles at positions ``index`` as a decision at ``now`` sees them: a lazy
        sequence of :class:`AgentView` (built on access) that also carries their ids and, on
        roads, their nodes and remaining seconds as arrays (see :class:`AgentViews`).
        ``ascending``: whether ``index`` is strictly increasing, if the caller knows."""
        vs = self.vehicles
        idx = np.asarray(index, dtype=np.int64)

        def make(k: int) -> AgentView:
            return vs[int(idx[k])].view(now)

        if ascending is None:  # ids ascend with the positions (vehicles are in id order)
            ascending = bool(idx.size < 2 or (idx[1:] > idx[:-1]).all())
        # (take: a gather about twice as fast as fancy indexing, the same elements; a decision
        # of an immediate city day gathers thousands of idle vehicles, so each one counts)
        ids = idx.copy() if self._ids_are_slots else self.ids.take(idx)
        if not self.road:
            return AgentViews(ids, make, ascending=ascending)
        node = self.node.take(idx)
        looked = self.driving_or_off_node.take(idx)
        # (count_nonzero: the same answer as any(), without its Python-level wrapper)
        if not np.count_nonzero(looked):  # every one stands on a node: ``remaining`` is 0 for all
            return AgentViews(ids, make, node, np.zeros(idx.size), _NO_POINTS, ascending)
        rem = self.remaining.take(idx)
        # driving (a leg: where is it now?) or stopped part-way along an edge
        points = self.legs.where(vs, idx, looked.nonzero()[0], node, rem, now,
                                 stands=self._stands)
        return AgentViews(ids, make, node, rem, points, ascending)

    def refresh(self, v: Vehicle) -> None:
        """Set ``v``'s state from its plan and its failure: failed, off duty (dispatch.fleet.shifts)
        or on a charging visit (a charge stop in its plan), it is neither idle nor busy (no
        decision considers it);
        serving a request or with one in its plan, busy; else idle (standing, or on a
        repositioning move, which a decision may cut)."""
        busy = idle = False
        if not v.failed and not v.off_duty:
            busy = v.serving is not None
            idle = not busy and v.break_since is None
            for s in v.plan:  # (a loop, not any(): it runs at every assignment and idle)
                if s.task is not None:
                    busy, idle = True, False
                    break
                if not KINDS[s.kind].idle:  # a charging visit, a break
                    idle = False
        v.busy = busy
        self.idle_mask[v._slot] = idle
        self.busy_mask[v._slot] = busy
        if self.places is not None:
            self.place(v._slot)


_NO_POINTS = np.zeros(0, dtype=np.int64)
_NO_POINTS.setflags(write=False)
_ZERO = np.zeros(1)  # (np.r_'s result, without its index-trick machinery)
_ZERO.setflags(write=False)


# ----------------------------------------------------------------------------- drivers


def stop_leg(v: Vehicle, now: float) -> None:
    """Roads: ``v`` stops part-way along its leg at ``now``: the metres driven so far count
    (with the passengers on board) and it stands where it got (a node, or a road point
    part-way along an edge)."""
    leg, t = v.leg, now - v.leg_start
    v.drove(float(np.interp(t, np.concatenate((_ZERO, leg.times)),
                            np.concatenate((_ZERO, leg.metres)))), t)
    point = leg.point_at(t)
    v.loc, v.leg = (point.node if point.on_node else point), None
