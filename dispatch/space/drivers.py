"""Drivers: how a vehicle follows a planner's path in its space.

A driver is made by its space (:meth:`dispatch.api.space.Space.driver`) and used by the
:class:`dispatch.plan.operator.Operator` and the repositioning drives. :class:`Driver` is the one
base: :meth:`Driver.plan` asks the planner (a planner's own exception becomes one PluginError
line naming the planner, the run, the vehicle and the time), checks that the answer reaches the
goal (:meth:`Driver.reaches`) and turns it into what :meth:`Driver.drive` follows
(:meth:`Driver.route`). A subclass overrides:

* :meth:`reaches` (optional): whether a planner's path goes from the vehicle to the goal
  (default: the space's answer);
* :meth:`route` (optional): the path as the driver follows it (default: the path itself);
* :meth:`goal` (required): where a route ends;
* :meth:`drive` (required): the SimPy process fragment that follows a route;
* :attr:`plain_legs` (optional): True where :meth:`drive` is one timeout of ``route.seconds``
  ending with the vehicle on the route's last node, so the operator may drive it inline;
* :meth:`node_of` (optional): the place of the space a location stands at (default: itself);
* :meth:`leg_seconds` (optional): a route's planned seconds (default: 0, untimed).

Two ship with the kernel: :class:`CellDriver` (voxel world: cell by cell, a ``move`` event per
cell, as the paper's vehicles do) and :class:`RoadDriver` (road network: one timeout per leg;
where a vehicle is part-way through a leg is interpolated when someone asks). A driver stands
below the space that makes it: it holds that space (the voxel :class:`dispatch.space.world.World`,
the
:class:`dispatch.space.roads.RoadNetwork`) as the :class:`dispatch.api.space.Space` it was given,
and
imports only the small types below both (:mod:`dispatch.api.legs`, :mod:`dispatch.api.motion`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import simpy

from dispatch.api.contracts import Planner
from dispatch.api.legs import as_point
from dispatch.api.motion import step_length
from dispatch.api.problem import AgentView
from dispatch.api.space import Space
from dispatch.errors import PluginError
from dispatch.events import EventBus

if TYPE_CHECKING:
    from dispatch.api.legs import Leg
    from dispatch.plan.vehicles import Vehicle

__all__ = ["CellDriver", "Driver", "RoadDriver"]


def _plan(planner: Planner, agent: AgentView, goal, now: float, run_id: str):
    """``planner.plan``, with a planner's own exception turned into one PluginError line that
    names the planner, the run, the vehicle and the simulated time."""
    try:
        return planner.plan(agent, goal)
    except Exception as e:  # noqa: BLE001 - a plugin may raise anything
        raise _plan_error(planner, agent, goal, now, run_id,
                          f"raised {type(e).__name__}: {' '.join(str(e).split())[:300]}") from e


def _plan_error(planner: Planner, agent: AgentView, goal, now: float, run_id: str,
                why: str) -> PluginError:
    run = f", run {run_id}" if run_id else ""
    return PluginError(f"planner {planner.name!r}{run}, t = {now:.6g} s: plan() for vehicle "
                       f"{agent.id} -> {goal} {why}")


class Driver:
    """Follows a planner's paths in one space (see the module docstring for what a subclass
    overrides). ``space`` is the run's space, ``planner`` the planner the paths come from
    (a space's driver factory may wrap it), ``bus`` where ``move`` events go."""

    #: why a path that :meth:`reaches` refuses is no path (ends the error message)
    no_path = "gave no path to the goal although its cost was finite"

    def __init__(self, space: Space, planner: Planner, bus: EventBus) -> None:
        self.space, self.planner, self.bus = space, planner, bus
        self.run_id = ""  # named in error messages
        #: ``dispatch.*`` metadata entries the driver adds to the results (e.g. congestion)
        self.metadata: dict[str, str] = {}

    @property
    def plain_legs(self) -> bool:
        return False

    def start(self, v: Vehicle, now: float):
        """Where ``v`` is when a path is planned for it at ``now``, and its view then."""
        return v.loc, v.view()

    def node_of(self, loc):
        """The place where someone at ``loc`` waits (a rider put down by a breakdown) or is
        towed from: ``loc`` itself (a cell)."""
        return loc

    def leg_seconds(self, route) -> float:
        """The seconds a route's drive is planned to take, where the driver times its routes;
        0 where it does not (cells: a decision's insertion gives the planned times)."""
        return 0.0

    def reaches(self, path, start, goal) -> bool:
        """Whether ``path`` (a planner's answer) goes from ``start`` to ``goal``: the
        space's answer (:meth:`dispatch.api.space.Space.reaches`)."""
        return self.space.reaches(path, start, goal)

    def route(self, start, path):
        """``path`` as :meth:`drive` follows it (ValueError: it is not one)."""
        return path

    def plan(self, v: Vehicle, goal, now: float):
        """The route ``v`` drives to ``goal`` from where it is at ``now``."""
        start, agent = self.start(v, now)
        path = _plan(self.planner, agent, goal, now, self.run_id)
        if path is None or len(path) == 0 or not self.reaches(path, start, goal):
            raise _plan_error(self.planner, agent, goal, now, self.run_id, self.no_path)
        try:
            return self.route(start, path)
        except ValueError as e:
            raise _plan_error(self.planner, agent, goal, now, self.run_id,
                              f"gave a path that is not one: {e}") from None

    @staticmethod
    def goal(route):
        raise NotImplementedError

    def drive(self, env: simpy.Environment, v: Vehicle, route, task_id: int):
        raise NotImplementedError


class CellDriver(Driver):
    """Voxel world (``world``: a :class:`dispatch.space.world.World`): paths are cells; a vehicle
    steps from cell to cell at its speed."""

    no_path = ("gave no path from the vehicle's cell to the goal although its cost was "
               "finite")

    def __init__(self, world: Space, planner: Planner, bus: EventBus) -> None:
        super().__init__(world, planner, bus)
        self.world = world

    @staticmethod
    def goal(path):
        return path[-1]

    def drive(self, env: simpy.Environment, v: Vehicle, path, task_id: int):
        """Process fragment: follow ``path`` (each cell entered counts at once)."""
        cell_m = self.world.cell
        for nxt in path[1:]:
            step = step_length(v.loc, nxt) * cell_m
            yield env.timeout(step / v.speed)
            v.loc = nxt
            v.drove(step, step / v.speed)
            self.bus.emit(env.now, "move", v.id, task_id, nxt)


class RoadDriver(Driver):
    """Road network (``network``: a :class:`dispatch.space.roads.RoadNetwork`): a leg is the
    planner's node path, driven in one timeout."""

    no_path = "gave no path to the goal node although its cost was finite"

    def __init__(self, network: Space, planner: Planner, bus: EventBus,
                 edge_events: bool = False) -> None:
        super().__init__(network, planner, bus)
        self.network, self.edge_events = network, edge_events

    @property
    def plain_legs(self) -> bool:
        # the plan's process drives such legs itself, without a generator per leg
        return not self.edge_events and type(self).drive is RoadDriver.drive

    def start(self, v: Vehicle, now: float):
        return v.location(now), v.view(now)

    def node_of(self, loc) -> int:
        """The node of ``loc``: itself, or the node a road point part-way along an edge
        drives to."""
        return as_point(loc).node

    def leg_seconds(self, leg: Leg) -> float:
        return leg.seconds

    def route(self, start, path) -> Leg:
        return self.network.leg(start, path)

    @staticmethod
    def goal(leg):
        return int(leg.nodes[-1])

    def drive(self, env: simpy.Environment, v: Vehicle, leg: Leg, task_id: int):
        """Process fragment: drive ``leg`` (its metres count on arrival; a cut leg counts
        what was driven: :func:`dispatch.plan.vehicles.stop_leg`)."""
        v.leg, v.leg_start = leg, env.now
        if self.edge_events:
            start = env.now
            for node, t in zip(leg.nodes[1:], leg.times[1:]):
                yield env.timeout(start + float(t) - env.now)
                self.bus.emit(env.now, "move", v.id, task_id, int(node))
        else:
            yield env.timeout(leg.seconds)
        v.leg, v.loc = None, int(leg.nodes[-1])
        v.drove(leg.length, leg.seconds)
