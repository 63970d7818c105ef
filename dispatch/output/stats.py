"""The run's one-line summary, kept as running totals so a run never re-reads its history.

:class:`RunStats` subscribes to the task book's closures (each task is counted once, when it
reaches its terminal state); :meth:`RunStats.summary` adds the fleet's and the dispatcher's
totals at the end. The metric definitions are in the README's output section.
"""

from __future__ import annotations

import math

from dispatch.plan.tasks import COMPLETED, Task, TaskState


class RunStats:
    """Running totals over closed tasks."""

    def __init__(self) -> None:
        self.count = {s: 0 for s in TaskState}
        self.total_cost = 0.0  # planned cost of every assigned task
        self.assigned = 0  # tasks that had a vehicle when they closed (total_cost's terms)
        self.offered = 0
        self.clean = 0  # offered, assigned and never in conflict
        self.conflicts = 0
        self.waits = 0.0  # release -> pickup, over tasks picked up
        self.picked = 0
        self.travel = 0.0  # assignment -> pickup, over tasks picked up
        self.makespan = 0.0
        self.n_tasks = 0
        self.reassigned = 0  # tasks re-opened at least once by a breakdown
        self.transferred = 0  # ... with the passenger on board
        self.rides = 0  # completed trips with a drop-off and a direct time
        self.shared = 0  # ... of those, shared
        self.delay = 0.0  # ... their delay over the direct drive (s)
        self.detour = 0.0  # ... their in-vehicle time over the direct drive
        self.detours = 0  # ... those with a direct time > 0
        self.promises = 0  # booked requests accepted (dispatch.decide.prebook)
        self.promises_broken = 0  # ... of those, ended failed or expired
        self.offers = 0  # offers made to riders (dispatch.api.acceptor)
        self.revenue = 0.0  # fares of the completed rides ([pricing])
        # ... metres their riders walked (meeting points: dispatch.decide.meeting)
        self.walked = 0.0

    def closed(self, t: Task) -> None:
        self.n_tasks += 1
        self.count[t.state] += 1
        self.reassigned += t.reassigned > 0
        self.transferred += t.transfers > 0
        if t.agent_id >= 0:
            self.total_cost += t.cost
            self.assigned += 1
        if t.offered:
            self.offered += 1
            self.clean += t.agent_id >= 0 and not t.conflicted
        self.conflicts += t.conflicted
        if t.promised:
            self.promises += 1
            # (cut_off: cut by the run's end, not broken)
            self.promises_broken += t.state is not COMPLETED \
                and t.state is not TaskState.CUT_OFF
        self.offers += t.offers
        if t.state is COMPLETED and t.fare == t.fare:
            self.revenue += t.fare
        if not math.isnan(t.picked_up_at):
            self.picked += 1
            self.waits += t.picked_up_at - t.released_at
            self.travel += t.picked_up_at - t.assigned_at
        if t.state is COMPLETED:
            self.makespan = max(self.makespan, t.completed_at)
            direct = t.direct_time
            if t.dropoff is not None and direct == direct and t.dropped_at == t.dropped_at:
                self.rides += 1
                self.shared += t.shared
                self.delay += t.dropped_at - t.released_at - direct
                if t.meeting is not None and t.agent_id >= 0:
                    self.walked += t.meeting.walk_to_board + t.meeting.walk_from_alight
                if direct > 0:
                    self.detour += (t.dropped_at - t.picked_up_at) / direct
                    self.detours += 1

    def summary(self, *, run: dict, vehicles, dispatcher, sim_time: float) -> dict:
        """The summary row: ``run`` holds the run's keys (:data:`dispatch.config.runkeys.RUN_KEYS`)
        and its space."""
        c, d = self.count, dispatcher
        n_uav = sum(1 for v in vehicles if v.kind == "uav")
        n_ugv = sum(1 for v in vehicles if v.kind == "ugv")
        pax = sum(v.passenger_distance for v in vehicles)
        dist = sum(v.distance for v in vehicles)
        return dict(
            **run, n_tasks=self.n_tasks, total_cost=self.total_cost,
            conflict_free_rate=self.clean / self.offered if self.offered else math.nan,
            alloc_seconds=d.cost_seconds + d.decide_seconds,
            tasks_completed=c[TaskState.COMPLETED],
            tasks_unfinished=self.n_tasks - c[TaskState.COMPLETED],
            makespan=self.makespan, n_uav=n_uav, n_ugv=n_ugv, decisions=d.decisions,
            rounds=d.rounds, messages=d.messages, conflicts=self.conflicts,
            cost_seconds=d.cost_seconds, decide_seconds=d.decide_seconds,
            first_decision_cost=d.first_cost, first_decision_seconds=d.first_seconds,
            realized_travel=self.travel,
            wait_time_mean=self.waits / self.picked if self.picked else math.nan,
            tasks_expired=c[TaskState.EXPIRED], tasks_rejected=c[TaskState.REJECTED],
            tasks_unreachable=c[TaskState.UNREACHABLE], tasks_cut_off=c[TaskState.CUT_OFF],
            tasks_failed=c[TaskState.FAILED], sim_time=sim_time, comm_delay=d.comm_delay,
            agent_seconds=d.agent_seconds,
            distance=sum(v.distance for v in vehicles),
            empty_distance=sum(v.empty_distance for v in vehicles),
            occupied_distance=sum(v.occupied_distance for v in vehicles),
            failures=sum(v.failures for v in vehicles), tasks_reassigned=self.reassigned,
            tasks_transferred=self.transferred, tasks_assigned=self.assigned,
            reassignments=d.reassignments,
            passenger_distance=pax, occupancy=pax / dist if dist > 0 else math.nan,
            shared_rate=self.shared / self.rides if self.rides else math.nan,
            delay_mean=self.delay / self.rides if self.rides else math.nan,
            detour_ratio=self.detour / self.detours if self.detours else math.nan,
            promises=self.promises, promises_broken=self.promises_broken,
            tasks_declined=c[TaskState.DECLINED], offers=self.offers, revenue=self.revenue,
            walk_mean=self.walked / self.rides if self.rides else math.nan,
        )
