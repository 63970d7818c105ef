"""Allocation instances drawn as a run draws them, for code outside a run: a learned
allocator's training pools (``allocators/magnnet/problems.py``), benchmarks.

:func:`first_decision` gives what the first decision of a static scenario's run sees: the run's
space (the world of its seed), its fleet (placed as the run places it) and its first tasks
(drawn from the run's task stream), each from the same seeded stream as in the run, so an
instance of seed ``s`` is the one the run of seed ``s`` starts with. The caller costs it with
a planner of its choice (``dispatch.api.registry.load("planner", name)(instance.space)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dispatch.api.problem import AgentView, TaskView
from dispatch.api.space import Space
from dispatch.config.scenario import RunSpec, Scenario


@dataclass(frozen=True)
class FirstDecision:
    """The first decision of one run: its spec, space, idle vehicles and open tasks (views,
    as an allocation problem holds them)."""

    spec: RunSpec
    space: Space
    agents: tuple[AgentView, ...]
    tasks: tuple[TaskView, ...]


def first_decision(scenario: Scenario | str | Path, seed: int, n_agents: int,
                   n_tasks: int | None = None) -> FirstDecision:
    """The first decision of the run of ``scenario`` (a static scenario, or its file) with
    fleet size ``n_agents`` and ``seed``: the space of the seed, the fleet as the run places
    it (:func:`dispatch.fleet.placement.place_fleet`), and ``n_tasks`` tasks (default: the run's
    static task count)
    drawn from the run's task stream (:func:`dispatch.plan.demand.demand_for`), all released at time
    0."""
    from dispatch.api.space import space_for
    from dispatch.fleet.placement import place_fleet
    from dispatch.plan.demand import demand_for
    from dispatch.plan.tasks import Task
    from dispatch.scenario.load import load_scenario
    from dispatch.streams import STREAM_FLEET, STREAM_TASKS, rng_for

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    spec = sc.runs(agents=n_agents, seed=seed)[0]
    space = space_for(sc.world, seed, sc.path)
    vehicles = place_fleet(space, spec, rng_for(seed, STREAM_FLEET))
    demand = demand_for(space, sc.tasks, rng_for(seed, STREAM_TASKS))
    m = n_tasks if n_tasks is not None else spec.n_static_tasks
    tasks = [Task(j, (r := demand.draw()).kind, r.loc, 0.0) for j in range(m)]
    return FirstDecision(spec, space, tuple(v.view() for v in vehicles),
                         tuple(t.view() for t in tasks))
