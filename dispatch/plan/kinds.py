"""The stop kinds: one declaration and one handler each, found in :data:`TABLE` by a stop's
``kind`` (the operator drives every stop through it: :meth:`dispatch.plan.operator.Operator.
drive`). A new kind is a subclass of :class:`dispatch.plan.stops.StopKind` (in a module of its
own, as :mod:`dispatch.plan.breaks`) and one entry here; a kind without a handler is refused
when its class is defined, and the table refuses two handlers of one kind.
"""

from __future__ import annotations

import simpy

from dispatch.plan.breaks import Break
from dispatch.plan.stops import CHARGE, DEPOT, DROPOFF, PICKUP, REPOSITION, Stop, StopKind
from dispatch.plan.tasks import COMPLETED, PICKED_UP


class _Request(StopKind):
    """A request's stop: the vehicle is busy while its plan holds one."""

    name = "_request"
    idle = False

    def arrive(self, op, v, stop: Stop):
        v.plan.done()
        self.board(op, v, stop)
        v.plan.changed()
        if not stop.completes:
            return True
        task, env = stop.task, op.env
        if op.service_time > 0:
            v.serving = task
            v.free_at = env.now + op.service_time
            try:
                yield env.timeout(op.service_time)
            except simpy.Interrupt:  # a breakdown in service: breakdown() did the rest
                return False
            v.serving = None
        v.completed += 1
        if v.plan:
            op.book.close(task, COMPLETED)
            return True
        v.proc = None
        op.go_idle(v, task)
        return False

    def board(self, op, v, stop: Stop) -> None:
        """What the stop changes on board (before the service, if it completes the request)."""
        raise NotImplementedError


class Pickup(_Request):
    """Pick a request's riders up (a point task of the voxel world: the pickup completes it).
    Riders boarding where others ride make a shared ride, theirs and those on board."""

    name = PICKUP

    def board(self, op, v, stop: Stop) -> None:
        task = stop.task
        if v.load and stop.passengers:
            task.shared = True
            for s in v.plan:
                if s.kind is DROPOFF and s.task.state is PICKED_UP:
                    s.task.shared = True
        v.load += stop.passengers
        op.book.picked_up(task, at=v.loc)


class Dropoff(_Request):
    """Drop a request's riders off: a ``dropoff`` event; the request completes here."""

    name = DROPOFF

    def board(self, op, v, stop: Stop) -> None:
        task, now = stop.task, op.env.now
        v.load += stop.passengers
        task.dropped_at = now
        op.bus.emit(now, "dropoff", v.id, task.id, v.loc)


class Charge(StopKind):
    """A charging visit (:class:`dispatch.fleet.chargers.Visit`): queue for a plug, charge,
    leave. Neither idle nor busy while it is planned; no drive where the vehicle stands at the
    station already."""

    name = CHARGE
    idle = False

    def there(self, v, stop: Stop, now: float) -> bool:
        return v.location(now) == stop.loc

    def arrive(self, op, v, stop: Stop):
        stop.visit.reached()
        try:
            yield from stop.visit.serve(v)
        except simpy.Interrupt:  # a breakdown at the station: the visit is closed
            return False
        v.plan.done()
        v.plan.changed()
        return True

    def dropped(self, op, v, stop: Stop) -> None:
        stop.visit.reached()  # no longer coming


class Reposition(StopKind):
    """A repositioning move: driven idle (a decision that gives the vehicle a request cuts
    it); its metres count once the move ends."""

    name = REPOSITION
    kept = False
    checks_battery = False

    def arrive(self, op, v, stop: Stop):
        yield from ()  # (nothing to wait for)
        v.plan.done()
        op.move_ended(v, stop)
        v.plan.changed()
        return True

    def dropped(self, op, v, stop: Stop) -> None:
        op.move_ended(v, stop)


class Depot(Reposition):
    """The way home at a shift's end (:mod:`dispatch.fleet.shifts`): driven idle; a decision
    keeps it."""

    name = DEPOT
    kept = True
    checks_battery = True

    def dropped(self, op, v, stop: Stop) -> None:
        """Nothing counts: the way home is no repositioning move."""


def table(*kinds: StopKind) -> dict[str, StopKind]:
    """``{name: kind}`` of ``kinds``; a name handled twice is refused."""
    out: dict[str, StopKind] = {}
    for k in kinds:
        if k.name in out:
            raise TypeError(f"stop kind {k.name!r} has two handlers: "
                            f"{type(out[k.name]).__name__} and {type(k).__name__}")
        out[k.name] = k
    return out


#: every stop kind's declaration and handler, by name
TABLE = table(Pickup(), Dropoff(), Charge(), Reposition(), Depot(), Break())
