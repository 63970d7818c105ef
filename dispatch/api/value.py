"""The value of a vehicle after a decision: what plugins ask to look ahead.

An allocator that scores (vehicle, request) pairs may add to each pair's cost the future the
pair leaves the vehicle in: a :class:`ValueFunction` answers ``value(place, time, seats_left)``
-- the discounted number of requests a vehicle whose plan ends at node ``place`` at ``time``
with ``seats_left`` free seats will still serve -- for whole arrays of candidate pairs at once
(vectorised: one call per decision, never one per pair). :func:`value_costs` turns a
problem's cost matrix into

    cost[i, j] - weight * (gamma ** (end[i, j] - now) * V(place[i, j], end[i, j], seats[i, j])
                           - gamma ** (end_i - now) * V(place_i, end_i, seats_i))

where ``place``, ``end`` and ``seats`` are the vehicle's post-decision state
(:func:`post_decision`): where and when its plan ends if it takes request ``j``, and its free
seats then; ``place_i``, ``end_i``, ``seats_i`` are the same of vehicle ``i`` taking nothing:
the end of its own plan (an idle vehicle: where it is, now, all its seats free). The
difference is what taking ``j`` adds to the vehicle's future, the same state the trainer
learns values of (a busy vehicle's value "now, all seats free" is one it is never in). ``weight`` is seconds of cost per unit of value; ``weight = 0`` (or a value that
is zero everywhere) returns the cost matrix itself, so the allocator decides exactly as
without a value. ``inf`` pairs stay ``inf``.

The post-decision state comes from the problem: with plans (shared rides, drop-off limits, the
``added_time`` objective) the dispatcher gives :attr:`AllocationProblem.post`, the end of each
pair's cheapest insertion; without, a pair's plan ends at the request's drop-off, ``cost``
seconds plus the trip's drive (:meth:`ValueFunction.trip_seconds`) after now. An allocator that
routes several requests (``rtv``) asks :meth:`ValueFunction.value` for its routes' ends itself.

Values are learned on one road network: :attr:`ValueFunction.network` is a fingerprint of its
node positions (:func:`network_key`), and :func:`check_network` refuses a value on another
network with one line.
"""

from __future__ import annotations

import hashlib
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class ValueFunction(Protocol):
    """A learned value of a vehicle's post-decision state (see the module doc)."""

    #: discount per simulated second (1.0: none)
    gamma: float
    #: seconds of cost per unit of value, when the allocator's parameters give none
    weight: float
    #: :func:`network_key` of the network the value was learned on ("" : any)
    network: str

    def value(self, place: np.ndarray, time: np.ndarray,
              seats_left: np.ndarray | None = None) -> np.ndarray:
        """Value of a vehicle at node ``place`` at ``time`` with ``seats_left`` free seats
        (None: all its seats), element-wise over broadcast arrays; 0 where it knows nothing."""
        ...

    def trip_seconds(self, pickup: np.ndarray, dropoff: np.ndarray, time: float) -> np.ndarray:
        """Expected drive from each pickup node to its drop-off node (aligned arrays)."""
        ...


class PostDecision(NamedTuple):
    """Where each pair's plan ends, how many seconds after the decision, and the seats then
    free (``(n, m)`` arrays aligned with a problem's cost matrix); ``rest``: the same of each
    vehicle taking nothing (``(n,)`` arrays: its own plan's end), None where no vehicle has a
    plan (it stays where it is, now, all seats free)."""

    place: np.ndarray
    after: np.ndarray
    seats: np.ndarray
    rest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def network_key(node_xy) -> str:
    """A fingerprint of a road network: its node count and positions to the centimetre."""
    xy = np.round(np.asarray(node_xy, dtype=float)[:, :2] * 100.0).astype(np.int64)
    return f"{len(xy)}:" + hashlib.sha256(np.ascontiguousarray(xy).tobytes()).hexdigest()[:16]


class NetworkMismatch(ValueError):
    """A value learned on another network than the run's."""


def check_network(value: ValueFunction, node_xy, source: str = "the value") -> None:
    """Raise :class:`NetworkMismatch` (one line) unless ``value`` was learned on the network of
    these node positions (a value with an empty :attr:`~ValueFunction.network` fits any)."""
    if not value.network:
        return
    key = network_key(node_xy)
    if key != value.network:
        raise NetworkMismatch(
            f"{source} was learned on another road network ({value.network.split(':')[0]} "
            f"nodes, fingerprint {value.network.split(':')[-1]}) than this run's "
            f"({key.split(':')[0]} nodes, {key.split(':')[-1]}): train one for this network")


class ZeroValue:
    """The value that is zero everywhere: an allocator with it decides as without a value."""

    gamma = 1.0
    weight = 0.0
    network = ""

    def value(self, place, time, seats_left=None) -> np.ndarray:
        return np.zeros(np.broadcast(np.asarray(place), np.asarray(time)).shape)

    def trip_seconds(self, pickup, dropoff, time) -> np.ndarray:
        return np.zeros(np.shape(pickup))


def nodes_of(problem) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(agent nodes, pickup nodes, drop-off nodes)`` of a road problem, or None where its
    locations are not network nodes (a voxel world)."""
    nodes = problem.agents.nodes
    if nodes is None:
        nodes = [getattr(a.loc, "node", a.loc) for a in problem.agents]
    picks = [t.loc for t in problem.tasks]
    drops = [t.loc if t.dropoff is None else t.dropoff for t in problem.tasks]
    if not all(isinstance(x, (int, np.integer)) and not isinstance(x, bool)
               for x in (*picks, *drops, *nodes)):
        return None
    return (np.asarray(nodes, dtype=np.int64).reshape(-1), np.array(picks, np.int64),
            np.array(drops, np.int64))


def post_decision(problem, value: ValueFunction) -> PostDecision | None:
    """Each pair's post-decision state (see the module doc): the dispatcher's
    (:attr:`AllocationProblem.post`) where it gives one, else the request's drop-off, ``cost``
    plus the expected trip after now, all seats free; None off road networks."""
    got = nodes_of(problem)
    if got is None:
        return None
    post = getattr(problem, "post", None)
    if post is not None:
        return post(problem)
    _, picks, drops = got
    now = float(problem.time)
    cost = np.asarray(problem.cost, dtype=float)
    c = np.where(np.isfinite(cost), cost, 0.0)
    after = c + value.trip_seconds(picks, drops, now)[None, :]
    seats = np.ones(cost.shape, np.int64) if problem.capacity is None \
        else np.broadcast_to(np.asarray(problem.capacity, np.int64)[:, None], cost.shape)
    return PostDecision(np.broadcast_to(drops[None, :], cost.shape), after, seats)


def value_costs(problem, value: ValueFunction | None, weight: float | None = None
                ) -> np.ndarray:
    """The problem's costs less the discounted value of each pair's post-decision state, plus
    the value of the vehicle's state now (the module's formula); ``problem.cost`` itself where
    ``value`` is None, the weight is 0 or the problem is not on a road network."""
    cost = problem.cost
    w = (0.0 if value is None else value.weight) if weight is None else float(weight)
    if value is None or w == 0.0 or cost.size == 0:
        return cost
    post = post_decision(problem, value)
    if post is None:
        return cost
    nodes = nodes_of(problem)[0]
    now = float(problem.time)
    finite = np.isfinite(cost)
    dt = post.after
    after = np.power(value.gamma, dt) * value.value(post.place, now + dt, post.seats)
    if post.rest is None:  # no plans: a vehicle that takes nothing stays where it is, now
        seats_now = None if problem.capacity is None else np.asarray(problem.capacity,
                                                                      np.int64)
        before = value.value(nodes, np.full(nodes.shape, now), seats_now)
    else:  # its own plan's end: the post-decision state of taking nothing
        place, dt0, seats0 = post.rest
        before = np.power(value.gamma, dt0) * value.value(place, now + dt0, seats0)
    return np.where(finite, cost - w * (after - before[:, None]), np.inf)
