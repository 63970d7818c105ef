"""One run: the world, the vehicles, the task source, the dispatcher, on one SimPy environment.

Randomness: every stream is a ``numpy.random.Generator`` seeded from the run's seed and a fixed
stream number, so the world (obstacles) depends on the seed only, and the same seed gives the
same fleet and the same tasks whichever allocator runs: instances are paired across allocators.
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache

import numpy as np
import simpy

from dispatch import registry
from dispatch.contracts import Allocation, AllocationProblem, Allocator, Planner
from dispatch.dispatcher import Dispatcher
from dispatch.errors import PluginError
from dispatch.physics import Physics
from dispatch.recorder import Recorder, json_meta
from dispatch.reservations import Traffic
from dispatch.scenario import RunSpec, WorldConfig
from dispatch.tasks import Task, TaskFactory, TaskState, start_source
from dispatch.vehicles import Vehicle
from dispatch.world import Cell, World, build_world

log = logging.getLogger(__name__)

STREAM_WORLD, STREAM_FLEET, STREAM_TASKS, STREAM_ALLOCATOR, STREAM_SOURCE = range(5)


def rng_for(seed: int, stream: int) -> np.random.Generator:
    """The generator of one named stream of a run's seed."""
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(stream,)))


@lru_cache(maxsize=8)
def world_for(cfg: WorldConfig, seed: int) -> World:
    """The world of a seed. Cached: runs that share it (other allocators, other fleet sizes)
    also share everything planners cache on its immutable grid."""
    o = cfg.obstacles
    return build_world(cfg.size, cfg.cell, o.count, o.min_size, o.max_size,
                       rng_for(seed, STREAM_WORLD))


def make_plugin(kind: str, name: str, params, *args):
    cls = registry.load(kind, name)
    try:
        return cls(*args, **dict(params))
    except TypeError as e:
        raise PluginError(f"{kind} {name!r} rejected its parameters {dict(params)}: {e}") from e


def place_fleet(world: World, spec: RunSpec, rng: np.random.Generator) -> list[Vehicle]:
    """UAVs (ids first) in free cells at or below the start altitude, UGVs in free ground
    cells; no two vehicles share a start cell."""
    fleet, grid = spec.fleet, world.grid
    free = grid.free_cells()
    max_k = int(math.floor(fleet.uav_max_start_altitude / grid.cell + 1e-9))
    air_pool = free[free[:, 2] <= max_k]
    taken: set[Cell] = set()
    vehicles = []
    for i in range(fleet.agents):
        flies = i < fleet.n_uav
        pool = air_pool if flies else free[free[:, 2] == 0]
        while True:
            c = pool[rng.integers(len(pool))]
            cell = (int(c[0]), int(c[1]), int(c[2]))
            if cell not in taken:
                break
        taken.add(cell)
        vehicles.append(Vehicle(i, "uav" if flies else "ugv",
                                fleet.uav_speed if flies else fleet.ugv_speed, cell))
    return vehicles


class Simulation:
    """Everything one run needs; :meth:`run` executes it, recording into ``recorder``, and
    returns the summary."""

    def __init__(self, spec: RunSpec, recorder: Recorder) -> None:
        sc = spec.scenario
        self.spec = spec
        self.env = simpy.Environment()
        self.world = world_for(sc.world, spec.seed)
        self.allocator: Allocator = make_plugin("allocator", spec.allocator,
                                                sc.dispatch.allocator_params)
        self.planner: Planner = make_plugin("planner", spec.planner, sc.dispatch.planner_params,
                                            self.world)
        self.alloc_rng = rng_for(spec.seed, STREAM_ALLOCATOR)
        self.task_factory = TaskFactory(self.world.grid, sc.tasks.ground_fraction,
                                        rng_for(spec.seed, STREAM_TASKS))
        self.vehicles = place_fleet(self.world, spec, rng_for(spec.seed, STREAM_FLEET))
        self.tasks: list[Task] = []
        self.recorder = recorder
        self.recorder.table_metadata["obstacles"] = {
            "dispatch.world_size": json_meta(list(self.world.size)),
            "dispatch.cell": str(self.world.cell),
        }
        self.physics = Physics(self.world)
        for v in self.vehicles:
            self.physics.add_vehicle(v.id, v.flies, self.world.grid.centre(v.cell))
        #: reservation-based execution, with a reservation-aware planner only
        self.traffic = Traffic(self) if self.planner.reservation_aware else None
        if self.traffic is not None:
            for v in self.vehicles:
                self.env.process(v.drive(self))
        self._source_finished = False
        self.finished = self.env.event()
        self.dispatcher = Dispatcher(self)
        self._source = start_source(self, rng_for(spec.seed, STREAM_SOURCE))

    # --------------------------------------------------------------- task life cycle
    def active_tasks(self) -> int:
        """Tasks released and not yet terminal."""
        return sum(1 for t in self.tasks if not t.state.terminal)

    def release(self, kind: str, cell: Cell) -> Task:
        task = Task(len(self.tasks), kind, cell, self.env.now)
        self.tasks.append(task)
        self.record_event("release", -1, task.id, cell)
        if not self.world.grid.is_free(cell):
            log.warning("task %d at %s lies in an obstacle; closed as unreachable", task.id, cell)
            self.close_task(task, TaskState.UNREACHABLE)
            return task
        ttl = self.spec.scenario.tasks.ttl
        if ttl is not None:
            self.env.process(self._expire(task, ttl))
        self.dispatcher.notify()
        return task

    def _expire(self, task: Task, ttl: float):
        yield self.env.timeout(ttl)
        if task.state is TaskState.OPEN:
            self.close_task(task, TaskState.EXPIRED)

    def assign(self, task: Task, vehicle: Vehicle, cost: float) -> None:
        path = None
        if self.traffic is None:
            path = self.planner.plan(vehicle.view(), task.cell)
            if path is None or path[0] != vehicle.cell or path[-1] != task.cell:
                raise RuntimeError(f"planner {self.spec.planner!r} gave no path for a finite "
                                   f"cost (vehicle {vehicle.id} -> task {task.id})")
        task.state, task.assigned_at, task.agent_id, task.cost = (
            TaskState.ASSIGNED, self.env.now, vehicle.id, cost)
        self.record_event("assign", vehicle.id, task.id, task.cell)
        vehicle.busy = True
        if self.traffic is None:
            self.env.process(vehicle.serve(self, task, path))
        else:  # its drive process follows the route; the task's cost is its priority
            vehicle.task, vehicle.busy_since = task, self.env.now
            self.record_event("depart", vehicle.id, task.id, vehicle.cell)
            self.traffic.request(vehicle)

    def task_arrived(self, task: Task, vehicle: Vehicle) -> None:
        task.arrived_at = self.env.now
        self.record_event("arrive", vehicle.id, task.id, vehicle.cell)

    def task_completed(self, task: Task, vehicle: Vehicle) -> None:
        task.completed_at = self.env.now
        self.close_task(task, TaskState.COMPLETED)
        self.record_event("idle", vehicle.id, -1, vehicle.cell)
        self.dispatcher.notify()

    def close_task(self, task: Task, state: TaskState) -> None:
        if task.state.terminal:
            raise RuntimeError(f"task {task.id} is already {task.state.value}")
        task.state, task.closed_at = state, self.env.now
        self.planner.task_closed(task.id)
        self.record_event({"completed": "complete", "expired": "expire",
                           "unreachable": "unreachable", "cancelled": "cancel"}[state.value],
                          task.agent_id, task.id, task.cell)
        self._check_finished()

    def source_done(self) -> None:
        self._source_finished = True
        self._check_finished()

    def _check_finished(self) -> None:
        if self._source_finished and not self.finished.triggered and self.active_tasks() == 0:
            self.finished.succeed()

    # --------------------------------------------------------------- recording
    def record_event(self, event: str, agent_id: int, task_id: int, cell: Cell | None) -> None:
        x, y, z = self.world.grid.centre(cell) if cell is not None else (math.nan,) * 3
        self.recorder.add("events", t=float(self.env.now), event=event, agent_id=agent_id,
                          task_id=task_id, x=x, y=y, z=z)

    def record_decision(self, index: int, problem: AllocationProblem, allocation: Allocation,
                        cost_s: float, decide_s: float, *, hops: int = 0, comm_delay: float = 0.0,
                        agent_seconds: float = math.nan, components: int = 1) -> float:
        for r in allocation.requests:
            self.recorder.add("assignments", decision=index, round=r.round, agent_id=r.agent_id,
                              task_id=r.task_id, cost=r.cost, won=r.won,
                              alloc_seconds=cost_s + decide_s)
        rows = {a.id: i for i, a in enumerate(problem.agents)}
        cols = {t.id: j for j, t in enumerate(problem.tasks)}
        total = float(sum(problem.cost[rows[a], cols[t]] for a, t in allocation.pairs))
        self.recorder.add("decisions", decision=index, t=float(problem.time),
                          n_idle=problem.n_agents, n_tasks=problem.n_tasks,
                          n_assigned=len(allocation.pairs), rounds=allocation.rounds,
                          messages=allocation.messages,
                          conflicts=len(allocation.conflicted_tasks()), total_cost=total,
                          cost_seconds=cost_s, decide_seconds=decide_s, hops=hops,
                          comm_delay=comm_delay, agent_seconds=agent_seconds,
                          comm_components=components)
        return total

    # --------------------------------------------------------------- running
    def run(self) -> dict:
        """Run until every task is terminal and the source is done, or the horizon."""
        try:
            horizon = self.env.timeout(self.spec.scenario.duration)
            self.env.run(until=self.env.any_of([self.finished, horizon]))
            for t in self.tasks:
                if not t.state.terminal:
                    self.close_task(t, TaskState.CANCELLED)
            for v in self.vehicles:
                if v.busy:
                    v.busy_seconds += self.env.now - v.busy_since
                v.end_wait(self.env.now)
            return self._finish()
        finally:
            self.physics.close()

    def _finish(self) -> dict:
        rec, spec = self.recorder, self.spec
        g = self.world.grid
        for t in self.tasks:
            x, y, z = g.centre(t.cell)
            rec.add("tasks", task_id=t.id, kind=t.kind, x=x, y=y, z=z, dropoff_x=math.nan,
                    dropoff_y=math.nan, dropoff_z=math.nan, released_at=t.released_at,
                    max_wait=math.nan, snap_m=math.nan, dropoff_snap_m=math.nan,
                    assigned_at=t.assigned_at, agent_id=t.agent_id, cost=t.cost,
                    picked_up_at=t.arrived_at, completed_at=t.completed_at, state=t.state.value,
                    conflicted=t.conflicted, closed_at=t.closed_at)
        for v in self.vehicles:
            x, y, z = g.centre(v.start)
            rec.add("vehicles", agent_id=v.id, kind=v.kind, speed=v.speed, x0=x, y0=y, z0=z,
                    distance=v.distance, empty_distance=v.distance, occupied_distance=0.0,
                    busy_seconds=v.busy_seconds, tasks_completed=v.completed,
                    waits=v.waits, replans=v.replans, wait_seconds=v.wait_seconds)
        for b in self.world.boxes:
            rec.add("obstacles", x0=b.x0, y0=b.y0, z0=b.z0, x1=b.x1, y1=b.y1, z1=b.z1)
        summary = summarize(self)
        rec.add("summary", **summary)
        return summary


def summarize(sim: Simulation) -> dict:
    """The run's one-line summary (see DESIGN.md, Metrics)."""
    spec, tasks, d = sim.spec, sim.tasks, sim.dispatcher
    count = {s: sum(1 for t in tasks if t.state is s) for s in TaskState}
    assigned = [t for t in tasks if t.agent_id >= 0]
    offered = [t for t in tasks if t.offered]
    clean = sum(1 for t in offered if t.agent_id >= 0 and not t.conflicted)
    waits = [t.arrived_at - t.released_at for t in tasks if not math.isnan(t.arrived_at)]
    travels = [t.arrived_at - t.assigned_at for t in tasks if not math.isnan(t.arrived_at)]
    n_uav = sum(1 for v in sim.vehicles if v.flies)
    distance = float(sum(v.distance for v in sim.vehicles))
    return dict(
        scenario=spec.scenario.name, allocator=spec.allocator, planner=spec.planner,
        n_agents=len(sim.vehicles), n_tasks=len(tasks), seed=spec.seed, space="voxel",
        total_cost=float(sum(t.cost for t in assigned)),
        conflict_free_rate=clean / len(offered) if offered else math.nan,
        alloc_seconds=d.cost_seconds + d.decide_seconds,
        tasks_completed=count[TaskState.COMPLETED],
        tasks_unfinished=len(tasks) - count[TaskState.COMPLETED],
        makespan=max((t.completed_at for t in tasks if t.state is TaskState.COMPLETED),
                     default=0.0),
        n_uav=n_uav, n_ugv=len(sim.vehicles) - n_uav, decisions=d.decisions, rounds=d.rounds,
        messages=d.messages, conflicts=sum(1 for t in tasks if t.conflicted),
        cost_seconds=d.cost_seconds, decide_seconds=d.decide_seconds,
        first_decision_cost=d.first_cost, first_decision_seconds=d.first_seconds,
        realized_travel=float(sum(travels)),
        wait_time_mean=float(np.mean(waits)) if waits else math.nan,
        tasks_expired=count[TaskState.EXPIRED], tasks_rejected=0,
        tasks_unreachable=count[TaskState.UNREACHABLE],
        tasks_cancelled=count[TaskState.CANCELLED], tasks_failed=0, sim_time=float(sim.env.now),
        comm_delay=d.comm_delay, agent_seconds=d.agent_seconds,
        distance=distance, empty_distance=distance, occupied_distance=0.0,
    )


def _spec_meta(spec: RunSpec) -> dict:
    return {"allocator": spec.allocator, "planner": spec.planner, "n_agents": spec.agents,
            "seed": spec.seed, "scenario": spec.scenario.name}
