"""The run's event stream: everything that happens, published once, read by subscribers.

Processes (the task source, the dispatcher, the vehicles) *emit*; the recorder's ``events``
table, the PyBullet mirror and anything a user adds *subscribe*. No process reaches back into
a central object to report what it did.

Event types (``Event.kind``), with the agent and task they name (-1: none):

=============  ===========================================================================
release        a task (trip) is released (task; at its pickup)
assign         the dispatcher hands a task to a vehicle (agent, task; at the pickup)
depart         a vehicle starts a leg: to a pickup, or with its passenger to the drop-off
               (or, task -1, toward a repositioning target)
move           a vehicle enters a cell (voxel world; one per cell) or, with
               ``[output] edge_events``, reaches a node on the way (roads)
pickup         a vehicle reaches a task's pickup (for the paper's point tasks: the task)
dropoff        a vehicle reaches a trip's drop-off
complete       a task is done (after the service time at its pickup or drop-off)
idle           a vehicle has no task any more
wait / replan  reservation-based execution: a vehicle stands, or its route was replaced
expire         an open task's ``ttl`` or ``max_wait`` ran out
reject         no vehicle could reach a request's pickup within its ``max_wait``
unreachable    no vehicle of the fleet can ever reach the task
cut_off        the run ended before the task did (still waiting or aboard)
skipped        a generated release was skipped because ``max_active`` tasks were open
breakdown      a vehicle fails where it is (its task, if any; ``[faults]``)
repair         a failed vehicle works again (then ``idle``)
reopen         a task goes back to open because its vehicle broke down (at its pickup:
               for a passenger on board, where the transfer will pick them up)
reassign       ``[dispatch] reassign``: a vehicle driving to a pickup gives its task up
               because a decision gave it another task or none (agent, the task given up;
               at the vehicle); the task is open again, and the ``assign`` events of the
               same decision follow (the vehicle's new task, the task's new vehicle)
reposition     an idle vehicle is sent toward a node by the repositioner (agent; at the
               target node), followed by a ``depart`` with task -1 where it starts and, on
               arrival, an ``idle`` there; it stays idle (dispatchable) all the way
insert         shared rides: a decision inserted a request's stops into a busy vehicle's
               plan (agent, the request; at the vehicle), after the request's ``assign``
queue          ``[fleet.energy]``: a vehicle reached a station whose plugs are all taken
               (agent; at the station)
charge_start   a vehicle is plugged in (agent; at the station); ``charge_end`` when it
charge_end     leaves the plug (at its target, or cut by a breakdown)
stranded       a vehicle's battery ran empty on a leg (agent; where it stopped); a
               ``breakdown`` follows, and after ``[faults] tow`` s a ``repair`` at the
               nearest station
shift_start    a vehicle enters the fleet at its depot (its shift starts, or the sizing
               brings it in; :mod:`dispatch.fleet.shifts`)
shift_end      a vehicle leaves the fleet on reaching its depot (its shift is over, or the
               sizing sent it home)
break_start    ``[fleet.breaks]``: a vehicle's driver starts a break (agent; where it
break_end      stands); ``break_end`` when it is over (:mod:`dispatch.plan.breaks`)
=============  ===========================================================================
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple

from dispatch.locations import Location

KINDS = ("release", "assign", "depart", "move", "pickup", "dropoff", "complete", "idle", "wait",
         "replan", "expire", "reject", "unreachable", "cut_off", "failed", "skipped",
         "breakdown", "repair", "reopen", "reassign", "reposition", "insert",
         "queue", "charge_start", "charge_end", "stranded", "decline", "shift_start",
         "shift_end", "break_start", "break_end")


class Event(NamedTuple):
    """One thing that happened at simulated time ``t`` (``loc`` where, or None); immutable.
    A named tuple: several are made per trip, and it is made twice as fast as a frozen
    dataclass."""

    t: float
    kind: str
    agent_id: int = -1
    task_id: int = -1
    loc: Location | None = None


Subscriber = Callable[[Event], None]
_new = tuple.__new__


class EventBus:
    """Delivers each emitted event to the subscribers of its kind, in subscription order."""

    def __init__(self) -> None:
        self._all: list[Subscriber] = []
        self._by_kind: dict[str, list[Subscriber]] = {k: [] for k in KINDS}

    def subscribe(self, fn: Subscriber, kinds: Iterable[str] | None = None) -> None:
        """Call ``fn(event)`` for every event (or only those of ``kinds``)."""
        if kinds is None:
            self._all.append(fn)
            for subs in self._by_kind.values():
                subs.append(fn)
            return
        for k in kinds:
            if k not in self._by_kind:
                raise ValueError(f"unknown event kind {k!r}; known: {', '.join(KINDS)}")
            self._by_kind[k].append(fn)

    def emit(self, t: float, kind: str, agent_id: int = -1, task_id: int = -1,
             loc: Location | None = None) -> None:
        subs = self._by_kind[kind]
        if subs:
            # tuple.__new__: Event(...) would run the named tuple's Python-level __new__
            ev = _new(Event, (float(t), kind, agent_id, task_id, loc))
            for fn in subs:
                fn(ev)
