"""The plugin contracts: what an allocator or a planner implements, and must never do (the data
it receives and returns is :mod:`dispatch.api.problem`).

Allocators
    Subclass :class:`Allocator` and implement :meth:`Allocator.allocate`. The allocator receives
    a read-only :class:`~dispatch.api.problem.AllocationProblem` and returns an
    :class:`~dispatch.api.problem.Allocation` that names agents and tasks by *id*. It must not
    mutate
    the problem, must not hold a task for two agents, and must not pair an agent with a task
    whose cost is ``inf``; the dispatcher rejects such answers with
    :class:`~dispatch.errors.AllocationError`. Randomness comes only from ``problem.rng``.
    Decentralized allocators should build on
    :class:`dispatch.api.decentralized.DecentralizedAllocator`,
    which runs the paper's decision rounds and conflict rule in one shared place.

Planners
    Subclass :class:`Planner` and implement :meth:`Planner.costs` and :meth:`Planner.plan`.
    A cost is the shortest path length (metres) divided by the agent's speed: travel seconds.
    ``inf`` marks a pair the agent can never serve (unreachable, or a UGV asked to fly).
    Planners may cache anything that depends only on the static world and the task's goal cell
    (the grid is immutable); :meth:`Planner.task_closed` tells them when a task's cache can go.

Lazy exact costs
    A planner that sets ``lower_bounds = True`` implements :meth:`Planner.bounds` (lower bounds
    of the costs, with a mask of the entries that are exact) and :meth:`Planner.exact` (the
    exact costs of given pairs); an allocator that sets ``minimizes_total_cost = True`` promises
    a maximum-cardinality, minimum-total-cost answer. With both and ``[dispatch] lazy_costs``
    the dispatcher decides on the bounds and certifies the answer (:mod:`dispatch.decide.lazy`).

Reservation-aware planners
    A planner that sets ``reservation_aware = True`` and implements :meth:`Planner.plan_timed`
    makes the kernel execute routes with reservations (:mod:`dispatch.plan.traffic`: the conflict
    rule, replans and waits; the time model is :func:`dispatch.api.motion.occupancy`). Other
    planners need neither; their vehicles follow :meth:`Planner.plan`'s paths without
    reservations.

Capabilities are declared
    What a plugin can do beyond the required methods is a boolean class attribute of its base
    class set to True (``decentralized``, ``minimizes_total_cost``, ``multi_request``,
    ``one_by_minimum``;
    ``lower_bounds``, ``travel_times``, ``reservation_aware``), and the methods a capability
    needs are methods of the base class the plugin then defines (the base class's say what
    they must do; the kernel calls them only on plugins that declare the capability). The
    registry reads the declaration once when it loads a plugin
    (:class:`dispatch.api.registry.Capabilities`) and refuses one that declares a capability
    without its methods, or that a scenario needs and it does not declare
    (:func:`dispatch.run.plugins.check_runs`). A constructor may withdraw a capability its
    parameters do not allow (an instance attribute set to False).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

import numpy as np

from dispatch.api.problem import AgentView, Allocation, AllocationProblem, TaskView
from dispatch.api.space import Space
from dispatch.locations import Cell, Location


class Allocator(ABC):
    """Base class of allocator plugins.

    Subclasses set ``name`` and implement :meth:`allocate`. Constructor keyword arguments come
    from the scenario's ``[dispatch.allocator_params]`` table; reject unknown ones with
    ``TypeError`` (the default ``__init__`` accepts none).
    """

    name: ClassVar[str] = ""
    #: True for methods whose agents decide from local information (reported in summaries).
    decentralized: ClassVar[bool] = False
    #: True for methods whose answer is always a maximum-cardinality assignment of finite-cost
    #: pairs with the smallest total cost among those, drawing nothing from ``problem.rng``
    #: (``hungarian``). The dispatcher may then decide on lower bounds of the costs and
    #: certify the answer (see :mod:`dispatch.decide.lazy`); a method that claims it wrongly gets
    #: answers that are not optimal for the exact costs.
    minimizes_total_cost: ClassVar[bool] = False
    #: True for batch-pooling methods that may give one agent several requests in one
    #: decision (``Allocation.routes`` then says in which order it serves them); the
    #: dispatcher gives them ``problem.travel`` to route between any locations, and checks
    #: each route by the schedule rule: a stop waits for its ``earliest`` time (the views'
    #: ``TaskView.earliest``, ``StopView.earliest``), every stop by its latest, the route's end
    #: by ``problem.until``. Others give an agent at most one request, inserted where the
    #: decision's cost says.
    multi_request: ClassVar[bool] = False
    #: True for methods whose answer to a problem of one task is that task to the agent of the
    #: least finite cost (the lowest agent id among equal costs), or nothing where every cost
    #: is ``inf``, as :meth:`~dispatch.api.problem.Allocation.centralized` builds it from that
    #: one pair, drawing nothing from ``problem.rng`` (``fcfs``, ``hungarian``). The dispatcher
    #: may then decide such a problem itself, without building it or asking the allocator
    #: (:mod:`dispatch.decide.one_request`); a method that claims it wrongly is not asked
    #: about one-request decisions at all. A subclass that overrides :meth:`allocate` without
    #: declaring it again does not inherit it (its own ``allocate`` is asked every time).
    one_by_minimum: ClassVar[bool] = False
    #: True for methods of :attr:`one_by_minimum` whose one-task answer may also be decided
    #: over only the agents that a lower bound of their cost cannot rule out: where the space
    #: and the planner promise such a bound (:attr:`dispatch.api.space.Space.top_speed`,
    #: :attr:`Planner.drive_floor`), the dispatcher then visits the idle vehicles nearest
    #: first and stops once the bound of every vehicle left exceeds the least cost found
    #: (:mod:`dispatch.decide.nearest`). The answer is the same; the decision still counts
    #: every candidate vehicle (``n_idle``). Like :attr:`one_by_minimum` it is not inherited
    #: by a subclass that overrides :meth:`allocate` without declaring it again.
    nearest_cut: ClassVar[bool] = False

    def __init_subclass__(cls, **kw) -> None:
        super().__init_subclass__(**kw)
        if "allocate" in vars(cls) and "one_by_minimum" not in vars(cls):
            cls.one_by_minimum = False
        if "allocate" in vars(cls) and "nearest_cut" not in vars(cls):
            cls.nearest_cut = False
    #: Named variants the plugin runs by name: ``"<name>:<variant>"`` (a scenario's
    #: ``allocator``, ``dispatch bench``) builds it with ``variant = "<variant>"`` unless the
    #: variant's own table, ``[dispatch.allocator_params."<name>:<variant>"]``, sets
    #: ``variant``; the constructor then takes a ``variant`` keyword (``magnnet``: ``match``,
    #: ``paper``, ``paper_nb``, ``ppo``). A name with another variant needs its table.
    variants: ClassVar[tuple[str, ...]] = ()
    #: The problems it decides where that is not every one: None (any), or the team sizes N
    #: of the static problems with as many tasks as agents that it decides (a network trained
    #: for one size: ``magnnet``'s ``paper`` variants); set by the constructor. ``dispatch
    #: bench`` reports another instance as ``unsupported``; a run of one fails at its first
    #: decision with the allocator's error.
    team_sizes: tuple[int, ...] | None = None

    @abstractmethod
    def allocate(self, problem: AllocationProblem) -> Allocation:
        """Return a valid allocation for ``problem`` (see the module docstring)."""

    def describe(self) -> dict[str, str]:
        """What the allocator ran, as strings (e.g. a learned model's name, variant and
        checkpoint hash; a batch method's counts, asked again at the end of a run): the
        summary's ``allocator_info`` column and the ``dispatch.allocator_info`` metadata.
        Default: nothing to say."""
        return {}


class Reservations(Protocol):
    """What a reservation-aware planner sees of the other vehicles' reservations (read-only)."""

    def blocked(self, cell: Cell) -> Sequence[tuple[float, float]]:
        """The half-open intervals ``[start, end)`` of simulated seconds during which ``cell``
        is reserved by someone else, sorted and merged (``end`` may be ``inf``)."""


@dataclass
class PlanStats:
    """Counters a planner keeps for the run's summary."""

    cost_queries: int = 0
    plans: int = 0
    extra: dict = field(default_factory=dict)


class Planner(ABC):
    """Base class of planner plugins.

    A planner is created once per run with the run's space (:class:`dispatch.api.space.Space`; a
    voxel planner gets the :class:`~dispatch.space.world.World`, also as ``self.world``) and serves
    the spaces named in :attr:`spaces` (a scenario that pairs it with another space fails
    validation). On roads, locations are nodes and road points, :meth:`plan` returns a node
    path and costs are the network's travel seconds. Costs are travel seconds:
    shortest path length in metres divided by the agent's speed; ``inf`` where the agent can
    never reach the task or may not serve it (a UGV and a task above the ground layer).
    Paths are lists of cells from the agent's cell to the goal cell, both included, each step a
    legal move of the agent's kind (see :mod:`dispatch.api.motion`).
    """

    name: ClassVar[str] = ""
    #: The kinds of space (:attr:`dispatch.api.space.Space.kind`) this planner serves.
    spaces: ClassVar[tuple[str, ...]] = ("voxel",)
    #: True for planners that implement :meth:`plan_timed` (execution with reservations).
    reservation_aware: ClassVar[bool] = False
    #: True for planners that implement :meth:`bounds` and :meth:`exact` (lazy exact costs:
    #: see :mod:`dispatch.decide.lazy`).
    lower_bounds: ClassVar[bool] = False
    #: True for planners that implement :meth:`between` (shared rides, drop-off limits, the
    #: added_time objective, energy and multi-request allocators need it: the kernel routes
    #: between the stops of a plan).
    travel_times: ClassVar[bool] = False
    #: A promise that lets a decision order vehicles by a lower bound of their cost
    #: (:mod:`dispatch.decide.nearest`): None (the default) promises nothing; a factor ``f >
    #: 0`` promises that the cost of a vehicle standing on node ``a`` (or stopped part-way
    #: along an edge into ``a``) to a task on node ``b`` is at least ``f`` times the straight
    #: line from ``a`` to ``b`` over the space's :attr:`~dispatch.api.space.Space.top_speed`,
    #: and that a vehicle's cost does not depend on which other vehicles are costed with it
    #: (the road planner: 1, its costs are the network's times; under congestion the
    #: smallest hourly factor).
    drive_floor: float | None = None
    #: Seconds after which a vehicle that found no timed route tries again (it also tries when
    #: other vehicles' reservations are released). Used only when ``reservation_aware``.
    retry_after: float = 1.0

    def __init__(self, space: Space) -> None:
        if space.kind not in self.spaces:
            raise TypeError(f"planner {self.name!r} serves {', '.join(self.spaces)} spaces, "
                            f"not {space.kind!r}")
        self.space = space
        self.world = space  # the voxel planners' name for it
        self.stats = PlanStats()

    @property
    def free_flow(self) -> Planner:
        """The planner whose costs are free-flow travel times (limits such as a request's
        direct time are set from them): itself, or the planner a congested one wraps
        (:class:`dispatch.space.congestion.CongestedPlanner`)."""
        return self

    def budget(self, *, agents: int, tasks: float, duration: float) -> str | None:
        """A sentence saying why a run of that many vehicles and (expected) tasks over that
        many simulated seconds would not finish with this planner's parameters, None when it
        would (the default); ``dispatch validate`` refuses the run with it (``--ignore-limits`` runs
        anyway). See :mod:`dispatch.scenario.budget`."""
        return None

    @abstractmethod
    def costs(self, agents: tuple[AgentView, ...], tasks: tuple[TaskView, ...]) -> np.ndarray:
        """Return the ``(len(agents), len(tasks))`` float array of travel seconds.

        ``agents`` is a sequence of views (the dispatcher passes an
        :class:`~dispatch.api.problem.AgentViews`: a planner may read its ``nodes`` / ``remaining``
        arrays instead of building every view)."""

    @abstractmethod
    def plan(self, agent: AgentView, goal: Location) -> list[Location] | None:
        """Return a shortest path from ``agent.loc`` to ``goal`` (cells; on roads, nodes from
        the node the agent is at or driving to), or None."""

    def plan_timed(self, agent: AgentView, goal: Cell | None, reservations: Reservations,
                   t0: float) -> list[tuple[float, Cell]] | None:
        """A timed route from ``agent.cell`` at time ``t0`` to ``goal``, or None (the vehicle
        waits and tries again later). Only called when ``reservation_aware`` is True.
        ``goal=None`` asks an idle vehicle that is in someone's way for a route to any cell
        where it can stay for good (the nearest: it is parking).

        The route is ``[(t0, agent.cell), (t1, c1), ..., (tn, goal)]``: ``t_i`` is when the step
        into ``c_i`` ends; each step is a legal move that takes its length / ``agent.speed``
        seconds and may start after a wait. Under the time model of
        :func:`dispatch.api.motion.occupancy` (standing cells, the step's bounding box, the
        goal held to infinity) the route must overlap none of ``reservations.blocked(cell)``.
        The kernel checks this and stops the run with an error naming the planner otherwise.
        A planner should return the earliest-arriving such route (SIPP does).
        """
        raise NotImplementedError(f"planner {self.name!r} does not declare reservation_aware")

    def bounds(self, agents, tasks: tuple[TaskView, ...]) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, exact)``, two ``(len(agents), len(tasks))`` arrays, for planners that set
        :attr:`lower_bounds`: ``lower[a, t] <= costs(agents, tasks)[a, t]`` for every pair (the
        cost as :meth:`costs` would compute it), and ``exact[a, t]`` (bool) True where
        ``lower[a, t]`` *is* that cost. An ``inf`` in ``lower`` must be exact (the pair can
        never be served): the dispatcher closes tasks as unreachable from it."""
        raise NotImplementedError(f"planner {self.name!r} does not declare lower_bounds")

    def exact(self, agents, tasks: tuple[TaskView, ...], rows: np.ndarray,
              cols: np.ndarray) -> np.ndarray:
        """``costs(agents, tasks)[rows, cols]`` (a 1-D float array), computing only those
        pairs; for planners that set :attr:`lower_bounds`."""
        raise NotImplementedError(f"planner {self.name!r} does not declare lower_bounds")

    def between(self, sources: Sequence[Location], targets: Sequence[Location],
                pairwise: bool = False) -> np.ndarray:
        """Travel seconds from each of ``sources`` (locations: on roads nodes or road points)
        to each of ``targets`` (nodes), as :meth:`costs` counts them: a ``(len(sources),
        len(targets))`` array, or with ``pairwise`` the 1-D array of ``sources[k] ->
        targets[k]``. For planners that set :attr:`travel_times`."""
        raise NotImplementedError(f"planner {self.name!r} does not declare travel_times")

    def task_closed(self, task_id: int) -> None:
        """Forget anything cached for a task that will never be asked about again."""
