"""The data a decision exchanges: what an allocator or a planner receives and what an allocator
returns (the plugins' contracts, which take and give these, are :mod:`dispatch.api.contracts`).

Received
    :class:`AllocationProblem`: one decision, read-only: the agents (:class:`AgentView`, as a
    lazy :class:`AgentViews` from the dispatcher), the open tasks (:class:`TaskView`), the cost
    matrix between them, the communication graph, the only random generator a plugin may use,
    and with shared rides each agent's plan (:class:`StopView`), seats and travel times.

Returned
    :class:`Allocation`: ``(agent_id, task_id)`` pairs and how they were reached (the
    :class:`Bid` of every round; messages, hops; a batch-pooling method's stop orders). Agents
    and tasks are named by *id*, never by position.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal, NamedTuple

import numpy as np

from dispatch.locations import Cell, Location

VehicleKind = Literal["uav", "ugv", "car"]
TaskKind = Literal["ground", "air", "trip"]


@dataclass(frozen=True, slots=True)
class AgentView:
    """What an allocator or planner may know about one vehicle at a decision.

    ``loc`` is where the vehicle is in the run's space: a voxel cell, or on roads a
    :class:`dispatch.space.roads.RoadPoint` (a node, or part-way along an edge)."""

    id: int
    kind: VehicleKind
    loc: Location
    speed: float  # metres per simulated second (roads: the network's travel times apply)

    @property
    def flies(self) -> bool:
        return self.kind == "uav"

    @property
    def cell(self) -> Cell:
        """The voxel name of :attr:`loc` (voxel planners speak cells)."""
        return self.loc


_NO_POINTS = np.zeros(0, dtype=np.int64)
_NO_POINTS.setflags(write=False)


class AgentViews(Sequence[AgentView]):
    """The agents of a decision: a read-only sequence of :class:`AgentView`, each built the
    first time it is read (a decision over a thousand idle vehicles need not build a thousand
    views when the allocator reads a few).

    It behaves as the tuple of views it stands for (index, slice, iterate, ``len``, ``==``);
    besides, it carries arrays a fast plugin may read instead of the views, all aligned with
    the sequence: ``ids`` (int64; ascending when the dispatcher builds it) and, on road
    networks (else None), ``nodes`` (the node each agent stands on or drives to next) and
    ``remaining`` (seconds left to that node: > 0 only part-way along an edge), with
    ``points`` the indices of those agents part-way along an edge (``remaining`` is 0 for all
    others). ``ascending`` is True when the ids are known to be strictly increasing.
    ``lazy`` is True where the views are built when first read (the dispatcher's: each id
    names a run's vehicle, which keeps its kind), False where they were given (:meth:`of`).
    """

    __slots__ = ("ids", "nodes", "remaining", "points", "ascending", "lazy", "_make", "_views")

    def __init__(self, ids: np.ndarray, make, nodes: np.ndarray | None = None,
                 remaining: np.ndarray | None = None, points: np.ndarray | None = None,
                 ascending: bool = False) -> None:
        self.ids = np.asarray(ids, dtype=np.int64)
        self.ids.setflags(write=False)
        self.ascending = ascending
        self.lazy = True
        self._make = make
        self._views: list[AgentView | None] | None = None
        self.nodes, self.remaining = nodes, remaining
        self.points = _NO_POINTS if points is None or not points.size else points
        if nodes is not None:
            nodes.setflags(write=False)
        if remaining is not None:
            remaining.setflags(write=False)
        self.points.setflags(write=False)

    @classmethod
    def of(cls, views) -> AgentViews:
        """Wrap already-built views (tests, hand-made problems)."""
        views = tuple(views)
        out = cls(np.fromiter((v.id for v in views), np.int64, len(views)), views.__getitem__)
        out._views = list(views)
        out.lazy = False
        return out

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return tuple(self[i] for i in range(*k.indices(len(self))))
        n = len(self.ids)
        k = int(k)
        if k < 0:
            k += n
        if not 0 <= k < n:
            raise IndexError("agent index out of range")
        views = self._views
        if views is None:
            views = self._views = [None] * n
        v = views[k]
        if v is None:
            v = views[k] = self._make(k)
        return v

    def __iter__(self):
        for k in range(len(self.ids)):
            yield self[k]

    def __eq__(self, other) -> bool:
        if not isinstance(other, Sequence) or isinstance(other, str):
            return NotImplemented
        return len(self) == len(other) and all(a == b for a, b in zip(self, other))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"AgentViews({len(self)} agents)"


@dataclass(frozen=True, slots=True)
class TaskView:
    """What an allocator or planner may know about one open task (a trip).

    ``loc`` is the pickup (a voxel cell or a road node); ``dropoff`` is where the trip ends
    (None for the paper's point tasks); ``deadline`` is the latest pickup time the request
    accepts (``released_at + max_wait``; ``inf`` without a ``max_wait``)."""

    id: int
    kind: TaskKind
    loc: Location
    released_at: float
    dropoff: Location | None = None
    deadline: float = math.inf
    #: shared rides: riders, and the latest drop-off time the request accepts (release +
    #: direct free-flow time + ``max_delay``; ``inf`` without a ``max_delay``)
    passengers: int = 1
    dropoff_deadline: float = math.inf
    #: the earliest time its pickup may start (a vehicle there sooner waits): a booked
    #: request's requested departure (:mod:`dispatch.decide.prebook`), a rider's arrival at a
    #: meeting
    #: point (:mod:`dispatch.decide.meeting`); ``-inf``: open since its release. Set in the views of
    #: decisions whose allocator routes several requests itself (``multi_request``)
    earliest: float = -math.inf

    @property
    def cell(self) -> Cell:
        """The voxel name of :attr:`loc`."""
        return self.loc


class _Positions:
    """An ``(K, 3)`` positions field of :class:`AllocationProblem` that may be given as an array
    or as a zero-argument callable returning it (the dispatcher's: most allocators never read
    positions, so a decision does not compute them unless someone does). Either way, reading
    the field gives the read-only array, checked for its shape on first read."""

    def __set_name__(self, owner, name: str) -> None:
        self.name, self.key = name, "_" + name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return None  # the field's default (dataclasses read it from the class)
        value = obj.__dict__[self.key]
        if callable(value):
            value = obj.__dict__[self.key] = obj._checked(self.name, value())
        return value

    def __set__(self, obj, value) -> None:
        obj.__dict__[self.key] = value


class StopView(NamedTuple):
    """One stop of an agent's plan as a decision sees it (shared rides): ``kind`` (``pickup``
    or ``dropoff``), the request's id, where, the passengers it adds (negative: removes),
    the latest time it may be reached, the occupancy after it, its planned arrival time and
    the earliest time its service may start (``-inf``: none; the planned arrival already
    counts the wait)."""

    kind: str
    task_id: int
    loc: Location
    passengers: int
    latest: float
    occupancy: int
    eta: float
    earliest: float = -math.inf


@dataclass(frozen=True, eq=False)
class AllocationProblem:
    """One decision: idle agents, open tasks, and the cost matrix between them (read-only).

    ``cost[a, t]`` is the travel time in seconds of ``agents[a]`` to ``tasks[t]``; ``inf`` where
    the agent cannot serve the task. ``comm`` is the symmetric boolean adjacency of the agents'
    communication graph, diagonal included (all True when range is unlimited; see
    :mod:`dispatch.api.comms`). ``rng`` is the only source of randomness an allocator may use.

    ``loss`` is the probability that one reception of a broadcast is lost (a decentralized
    allocator simulates it with ``rng``, e.g. through :class:`dispatch.api.comms.Channel`);
    ``latency`` is the simulated seconds per message hop, for information only: the dispatcher
    applies it from :attr:`Allocation.hops`. ``agent_pos`` / ``task_pos`` are the ``(N, 3)`` /
    ``(M, 3)`` positions in metres of the agents and of the tasks' pickups (for features and
    straight-line distances; costs come from ``cost``). ``cell_size`` (metres) is the voxel
    world's cell (1.0 on roads).

    ``agents`` is an :class:`AgentViews`: the dispatcher's (lazy, with arrays), or the views a
    hand-made problem gives (any sequence), wrapped by :meth:`AgentViews.of`;
    :attr:`agent_ids` / :attr:`task_ids` give the ids as arrays. With an unlimited communication range ``comm`` is a read-only
    all-True broadcast array (no ``N x N`` memory). ``agent_pos`` / ``task_pos`` may be given as
    zero-argument callables (the dispatcher does): computed when first read, then kept.
    """

    time: float
    agents: AgentViews
    tasks: tuple[TaskView, ...]
    cost: np.ndarray
    comm: np.ndarray
    rng: np.random.Generator
    max_rounds: int = 1000
    loss: float = 0.0
    latency: float = 0.0
    cell_size: float = 1.0
    agent_pos: np.ndarray | None = _Positions()  # type: ignore[assignment]
    task_pos: np.ndarray | None = _Positions()  # type: ignore[assignment]
    #: shared rides: the current stop list of each agent that has one, by agent id (a
    #: read-only mapping of tuples of :class:`StopView`); empty when no agent has a plan
    plans: Mapping[int, tuple[StopView, ...]] = field(default_factory=dict)
    #: shared rides: seats per agent (aligned with ``agents``; None: one each), the seconds a
    #: vehicle spends at a stop that completes a request, and ``travel(sources, targets)``:
    #: seconds between locations (a ``(len(sources), len(targets))`` array; None where the
    #: planner cannot route between arbitrary locations)
    capacity: np.ndarray | None = None
    service_time: float = 0.0
    travel: Callable[..., np.ndarray] | None = None
    #: shared rides: when each agent can leave where it is (the decision's time, or the end
    #: of the service it is in); None: the decision's time for all
    ready: np.ndarray | None = None
    #: driver shifts: the latest time each agent's plan may end (departure from its last stop:
    #: its shift's end plus the grace, ``-inf`` once it ended; aligned with ``agents``); None:
    #: no limit. A multi-request allocator's routes keep it (the dispatcher checks them)
    until: np.ndarray | None = None
    #: with plans: ``post(problem)``, where and when each pair's cheapest insertion leaves the
    #: agent's plan ending and the seats then free (a
    #: :class:`dispatch.api.value.PostDecision`; read by :func:`dispatch.api.value.value_costs`
    #: for allocators that look ahead); None: the dispatcher gives none
    post: Callable[..., object] | None = None

    @classmethod
    def made(cls, time: float, agents, tasks, cost: np.ndarray, comm: np.ndarray,
             rng: np.random.Generator, *, max_rounds: int, loss: float, latency: float,
             cell_size: float, agent_pos, task_pos, plans=None, capacity=None,
             service_time: float = 0.0, travel=None, ready=None,
             until=None, post=None) -> AllocationProblem:
        """The problem ``cls(...)`` of these fields (all of them, positionally) makes, checked
        the same way, without the field-by-field ``object.__setattr__`` of a frozen
        ``__init__`` (the dispatcher makes one per decision)."""
        obj = object.__new__(cls)
        obj.__dict__.update(time=time, agents=agents, tasks=tasks, cost=cost, comm=comm, rng=rng,
                            max_rounds=max_rounds, loss=loss, latency=latency,
                            cell_size=cell_size, _agent_pos=agent_pos, _task_pos=task_pos,
                            plans={} if plans is None else plans, capacity=capacity,
                            service_time=service_time, travel=travel, ready=ready,
                            until=until, post=post)
        obj.__post_init__()
        return obj

    def __post_init__(self) -> None:
        if not isinstance(self.agents, AgentViews):  # views given by hand: one type to read
            self.__dict__["agents"] = AgentViews.of(self.agents)
        n, m = len(self.agents), len(self.tasks)
        for name in ("agent_pos", "task_pos"):
            arr = self.__dict__["_" + name]
            if not callable(arr):
                self.__dict__["_" + name] = self._checked(name, arr)
        if self.cost.shape != (n, m):
            raise ValueError(f"cost has shape {self.cost.shape}, expected {(n, m)}")
        if self.comm.shape != (n, n):
            raise ValueError(f"comm has shape {self.comm.shape}, expected {(n, n)}")
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"loss must be in [0, 1), got {self.loss!r}")
        if not self.latency >= 0.0:
            raise ValueError(f"latency must be >= 0, got {self.latency!r}")
        self.cost.setflags(write=False)
        self.comm.setflags(write=False)

    def __getstate__(self) -> dict:
        """Pickled with its positions computed (a callable given for them may not pickle)."""
        state = dict(self.__dict__)
        state["_agent_pos"], state["_task_pos"] = self.agent_pos, self.task_pos
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        for name in ("cost", "comm", "_agent_pos", "_task_pos"):  # read-only again
            state[name].setflags(write=False)

    def _checked(self, name: str, arr: np.ndarray | None) -> np.ndarray:
        """Positions field ``name`` as kept: read-only, of shape ``(K, 3)`` (ValueError
        otherwise); None for a voxel problem built by hand (tests, training): cell centres."""
        views = self.agents if name == "agent_pos" else self.tasks
        if arr is None:
            arr = (np.array([v.loc for v in views], float).reshape(len(views), 3)
                   + 0.5) * self.cell_size
        if arr.shape != (len(views), 3):
            raise ValueError(f"{name} has shape {arr.shape}, expected {(len(views), 3)}")
        arr.setflags(write=False)
        return arr

    @property
    def n_agents(self) -> int:
        return len(self.agents)

    @property
    def agent_ids(self) -> np.ndarray:
        """The agents' ids (int64, aligned with ``agents``; read-only)."""
        return self.agents.ids

    # task_ids is cached by hand: functools.cached_property takes a lock on every first
    # read, and a run builds a problem per decision
    @property
    def task_ids(self) -> np.ndarray:
        """The tasks' ids (int64, aligned with ``tasks``; read-only)."""
        ids = self.__dict__.get("_task_ids")
        if ids is None:
            ids = self.__dict__["_task_ids"] = np.fromiter((t.id for t in self.tasks), np.int64,
                                                           len(self.tasks))
            ids.setflags(write=False)
        return ids

    @property
    def n_tasks(self) -> int:
        return len(self.tasks)

    @property
    def feasible(self) -> np.ndarray:
        """Boolean ``(N, M)`` mask of pairs with finite cost."""
        return np.isfinite(self.cost)


@dataclass(frozen=True)
class Bid:
    """One agent's bid for one task in one decision round (what the MAGNNET paper calls the
    agent's request; a request of the domain is a trip, :class:`dispatch.plan.tasks.Request`), and
    whether it won."""

    round: int
    agent_id: int
    task_id: int
    cost: float
    won: bool


@dataclass(frozen=True)
class Allocation:
    """An allocator's answer: ``(agent_id, task_id)`` pairs and how they were reached.

    ``requests`` lists every request made in every round (a centralized allocator lists its
    chosen pairs as round-0 requests that won); a task requested by two or more agents in one
    round, or requested after it was won, was in conflict. ``messages`` counts messages
    transmitted (0 for a centralized method; see :mod:`dispatch.api.comms`).

    ``hops`` is the number of sequential message hops of the decision (its critical path in
    communication): the dispatcher hands the tasks out ``hops * problem.latency`` simulated
    seconds after the decision started (0 for a centralized method). ``agent_seconds``, when
    given, holds each agent's own compute seconds (aligned with ``problem.agents``): agents think
    in parallel, so the decision's per-agent critical path is its maximum. Being wall-clock
    time, it takes no part in comparing two allocations.
    """

    pairs: tuple[tuple[int, int], ...]
    rounds: int = 1
    requests: tuple[Bid, ...] = ()
    messages: int = 0
    hops: int = 0
    agent_seconds: tuple[float, ...] = field(default=(), compare=False)  # wall clock
    #: allocators that set :attr:`dispatch.api.contracts.Allocator.multi_request` (batch pooling,
    #: e.g. RTV): the new stop order of each agent given one or more requests, by agent id:
    #: every stop of its current plan (``problem.plans``) and the pickup and drop-off of each
    #: of its new requests, as ``(kind, task_id)`` pairs (``"pickup"`` / ``"dropoff"``) in
    #: driving order. The dispatcher checks it (each request's pickup before its drop-off, the
    #: capacity and every limit on the network's travel times) and the vehicle drives it.
    routes: Mapping[int, tuple[tuple[str, int], ...]] = field(default_factory=dict)
    #: each pair's ``(row, column)`` in the problem, as :meth:`centralized` was given them (it
    #: turns them into the ids of ``pairs``): a hint :func:`dispatch.decide.answers.validate`
    #: verifies against the problem instead of looking every id up (a wrong hint changes
    #: nothing; empty: none). Not part of the answer's value.
    index: tuple[tuple[int, int], ...] = field(default=(), compare=False, repr=False)

    @classmethod
    def centralized(cls, problem: AllocationProblem, index_pairs) -> Allocation:
        """Build the answer of a centralized method from ``(agent_index, task_index)`` pairs."""
        pairs, reqs, index = [], [], []
        agent_ids, task_ids, cost = problem.agent_ids, problem.task_ids, problem.cost
        for a, t in index_pairs:
            aid, tid = int(agent_ids[a]), int(task_ids[t])
            pairs.append((aid, tid))
            index.append((a, t))
            reqs.append(Bid(0, aid, tid, float(cost[a, t]), True))
        if cls is not Allocation:  # a subclass may add fields or checks: its own __init__
            return cls(pairs=tuple(pairs), rounds=1, requests=tuple(reqs), messages=0)
        return cls(pairs=tuple(pairs), rounds=1, requests=tuple(reqs), messages=0,
                   index=tuple(index))

    def conflicted_tasks(self) -> set[int]:
        """Ids of tasks requested by more than one agent in some round, or requested again in a
        later round than the one it was won in (an agent that did not hear of the win); a
        fresh set each time."""
        if len(self.requests) < 2:  # a conflict takes two requests
            return set()
        return set(self._conflicts)

    @cached_property
    def _conflicts(self) -> frozenset[int]:
        """:meth:`conflicted_tasks`, computed once per answer (the dispatcher and the recorder
        both ask; a taxi decision logs hundreds of requests)."""
        seen: dict[tuple[int, int], int] = {}
        won: dict[int, int] = {}
        for r in self.requests:
            seen[(r.round, r.task_id)] = seen.get((r.round, r.task_id), 0) + 1
            if r.won:
                won[r.task_id] = min(r.round, won.get(r.task_id, r.round))
        late = {r.task_id for r in self.requests if r.task_id in won and r.round > won[r.task_id]}
        return frozenset({task for (_, task), n in seen.items() if n > 1} | late)
