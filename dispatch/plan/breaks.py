"""Drivers' breaks (``[fleet.breaks]``): after ``after`` seconds on duty a vehicle takes a break
of ``duration`` seconds, planned as a stop of its plan.

**The rule.** A vehicle's stretch on duty starts at its shift's start (:mod:`dispatch.fleet.
shifts`; without shifts: the run's start) and again at the end of each break. When a stretch
reaches ``after`` seconds the break is due and is planned at once as a :data:`BREAK` stop:

* where the vehicle is empty (no rider on board at the stop before it): the first such place
  in its plan whose later stops all keep their windows once the break pushes them (every
  promised pickup and drop-off stays on time); failing that, after its last stop (where no
  one is on board);
* at the place of the stop before it (the node the vehicle stands on or drives to, when the
  break is first), so it needs no drive of its own;
* its window opens when it is due (``earliest``: a break never starts before ``after`` seconds
  on duty) and it lasts ``duration`` seconds (its ``service``, so the schedule rule and every
  insertion count it); it holds every seat (:attr:`dispatch.plan.stops.Stop.holds_seats`), so
  no insertion carries a rider across it.

A vehicle off duty, on its way home or broken down when its break falls due takes it when it
is next in service and free of those (checked every ``RETRY`` seconds); one that is on a
break, or has one planned, is not given another. Events ``break_start`` and ``break_end``
(the vehicle, task -1); the ``vehicles`` table's ``break_seconds`` sums its breaks.
Breaks need a road network and single-request decisions (the scenario check refuses others).
"""

from __future__ import annotations

import math

import simpy

from dispatch.plan.stops import DEPOT, TOL, Stop, StopKind, leave, pushed

#: the stop kind of a break
BREAK = "break"
#: seconds between two looks at a vehicle whose break is due but cannot be planned yet
RETRY = 60.0


class Break(StopKind):
    """A driver's break: ``break_start``, ``service`` seconds standing, ``break_end``. Neither
    idle nor busy while it is all that is planned."""

    name = BREAK
    idle = False

    def there(self, v, stop: Stop, now: float) -> bool:
        return v.location(now) == stop.loc

    def arrive(self, op, v, stop: Stop):
        # made as a request's service is: off the plan at once, the vehicle free at its end
        # (decisions plan the stops after it from then on), neither idle nor busy meanwhile
        env = op.env
        start = env.now
        v.plan.done()
        v.free_at, v.break_since = start + stop.service, start
        v.plan.changed()
        op.fleet.refresh(v)
        op.bus.emit(start, "break_start", v.id, -1, v.loc)
        try:
            yield env.timeout(stop.service)
        except simpy.Interrupt:  # a breakdown during the break: the rest is the repair's
            v.break_seconds += env.now - start
            v.free_at, v.break_since = env.now, None
            return False
        v.break_seconds += env.now - start
        v.break_since = None
        op.fleet.refresh(v)
        op.bus.emit(env.now, "break_end", v.id, -1, v.loc)
        return True


def plan_break(v, due: float, duration: float, now: float, driver
               ) -> tuple[int, Stop, list[float]] | None:
    """Where ``v``'s break of ``duration`` seconds, due since ``due``, goes at ``now``:
    ``(k, stop, times)``, the break to put before the plan's ``k``-th stop and the planned
    arrival times of the plan with it; None where the plan holds a break or the way home.
    ``k`` is the first place where no rider is on board (the load now for ``k = 0``, the
    occupancy after stop ``k - 1``) and every later stop, pushed by the break, keeps its
    latest time, or the end of the plan; ``k = 0`` only where the vehicle drives to its first
    stop (or has none), never before a stop it is making. The break stands where the stop
    before it is, or (first) at the node the vehicle stands on or drives to
    (``driver.node_of``)."""
    stops = v.plan.stops
    if any(s.kind is BREAK or s.kind is DEPOT for s in stops):
        return None
    until = math.inf if v.duty is None else v.duty.until  # (dispatch.fleet.shifts)
    times = v.plan.times(now)
    n = len(stops)
    for k in range(n + 1):
        if k == 0:
            if v.load or (stops and v.heading is not stops[0]):
                continue
            here = v.location(now)
            loc = driver.node_of(here)
            arrive = max(now, v.free_at) + _drive(driver, here, loc)
        else:
            if stops[k - 1].occupancy:
                continue
            s = stops[k - 1]
            loc, arrive = s.loc, leave(times[k - 1], s.earliest, s.service)
        after: list[float] = []
        if k < n:
            nxt = leave(arrive, due, duration) + (
                _drive(driver, loc, stops[0].loc) if k == 0 else stops[k].leg)
            push = nxt - times[k]
            after = pushed(times, stops, k, k, push, push)[k:]
            last = stops[-1]  # (and the plan still ends by its shift's end plus grace)
            if any(t > s.latest + TOL for t, s in zip(after, stops[k:])) or leave(
                    after[-1], last.earliest, last.service) > until + TOL:
                continue
        stop = Stop(BREAK, None, loc, 0, math.inf, False, earliest=due, service=duration,
                    holds_seats=True)
        return k, stop, times[:k] + [arrive] + after
    return None


def _drive(driver, a, b) -> float:
    """Seconds of the drive from ``a`` to ``b`` on the planner's travel times."""
    return 0.0 if a == b else float(driver.planner.between([a], [b])[0, 0])


class Breaks:
    """Plans every vehicle's breaks through the operator
    (:meth:`dispatch.plan.operator.Operator.take_break`): a stretch of ``after`` seconds on duty,
    then a break of ``duration`` seconds; the next stretch starts at its ``break_end`` (or, a
    break cut short by a breakdown, at the ``repair``)."""

    def __init__(self, env: simpy.Environment, bus, operator, vehicles, after: float,
                 duration: float) -> None:
        self.env, self.operator = env, operator
        self.after, self.duration = after, duration
        self.by_id = {v.id: v for v in vehicles}
        #: vehicles whose next break is being waited for (one stretch at a time)
        self._stretch: set[int] = set()
        self.planned = 0  # breaks planned
        for v in vehicles:
            start = v.duty.start if v.duty is not None else env.now
            self._begin(v, max(start, env.now))
        bus.subscribe(self._ended, ["break_end", "repair"])

    def _ended(self, e) -> None:
        v = self.by_id[e.agent_id]
        if e.kind == "break_end" or not any(s.kind is BREAK for s in v.plan):
            self._begin(v, e.t)

    def _begin(self, v, start: float) -> None:
        """A stretch on duty begins at ``start``: its break falls due ``after`` seconds on."""
        if v.id not in self._stretch:
            self._stretch.add(v.id)
            self.env.process(self._due(v, start + self.after))

    def _due(self, v, due: float):
        env = self.env
        if due > env.now:
            yield env.timeout(due - env.now)
        while True:
            if v.duty is not None and env.now >= v.duty.end and v.off_duty:
                break  # its shift is over: no more breaks
            if not (v.failed or v.off_duty) and \
                    self.operator.take_break(v, due, self.duration) is not None:
                self.planned += 1
                break
            yield env.timeout(RETRY)
        self._stretch.discard(v.id)


__all__ = ["BREAK", "Break", "Breaks", "plan_break"]
