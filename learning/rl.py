"""Reinforcement-learning interfaces to the simulator's own decisions (issue 22).

Two environments over any road scenario file, both stepping the real simulation (the same
vehicles, requests, congestion, rejections and summary as ``dispatch run``):

* :class:`DispatchEnv` — a Gymnasium ``Env`` with one central agent. One step is one dispatcher
  decision: the observation shows that decision's idle vehicles, its open requests, their cost
  matrix, the time and the recent demand per zone; the action is an allocation (a request,
  or none, for each vehicle); the simulation then runs to the next decision.
* :class:`FleetEnv` — a PettingZoo ``ParallelEnv`` with one agent per vehicle. The same
  decisions, seen locally: each vehicle observes its own costs to the open requests and, over
  the radio graph of the decision (``[comms] range``), the best cost of a neighbour for each;
  each idle vehicle answers one request or none; two vehicles asking for the same request
  are a conflict, won by the smaller cost (the paper's rule, as :mod:`dispatch.api.decentralized`).

How control is inverted (no threads). The environment builds the run with a deferring
allocator (``Simulation(..., allocator=...)``): when the dispatcher asks it, it keeps the :class:`AllocationProblem` and raises
:class:`dispatch.decide.dispatcher.DecisionDeferred`; the dispatcher's loop then waits on an event.
The environment stops stepping SimPy there and returns the observation. ``step(action)`` turns
the action into an :class:`Allocation`, triggers the event (at the same instant, ahead of any
other queued event) and steps SimPy again: the dispatcher builds the same problem again, gets
the answer and hands the trips out, and the run goes on to the next decision (or its end).
A decision the environment answers with Hungarian's pairs is therefore the decision a
``hungarian`` run takes (``tests/learning/test_rl.py`` checks the whole summary).

Sizes. Observations are padded to fixed sizes: ``max_agents`` vehicles (default: the fleet)
and ``max_tasks`` requests (default 32); a decision with more idle vehicles or open requests
shows (and lets the action use) the first ones only (vehicles by id, requests by release);
the others stay idle / open for the next decision. ``env.problem`` is the full problem.

Reward of a step (both environments; documented so policies compare): over the simulated
interval from this decision to the next one, ``+1`` per request picked up, ``-lost_cost`` per
request lost (rejected or expired) and ``-wait_cost`` per minute waited by the requests
picked up (release to pickup). Defaults ``lost_cost = 0``, ``wait_cost = 0.01``: the return of
a day is about the requests served, waits breaking ties. In :class:`FleetEnv` each vehicle
gets the pickups it made and their waits; the lost requests are shared evenly.

An episode is one run of the scenario (e.g. a day): it terminates when every request is
closed and the source is done, and is truncated at the scenario's ``duration``;
``env.summary`` then holds the run's summary row (as ``dispatch run`` prints it). ``reset(seed=s)``
simulates the day of seed ``s``; ``reset()`` without a seed simulates the next seed (the
constructor's first). Lazy costs are turned off (the action needs exact costs).
"""

from __future__ import annotations

import collections
import math
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import simpy
from simpy.events import URGENT

from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem
from dispatch.config.scenario import RunSpec, Scenario
from dispatch.config.sweep import SweepConfig
from dispatch.decide.dispatcher import DecisionDeferred
from dispatch.errors import AllocationError, ScenarioError
from dispatch.scenario.load import load_scenario
from learning.zones import Zones

__all__ = ["Decisions", "DispatchEnv", "FleetEnv", "pairs_from_choices"]


# ------------------------------------------------------------------------------ the driver
class _NullRecorder:
    """A recorder that keeps nothing (the environments need the summary, not the tables)."""

    out = None  # no results folder (the space's shared tables are not written)

    def __init__(self) -> None:
        self.metadata: dict = {}
        self.table_metadata: dict = {}

    def appender(self, table, columns=None):
        return lambda values: None

    def append(self, table, values) -> None:
        pass

    def add(self, table, **row) -> None:
        pass

    def finish(self) -> dict:
        return {}

    def abort(self) -> None:
        pass


class _Resume(simpy.Event):
    """The event the deferred decision waits on, triggered ahead of the events queued at the
    same instant (so nothing happens between the deferral and the answer)."""

    def go(self) -> None:
        self._ok, self._value = True, None
        self.env.schedule(self, URGENT)


class _Deferring(Allocator):
    """The allocator the environments put in the run: it keeps the problem and defers the
    decision (:class:`DecisionDeferred`), then returns the answer it was given."""

    name = "rl"
    decentralized = False

    def __init__(self, env: simpy.Environment) -> None:
        self.env = env
        self.problem: AllocationProblem | None = None  # waiting for an answer
        self.held: AllocationProblem | None = None  # answered, to be decided again
        self.answer: Allocation | None = None
        self.resume: _Resume | None = None

    def allocate(self, problem: AllocationProblem) -> Allocation:
        if self.answer is None:
            self.problem, self.resume = problem, _Resume(self.env)
            raise DecisionDeferred(self.resume)
        held, answer = self.held, self.answer
        self.held = self.answer = self.resume = None
        if not (np.array_equal(held.agent_ids, problem.agent_ids)
                and np.array_equal(held.task_ids, problem.task_ids)):
            raise AllocationError("the decision changed while it was deferred (learning.rl)")
        if held.cost.shape == problem.cost.shape and not np.array_equal(held.cost, problem.cost):
            raise AllocationError("the decision's costs changed while it was deferred")
        return answer


def _scenario(scenario: str | Path | Scenario, agents: int | None,
              batch_window: float | None) -> Scenario:
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    from dispatch.api.space import space_class

    if "rl" not in space_class(sc.world.space).features:
        raise ScenarioError(sc.path, "world.network", "learning.rl needs a road scenario")
    d = sc.dispatch
    window = d.batch_window if batch_window is None else float(batch_window)
    if batch_window is None and sc.sweep.batch_window:
        window = sc.sweep.batch_window[0]
    sc = replace(sc, dispatch=replace(d, batch_window=window, lazy_costs=False),
                 sweep=SweepConfig())
    if agents is not None:
        sc = replace(sc, fleet=replace(sc.fleet, agents=int(agents)))
    return sc


class Decisions:
    """One run of a scenario driven decision by decision (what both environments step).

    ``start()`` builds the run and goes to its first decision; ``problem`` is the decision
    waiting for an answer (None once the run is over); ``answer(allocation)`` hands it out
    and goes to the next decision, returning what happened meanwhile (pickups by vehicle,
    their waits, the requests lost). ``summary`` is the run's summary row once it is over."""

    def __init__(self, scenario: Scenario, seed: int, zone: float = 2000.0,
                 demand_window: float = 1800.0) -> None:
        from dispatch.run.sim import Simulation

        self.scenario = scenario
        # the summary names the run's decider: the shim, which defers every decision here
        spec = RunSpec(scenario, "rl", scenario.dispatch.planner, scenario.fleet.agents,
                       int(seed), scenario.reposition.policy)
        self.env = env = simpy.Environment()
        self.shim = _Deferring(env)
        self.sim = sim = Simulation(spec, _NullRecorder(), allocator=self.shim, env=env)
        horizon = env.timeout(scenario.duration)  # as Simulation.run, before any step
        self.until = env.any_of([sim.finished, horizon])
        self.space = sim.space
        self.node_xy = np.asarray(self.space.node_positions, dtype=float)[:, :2]
        self.zones = Zones(self.node_xy, zone)
        self.demand_window = float(demand_window)
        self._recent: collections.deque = collections.deque()  # (time, zone) of releases
        self._released: dict[int, float] = {}
        self._pickups: list[tuple[int, float]] = []  # (vehicle, wait) since the last decision
        self._lost = 0
        sim.bus.subscribe(self._on_event, ["release", "pickup", "reject", "expire"])
        self.summary: dict | None = None
        self.terminated = self.truncated = False
        self.decisions = 0

    # events ---------------------------------------------------------------------------
    def _on_event(self, ev) -> None:
        kind = ev.kind
        if kind == "release":
            self._released[ev.task_id] = ev.t
            loc = ev.loc
            node = loc if isinstance(loc, (int, np.integer)) else getattr(loc, "node", -1)
            if 0 <= node < len(self.zones.of_node):
                self._recent.append((ev.t, int(self.zones.of_node[node])))
        elif kind == "pickup":
            released = self._released.pop(ev.task_id, ev.t)
            self._pickups.append((ev.agent_id, ev.t - released))
        else:
            self._released.pop(ev.task_id, None)
            self._lost += 1

    def demand(self) -> np.ndarray:
        """Requests released per zone in the last ``demand_window`` seconds."""
        now, recent = self.env.now, self._recent
        while recent and recent[0][0] < now - self.demand_window:
            recent.popleft()
        counts = np.zeros(self.zones.n, dtype=np.float32)
        if recent:
            np.add.at(counts, np.fromiter((z for _, z in recent), np.int64, len(recent)), 1.0)
        return counts

    # stepping -------------------------------------------------------------------------
    @property
    def problem(self) -> AllocationProblem | None:
        return self.shim.problem

    @property
    def done(self) -> bool:
        return self.summary is not None

    def start(self) -> dict:
        return self._advance()

    def answer(self, allocation: Allocation) -> dict:
        """Hand ``allocation`` out for the waiting decision and run to the next one."""
        if self.shim.problem is None:
            raise RuntimeError("no decision is waiting (the run is over: reset the env)")
        self.shim.answer, self.shim.held, self.shim.problem = allocation, self.shim.problem, None
        self.shim.resume.go()
        self.decisions += 1
        return self._advance()

    def _advance(self) -> dict:
        env, until, shim = self.env, self.until, self.shim
        self._pickups, self._lost = [], 0
        while shim.problem is None:
            if until.processed:
                break
            try:
                env.step()
            except simpy.core.EmptySchedule:
                break
        if shim.problem is None and self.summary is None:
            self._finish()
        return {"pickups": self._pickups, "lost": self._lost}

    def _finish(self) -> None:
        """The end of the run: :meth:`dispatch.run.sim.Simulation.run` itself, its SimPy run made
        a no-op (this driver has already stepped the run to the stop ``Simulation.run`` would
        reach: ``until`` processed or an empty queue), so the legs driven, the requests left
        open (cut off), the vehicles' times and the summary come out exactly as in a run."""
        sim, env = self.sim, self.env
        self.terminated = bool(sim.finished.triggered)
        self.truncated = not self.terminated
        env.run = lambda until=None: None  # an instance attribute, removed below
        try:
            self.summary = sim.run()
        finally:
            del env.run


def pairs_from_choices(problem: AllocationProblem, choice: np.ndarray,
                       rows: int | None = None) -> Allocation:
    """The allocation of per-vehicle choices: ``choice[i]`` is ``0`` (no request) or
    ``k + 1`` (request ``k``) for the ``i``-th agent of ``problem``. Choices of a padded
    vehicle or request, or of an infeasible pair (``inf`` cost), are ignored; a request chosen
    by several vehicles goes to the one with the smallest cost (ties: the first)."""
    cost = problem.cost
    n, m = cost.shape
    choice = np.asarray(choice, dtype=np.int64).reshape(-1)[: n if rows is None else rows]
    i = np.flatnonzero((choice > 0) & (choice <= m))
    i = i[i < n]
    j = choice[i] - 1
    c = cost[i, j]
    ok = np.isfinite(c)
    i, j, c = i[ok], j[ok], c[ok]
    order = np.lexsort((i, c))
    seen: set[int] = set()
    pairs = []
    for k in order.tolist():
        if int(j[k]) not in seen:
            seen.add(int(j[k]))
            pairs.append((int(i[k]), int(j[k])))
    return Allocation.centralized(problem, pairs)


class _Common:
    """What both environments share: the scenario, the run, sizes and the reward."""

    def _setup(self, scenario, seed, agents, max_agents, max_tasks, batch_window, zone,
               demand_window, wait_cost, lost_cost, cost_scale) -> None:
        self.scenario = _scenario(scenario, agents, batch_window)
        self.seed = int(seed)
        self._next_seed = self.seed
        self.zone, self.demand_window = float(zone), float(demand_window)
        self.wait_cost, self.lost_cost = float(wait_cost), float(lost_cost)
        self.run: Decisions | None = None
        probe = self._new_run(self.seed)
        self.n_vehicles = len(probe.sim.vehicles)
        self.vehicle_ids = [v.id for v in probe.sim.vehicles]
        self.max_agents = self.n_vehicles if max_agents is None else int(max_agents)
        self.max_tasks = int(max_tasks)
        self.n_zones = probe.zones.n
        lo, hi = probe.node_xy.min(axis=0), probe.node_xy.max(axis=0)
        self._lo, self._span = lo, np.maximum(hi - lo, 1.0)
        mw = self.scenario.tasks.max_wait
        self.cost_scale = float(cost_scale if cost_scale is not None
                                else (mw if mw is not None and math.isfinite(mw) else 600.0))
        self._day = float(self.scenario.duration) if math.isfinite(self.scenario.duration) \
            else 86400.0
        self._probe = probe

    def _new_run(self, seed: int) -> Decisions:
        return Decisions(self.scenario, seed, self.zone, self.demand_window)

    def _start(self, seed: int | None) -> dict:
        if seed is None:
            seed = self._next_seed
        self._next_seed = int(seed) + 1
        probe, self._probe = getattr(self, "_probe", None), None
        self.run = probe if probe is not None and probe.sim.spec.seed == seed \
            else self._new_run(int(seed))
        return self.run.start()

    @property
    def problem(self) -> AllocationProblem | None:
        """The decision waiting for the action (None once the episode is over)."""
        return None if self.run is None else self.run.problem

    @property
    def summary(self) -> dict | None:
        """The run's summary row, once the episode is over."""
        return None if self.run is None else self.run.summary

    def _norm(self, xy: np.ndarray) -> np.ndarray:
        return np.clip((xy - self._lo) / self._span, 0.0, 1.0).astype(np.float32)

    def _xy(self, nodes) -> np.ndarray:
        return self.run.node_xy[np.asarray(nodes, dtype=np.int64)]

    def _agent_nodes(self, problem: AllocationProblem) -> np.ndarray:
        nodes = problem.agents.nodes
        if nodes is not None:
            return np.asarray(nodes, dtype=np.int64)
        return np.array([getattr(a.loc, "node", a.loc) for a in problem.agents], np.int64)

    def _reward_terms(self, happened: dict) -> tuple[float, float, int]:
        pickups = happened["pickups"]
        waits = sum(w for _, w in pickups)
        return float(len(pickups)), float(waits), int(happened["lost"])

    def _reward(self, happened: dict) -> float:
        n, waits, lost = self._reward_terms(happened)
        return n - self.lost_cost * lost - self.wait_cost * waits / 60.0


# --------------------------------------------------------------------------- DispatchEnv
def _gym():
    import gymnasium

    return gymnasium


try:  # the base classes when the (optional) packages are installed
    import gymnasium as _gymnasium

    _GymEnv = _gymnasium.Env
except ImportError:  # pragma: no cover - the learning (or magnnet) extra brings gymnasium
    _GymEnv = object

try:
    from pettingzoo import ParallelEnv as _ParallelEnv
except ImportError:  # pragma: no cover - the learning (or magnnet) extra brings pettingzoo
    _ParallelEnv = object


class DispatchEnv(_Common, _GymEnv):
    """A Gymnasium environment: one central agent decides every dispatcher decision.

    ``DispatchEnv(scenario, seed=0, *, agents=None, max_agents=None, max_tasks=32,
    batch_window=None, zone=2000.0, demand_window=1800.0, wait_cost=0.01, lost_cost=0.0,
    cost_scale=None)``: ``scenario`` a road scenario file (or a parsed :class:`Scenario`; its
    sweep is ignored: the first swept batch window, the file's fleet, or ``agents`` /
    ``batch_window`` given here). ``zone`` (metres) is the side of the demand zones.

    Observation (a ``Dict``; ``N = max_agents``, ``M = max_tasks``, ``Z`` zones):

    ========== ================ ================================================================
    key        shape            meaning
    ========== ================ ================================================================
    time       (1,)             simulated seconds since the start of the run
    agent_mask (N,)             1 for the rows that are idle vehicles of this decision
    agent_xy   (N, 2)           their positions, scaled to [0, 1] over the network's extent
    task_mask  (M,)             1 for the columns that are open requests of this decision
    pickup_xy  (M, 2)           the requests' pickups, scaled as agent_xy
    dropoff_xy (M, 2)           their drop-offs (the pickup for requests without one)
    waited     (M,)             seconds since the request was released
    slack      (M,)             seconds left to its pickup deadline (``cost_scale`` x 10 if none)
    cost       (N, M)           the decision's cost (seconds) divided by ``cost_scale``
                                (default: the scenario's ``max_wait``); ``feasible`` says
                                which pairs can be chosen (the others hold 0)
    feasible   (N, M)           1 where the vehicle can serve the request in time
    demand     (Z,)             requests released per zone in the last ``demand_window`` s
    ========== ================ ================================================================

    Action: ``MultiDiscrete([M + 1] * N)``: for each vehicle row, 0 (no request) or ``k + 1``
    (request ``k``); see :func:`pairs_from_choices` for what is ignored and how a request chosen
    twice is settled. :meth:`action_of` turns an :class:`Allocation` (e.g. Hungarian's answer
    to ``env.problem``) into the action. Reward: see the module doc. ``info``: ``time``,
    ``n_agents``, ``n_tasks`` (of the full problem), ``decision``, and after each step
    ``pickups``, ``lost``, ``wait_seconds``.
    """

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(self, scenario, seed: int = 0, *, agents: int | None = None,
                 max_agents: int | None = None, max_tasks: int = 32,
                 batch_window: float | None = None, zone: float = 2000.0,
                 demand_window: float = 1800.0, wait_cost: float = 0.01,
                 lost_cost: float = 0.0, cost_scale: float | None = None) -> None:
        gym = _gym()
        spaces = gym.spaces
        self._setup(scenario, seed, agents, max_agents, max_tasks, batch_window, zone,
                    demand_window, wait_cost, lost_cost, cost_scale)
        n, m, z = self.max_agents, self.max_tasks, self.n_zones
        f32, inf = np.float32, np.inf
        self.observation_space = spaces.Dict({
            "time": spaces.Box(0.0, inf, (1,), f32),
            "agent_mask": spaces.MultiBinary(n),
            "agent_xy": spaces.Box(0.0, 1.0, (n, 2), f32),
            "task_mask": spaces.MultiBinary(m),
            "pickup_xy": spaces.Box(0.0, 1.0, (m, 2), f32),
            "dropoff_xy": spaces.Box(0.0, 1.0, (m, 2), f32),
            "waited": spaces.Box(0.0, inf, (m,), f32),
            "slack": spaces.Box(0.0, inf, (m,), f32),
            "cost": spaces.Box(0.0, inf, (n, m), f32),
            "feasible": spaces.MultiBinary((n, m)),
            "demand": spaces.Box(0.0, inf, (z,), f32),
        })
        self.action_space = spaces.MultiDiscrete(np.full(n, m + 1, dtype=np.int64))

    # gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._start(seed)
        return self._observe(), self._info()

    def step(self, action):
        problem = self.problem
        if problem is None:
            raise RuntimeError("the episode is over: call reset()")
        allocation = pairs_from_choices(problem, action, rows=self.max_agents)
        happened = self.run.answer(allocation)
        info = self._info()
        n, waits, lost = self._reward_terms(happened)
        info.update(pickups=int(n), lost=lost, wait_seconds=waits)
        return (self._observe(), self._reward(happened), self.run.terminated,
                self.run.truncated, info)

    def action_of(self, allocation: Allocation | list[tuple[int, int]]) -> np.ndarray:
        """The action that makes these (agent id, task id) pairs (an :class:`Allocation`
        or its ``pairs``) for the waiting decision; pairs outside the padded sizes are left
        out."""
        problem = self.problem
        pairs = allocation.pairs if isinstance(allocation, Allocation) else allocation
        rows = {int(a): i for i, a in enumerate(problem.agent_ids.tolist())}
        cols = {int(t): j for j, t in enumerate(problem.task_ids.tolist())}
        action = np.zeros(self.max_agents, dtype=np.int64)
        for a, t in pairs:
            i, j = rows[int(a)], cols[int(t)]
            if i < self.max_agents and j < self.max_tasks:
                action[i] = j + 1
        return action

    # observations --------------------------------------------------------------------
    def _info(self) -> dict[str, Any]:
        p = self.problem
        return {"time": float(self.run.env.now), "decision": self.run.decisions,
                "n_agents": 0 if p is None else p.n_agents,
                "n_tasks": 0 if p is None else p.n_tasks}

    def _observe(self) -> dict[str, np.ndarray]:
        n, m = self.max_agents, self.max_tasks
        f32 = np.float32
        obs = {
            "time": np.array([self.run.env.now], f32),
            "agent_mask": np.zeros(n, np.int8), "agent_xy": np.zeros((n, 2), f32),
            "task_mask": np.zeros(m, np.int8), "pickup_xy": np.zeros((m, 2), f32),
            "dropoff_xy": np.zeros((m, 2), f32), "waited": np.zeros(m, f32),
            "slack": np.zeros(m, f32), "cost": np.zeros((n, m), f32),
            "feasible": np.zeros((n, m), np.int8), "demand": self.run.demand(),
        }
        p = self.problem
        if p is None:
            return obs
        a, t = min(p.n_agents, n), min(p.n_tasks, m)
        now = p.time
        obs["agent_mask"][:a] = 1
        obs["agent_xy"][:a] = self._norm(self._xy(self._agent_nodes(p)[:a]))
        tasks = p.tasks[:t]
        obs["task_mask"][:t] = 1
        picks = [x.loc for x in tasks]
        obs["pickup_xy"][:t] = self._norm(self._xy(picks))
        obs["dropoff_xy"][:t] = self._norm(self._xy(
            [x.loc if x.dropoff is None else x.dropoff for x in tasks]))
        obs["waited"][:t] = [max(0.0, now - x.released_at) for x in tasks]
        obs["slack"][:t] = [max(0.0, x.deadline - now) if math.isfinite(x.deadline)
                            else 10 * self.cost_scale for x in tasks]
        c = p.cost[:a, :t]
        ok = np.isfinite(c)
        obs["feasible"][:a, :t] = ok
        obs["cost"][:a, :t] = np.where(ok, np.maximum(c, 0.0), 0.0) / self.cost_scale
        return obs


# ----------------------------------------------------------------------------- FleetEnv
class FleetEnv(_Common, _ParallelEnv):
    """A PettingZoo ``ParallelEnv``: one agent per vehicle (``"vehicle_<id>"``), deciding
    together at each dispatcher decision from local observations.

    ``FleetEnv(scenario, seed=0, *, agents=None, max_tasks=16, batch_window=None, zone=2000.0,
    demand_window=1800.0, wait_cost=0.01, lost_cost=0.0, cost_scale=None)``.

    Observation of a vehicle (a ``Box`` of ``7 + 5 M`` floats, ``M = max_tasks``): its
    position (2, scaled to [0, 1]), whether it is idle in this decision, the time of day as
    ``sin`` and ``cos`` (one period = one day), the share of the other idle vehicles it hears
    over the radio graph, the recent demand of its zone (requests in the last
    ``demand_window`` seconds); then per open request (the first ``M``, by release): its own
    cost (seconds / ``cost_scale``; 1 where infeasible), the smallest cost among the vehicles
    it hears (1 if none can), the pickup position (2) and 1 if it can serve it. A vehicle that
    is not idle sees itself not idle, costs 1 and no request it can serve.

    Action: ``Discrete(M + 1)``: 0 (none) or ``k + 1`` (request ``k``); a vehicle that is not
    idle, or a request it cannot serve, is ignored; ``infos[agent]["action_mask"]`` says what
    counts. A request asked by several vehicles goes to the one with the smallest cost.
    Reward: the module doc's, per vehicle (its pickups and their waits; lost requests shared
    evenly). All agents stay for the whole episode (a day) and end together.
    """

    metadata: ClassVar[dict] = {"render_modes": [], "name": "dispatch_fleet_v0",
                                "is_parallelizable": True}

    def __init__(self, scenario, seed: int = 0, *, agents: int | None = None,
                 max_tasks: int = 16, batch_window: float | None = None,
                 zone: float = 2000.0, demand_window: float = 1800.0,
                 wait_cost: float = 0.01, lost_cost: float = 0.0,
                 cost_scale: float | None = None) -> None:
        gym = _gym()
        self._setup(scenario, seed, agents, None, max_tasks, batch_window, zone,
                    demand_window, wait_cost, lost_cost, cost_scale)
        self.possible_agents = [f"vehicle_{i}" for i in self.vehicle_ids]
        self.agents: list[str] = []
        self._name_of = dict(zip(self.vehicle_ids, self.possible_agents))
        self._row_of = {i: k for k, i in enumerate(self.vehicle_ids)}
        m = self.max_tasks
        self.n_features = 7 + 5 * m
        self._obs_space = gym.spaces.Box(-1.0, np.inf, (self.n_features,), np.float32)
        self._act_space = gym.spaces.Discrete(m + 1)

    def observation_space(self, agent):
        return self._obs_space

    def action_space(self, agent):
        return self._act_space

    def reset(self, seed: int | None = None, options: dict | None = None):
        self._start(seed)
        self.agents = list(self.possible_agents)
        obs, masks = self._observe()
        return obs, {a: {"action_mask": masks[a]} for a in self.agents}

    def step(self, actions: dict):
        problem = self.problem
        if problem is None:
            raise RuntimeError("the episode is over: call reset()")
        choice = np.zeros(problem.n_agents, dtype=np.int64)
        for r, aid in enumerate(problem.agent_ids.tolist()):
            a = actions.get(self._name_of[int(aid)])
            choice[r] = 0 if a is None else int(a)
        choice[choice > self.max_tasks] = 0
        happened = self.run.answer(pairs_from_choices(problem, choice))
        obs, masks = self._observe()
        lost_share = self.lost_cost * happened["lost"] / max(1, len(self.possible_agents))
        rewards = {a: -lost_share for a in self.agents}
        for vid, wait in happened["pickups"]:
            name = self._name_of.get(int(vid))
            if name is not None:
                rewards[name] += 1.0 - self.wait_cost * wait / 60.0
        done = self.run.done
        term = {a: bool(done and self.run.terminated) for a in self.agents}
        trunc = {a: bool(done and self.run.truncated) for a in self.agents}
        infos = {a: {"action_mask": masks[a]} for a in self.agents}
        if done:
            self.agents = []
        return obs, rewards, term, trunc, infos

    def _observe(self) -> tuple[dict, dict]:
        m, n_all = self.max_tasks, len(self.possible_agents)
        feats = np.zeros((n_all, self.n_features), np.float32)
        masks = np.zeros((n_all, m + 1), np.int8)
        masks[:, 0] = 1
        run = self.run
        sim = run.sim
        now = run.env.now
        nodes = np.array([getattr(v.loc, "node", v.loc) for v in sim.vehicles], np.int64)
        feats[:, 0:2] = self._norm(run.node_xy[nodes])
        phase = 2 * math.pi * (now % 86400.0) / 86400.0
        feats[:, 3], feats[:, 4] = math.sin(phase), math.cos(phase)
        demand = run.demand()
        if demand.size:
            feats[:, 6] = demand[np.maximum(run.zones.of_node[nodes], 0)] \
                * (run.zones.of_node[nodes] >= 0)
        base = 7
        own = feats[:, base:base + m]
        nbr = feats[:, base + m:base + 2 * m]
        pxy = feats[:, base + 2 * m:base + 4 * m].reshape(n_all, m, 2)
        can = feats[:, base + 4 * m:base + 5 * m]
        own[:] = 1.0
        nbr[:] = 1.0
        p = self.problem
        if p is not None and p.n_agents:
            rows = np.array([self._row_of[int(a)] for a in p.agent_ids.tolist()], np.int64)
            t = min(p.n_tasks, m)
            feats[rows, 2] = 1.0
            c = np.asarray(p.cost[:, :t], dtype=float)
            ok = np.isfinite(c)
            scaled = np.where(ok, np.clip(c / self.cost_scale, 0.0, 1.0), 1.0)
            own[rows, :t] = scaled
            can[rows, :t] = ok
            masks[rows, 1:t + 1] = ok
            best, hears = _neighbour_best(scaled, p.comm)
            nbr[rows, :t] = best
            feats[rows, 5] = hears / max(1, p.n_agents - 1)
            if t:
                picks = self._norm(self._xy([x.loc for x in p.tasks[:t]]))
                pxy[:, :t] = picks[None]
        obs = {a: feats[k] for k, a in enumerate(self.possible_agents)} if self.agents \
            or p is not None else {}
        mask = {a: masks[k] for k, a in enumerate(self.possible_agents)}
        return obs, mask

    def state(self) -> np.ndarray:
        """The global state (for a centralized critic): every vehicle's observation, stacked."""
        obs, _ = self._observe()
        return np.stack([obs[a] for a in self.possible_agents]) if obs else \
            np.zeros((len(self.possible_agents), self.n_features), np.float32)


def _neighbour_best(scaled: np.ndarray, comm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per agent and task, the smallest (scaled) cost among the other agents it hears, and
    how many it hears; ``comm`` may be the broadcast all-True array of an unlimited range."""
    n, t = scaled.shape
    if n == 0:
        return scaled, np.zeros(0)
    if comm.strides == (0, 0) and bool(comm.all()):  # everyone hears everyone
        if n == 1:
            return np.ones_like(scaled), np.zeros(1)
        order = np.argsort(scaled, axis=0, kind="stable")
        first = scaled[order[0], np.arange(t)]
        second = scaled[order[1], np.arange(t)]
        best = np.where(np.arange(n)[:, None] == order[0][None, :], second[None, :],
                        first[None, :])
        return best, np.full(n, n - 1.0)
    other = np.asarray(comm, dtype=bool) & ~np.eye(n, dtype=bool)
    best = np.ones_like(scaled)
    for k in range(t):
        best[:, k] = np.where(other, scaled[None, :, k], 1.0).min(axis=1, initial=1.0)
    return best, other.sum(axis=1).astype(float)
