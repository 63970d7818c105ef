"""Driver shifts and the fleet's size over the day.

**Input.** A fleet start file (``[fleet] start``) may give each vehicle a shift:
``shift_start`` and ``shift_end`` (seconds, or date-times read as seconds from ``[tasks]
start``, as a trace's ``departure_time``; blank: from the run's start, to its end) and a
``depot`` (a node id, or ``"x,y"`` metres snapped to the nearest node; blank: where the
vehicle starts). ``[fleet] shift_grace`` (seconds, default 0) is how long after its shift's end
a vehicle may still be finishing its plan. :func:`read_shifts` reads them once.

**In the run** (:class:`Shifts`): a vehicle with a depot starts there. Before its shift
starts it is not in the fleet (``Vehicle.off_duty``: neither idle nor busy, no decision sees
it); at its start it enters, idle at its depot. While on duty it takes only requests whose
stops leave its plan's last stop completed by ``shift_end + shift_grace``: a limit of the
decision (:meth:`Shifts.limit`, applied to the cost matrix after the insertion step, from the
schedule rule's times: an empty plan ends at now + drive + service + direct ride + service, a
plan with an insertion at the insertion's drop-off when that is last, else at the plan's
end pushed by the insertion's ``shift2``; a push a stop's wait absorbs is counted in full,
so the limit errs on the safe side). At its shift's end it takes no new request; once its
plan is empty it drives to its depot (a :data:`dispatch.plan.stops.DEPOT` stop) and leaves the
fleet on arrival (a ``shift_end`` event). Arriving after ``shift_end + shift_grace`` is an
overrun: counted per vehicle (``overrun_seconds``) and in the summary (``shift_overruns``).

**Sizing** (``[fleet] sizing``, a :mod:`dispatch.api.sizer` plugin; parameters in
``[fleet.sizing_params]``): ``fixed`` (the default) keeps every vehicle on duty over its
shift; another strategy is asked every ``interval`` seconds how many vehicles it wants on
duty: the idle pool (off duty at their depots, within their shift) joins lowest id first,
idle vehicles leave (drive to their depot, then wait there in the pool) highest id first.

**Output.** The ``vehicles`` table's ``shift_start``, ``shift_end`` (inf: none),
``vehicle_hours`` (on-duty hours: from entering to arriving at the depot, or the run's end)
and ``overrun_seconds``; the summary's ``vehicle_hours``, ``riders_per_vehicle_hour``
(completed requests per vehicle-hour) and ``shift_overruns``. Without shift columns and with
``fixed`` nothing of this runs: every vehicle is on duty from 0 to the run's end.

The shift limit is kept in the cost matrix, and for an allocator that routes several requests
per vehicle itself (``multi_request``, e.g. ``rtv``) in the problem too
(:attr:`dispatch.api.problem.AllocationProblem.until`, from :attr:`Shifts.until`): its routes end
by it, and the dispatcher refuses a route that does not
(:meth:`dispatch.plan.operator.Operator.route_times`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dispatch.errors import ScenarioError
from dispatch.files.tables import CELLS, Table
from dispatch.files.traces import parse_datetime, seconds_between
from dispatch.plan.stops import REPOSITION, TOL, leave

if TYPE_CHECKING:
    from dispatch.api.sizer import Sizer
    from dispatch.plan.vehicles import Fleet, Vehicle

#: metres a depot given as ``x,y`` may lie from the nearest node of the road network
DEPOT_SNAP = 250.0
SHIFT_COLUMNS = ("shift_start", "shift_end", "depot")


@dataclass(frozen=True)
class ShiftTable:
    """The shift columns of a fleet start file, in row order: ``start`` / ``end`` seconds
    (0 / inf where blank), ``depot`` cells as read (None where blank or absent)."""

    path: Path
    start: tuple[float, ...]
    end: tuple[float, ...]
    depot: tuple[Any, ...]

    @property
    def limited(self) -> bool:
        """Some vehicle's shift ends before the run does."""
        return any(e < math.inf for e in self.end)


def _seconds(path: Path, row: int, name: str, v, start: datetime | None) -> float | None:
    """A shift cell as seconds from the run's start (None: blank)."""
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        f = None
    if f is not None:
        if not math.isfinite(f):
            raise ScenarioError(path, f"row {row}", f"{name} {v!r} is not a finite number")
        return f
    if start is None:
        raise ScenarioError(path, f"row {row}", f"{name} {v!r} is a date-time (or not a "
                            "time): set [tasks] start to read it, or give seconds")
    try:
        d = parse_datetime(v)
    except (TypeError, ValueError):
        raise ScenarioError(path, f"row {row}", f"{name} {v!r} is not a number of seconds or "
                            "a date-time (ISO 8601, e.g. 2014-12-21 08:30:00)") from None
    return seconds_between(d, start)


def read_shifts(path: Path, rows: int, start: datetime | None,
                max_bytes: int | None = None) -> ShiftTable | None:
    """The shift columns of the fleet start file ``path`` for its first ``rows`` rows (None
    when it has none of :data:`SHIFT_COLUMNS`). A shift ending at or before its start, or a
    cell that is no time, raises a ScenarioError naming the file, the row and the column."""
    table = Table(path, max_bytes)
    have = [c for c in SHIFT_COLUMNS if c in table.names]
    if not have:
        table.read({})
        return None
    cols = table.read(dict.fromkeys(have, CELLS))
    blank = [None] * cols.n
    s_cells = cols.cells("shift_start") if "shift_start" in have else blank
    e_cells = cols.cells("shift_end") if "shift_end" in have else blank
    d_cells = cols.cells("depot") if "depot" in have else blank
    starts, ends, depots = [], [], []
    for i in range(min(rows, cols.n)):
        s = _seconds(path, i + 1, "shift_start", s_cells[i], start)
        e = _seconds(path, i + 1, "shift_end", e_cells[i], start)
        s = 0.0 if s is None else max(s, 0.0)
        e = math.inf if e is None else e
        if e <= s:
            raise ScenarioError(path, f"row {i + 1}", f"shift_end {e_cells[i]!r} is not after "
                                f"shift_start {s_cells[i] if s_cells[i] else 0!r}: a shift "
                                "must end after it starts")
        d = d_cells[i]
        starts.append(s)
        ends.append(e)
        depots.append(None if d is None or (isinstance(d, str) and not d.strip()) else d)
    return ShiftTable(path, tuple(starts), tuple(ends), tuple(depots))


def depot_location(space, path: Path, row: int, cell):
    """The location of a ``depot`` cell on ``space`` (a road network): a node id, or ``x,y``
    metres within :data:`DEPOT_SNAP` of a node; ScenarioError naming the file, row and
    column otherwise."""
    net = space
    if "depots" not in space.features:  # (the voxel world has no nodes to name)
        raise ScenarioError(path, f"row {row}", "depot is only read on a road network "
                                                "([world] network)")
    text = str(cell).strip()
    if "," in text:
        try:
            x, y = (float(p) for p in text.split(","))
        except ValueError:
            raise ScenarioError(path, f"row {row}", f"depot {text!r} is neither a node id nor "
                                                    "\"x,y\" metres") from None
        idx, dist = net.nearest(np.array([[x, y]]))
        if not dist[0] <= DEPOT_SNAP:
            raise ScenarioError(path, f"row {row}", f"depot {text!r} is off the network: "
                                f"{dist[0]:.0f} m from the nearest node (at most "
                                f"{DEPOT_SNAP:.0f} m)")
        return int(idx[0])
    try:
        return net.index_of(text)
    except ValueError as e:
        raise ScenarioError(path, f"row {row}", f"depot {text!r} is off the network: {e}") \
            from None


class Duty:
    """One vehicle's shift and its time on duty."""

    __slots__ = ("start", "end", "until", "depot", "on", "home", "ended", "since", "seconds",
                 "overrun")

    def __init__(self, start: float, end: float, grace: float, depot) -> None:
        self.start, self.end, self.depot = start, end, depot
        #: the latest completion of its plan's last stop (-inf once its shift has ended)
        self.until = end + grace
        self.on = False  # on duty (in the fleet)
        self.home = False  # driving to its depot to leave
        self.ended = False  # its shift is over
        self.since = 0.0
        self.seconds = 0.0
        self.overrun = 0.0

    def hours(self, now: float) -> float:
        return (self.seconds + (now - self.since if self.on else 0.0)) / 3600.0


def duty_columns(v: Vehicle, now: float) -> tuple[float, float, float, float]:
    """The ``vehicles`` table's ``shift_start``, ``shift_end``, ``vehicle_hours``,
    ``overrun_seconds`` of ``v`` at the run's end ``now``."""
    d = v.duty
    if d is None:
        return 0.0, math.inf, now / 3600.0, 0.0
    return d.start, d.end, d.hours(now), d.overrun


def fleet_summary(vehicles, now: float, completed: int) -> dict:
    """The summary's ``vehicle_hours``, ``riders_per_vehicle_hour``, ``shift_overruns``."""
    hours = sum(duty_columns(v, now)[2] for v in vehicles)
    overruns = sum(1 for v in vehicles if v.duty is not None and v.duty.overrun > 0)
    return {"vehicle_hours": hours,
            "riders_per_vehicle_hour": completed / hours if hours > 0 else math.nan,
            "shift_overruns": overruns}


class Shifts:
    """The run's shifts and sizing (see the module): who is on duty, the decision's shift
    limit, the drives home."""

    def __init__(self, env, bus, fleet: Fleet, operator, space, cfg, *, notify,
                 sizer: Sizer | None, rng: np.random.Generator) -> None:
        self.env, self.bus, self.fleet, self.operator = env, bus, fleet, operator
        self.notify, self.sizer, self.rng = notify, sizer, rng
        table: ShiftTable | None = cfg.shifts
        n = len(fleet)
        #: per fleet position: the latest completion of a plan's last stop
        self.until = np.full(n, math.inf)
        self.limited = False
        grace = cfg.shift_grace
        rows = {r[0]: k for k, r in enumerate(cfg.start)}  # vehicle id -> its start file row
        for k, v in enumerate(fleet.vehicles):
            start, end, depot = 0.0, math.inf, None
            row = rows.get(v.id, -1)
            if table is not None and 0 <= row < len(table.start):
                start, end = table.start[row], table.end[row]
                if table.depot[row] is not None:
                    depot = depot_location(space, table.path, row + 1, table.depot[row])
            if depot is None:
                depot = v.loc
            elif v.loc != depot:
                v.start = v.loc = depot  # it enters at its depot (and starts there)
            v.duty = Duty(start, end, grace, depot)
            self.until[k] = v.duty.until
            self.limited = self.limited or end < math.inf
        passive = sizer is None or sizer.passive
        starting = [v for v in fleet.vehicles if v.duty.start <= 0.0]
        if not passive:
            want = sizer.initial(self._view(0, len(starting)))
            starting = starting[:max(0, int(want))]
        for v in fleet.vehicles:
            if v in starting:
                v.duty.on = True
            else:
                v.off_duty = True
                fleet.refresh(v)
        self._slot_until()
        bus.subscribe(self._idle, ("idle",))
        env.process(self._calendar(passive))
        if not passive:
            self._busy_mark, self._duty_mark = self._totals()
            self._released = self._unserved = 0
            bus.subscribe(self._count, ("release", "reject", "expire"))
            env.process(self._sizing())

    # ------------------------------------------------------------------ the decision's limit
    def _slot_until(self) -> None:
        for k, v in enumerate(self.fleet.vehicles):
            d = v.duty
            self.until[k] = -math.inf if (d.ended or not d.on or d.home) else d.until

    def limit(self, cost: np.ndarray, drive: np.ndarray, now: float, slots: np.ndarray,
              tasks: list, inserts, *, plans: bool, ride: np.ndarray | None = None,
              holders: frozenset = frozenset()) -> np.ndarray:
        """``cost`` with ``inf`` where vehicle ``slots[i]`` would complete its plan's last
        stop after its shift's end plus the grace with request ``j`` (see the module);
        ``drive``: the seconds from each vehicle to each pickup; ``inserts``: where a busy
        vehicle's stops go (:class:`dispatch.decide.plan_costs.Inserts`); ``ride``: each
        request's drive to its drop-off at this hour (congestion; None: its free-flow
        ``direct_time``); ``holders``: ids of vehicles driving to a pickup they may give up
        (``[dispatch] reassign``), whose plans count as empty, as the decision's costs take
        them (else each of two vehicles was ruled out of a task while it held it: a hand-back
        loop at one instant)."""
        lim = self.until[slots]
        if not (lim < math.inf).any() or not cost.size:
            return cost
        svc = self.operator.service_time
        point = np.array([t.dropoff is None for t in tasks])
        pd = np.array([0.0 if t.dropoff is None or t.direct_time != t.direct_time
                       else t.direct_time for t in tasks])
        if ride is not None:
            pd = np.where(point, 0.0, ride)
        svc_p = np.where(point, svc, 0.0)
        svc_d = np.where(point, 0.0, svc)
        # a booked pickup waits for its requested departure (dispatch.decide.prebook)
        ep = np.array([t.earliest_pickup for t in tasks])
        end = np.maximum(now + drive, ep[None, :]) + (svc_p + pd + svc_d)[None, :]
        if plans:
            fleet, vs = self.fleet, self.fleet.vehicles
            planned = fleet.busy_mask[slots]
            if holders:
                planned = planned & ~np.isin(fleet.ids[slots], list(holders))
            rows_busy = np.flatnonzero(planned)
            if rows_busy.size:
                end[rows_busy] = math.inf  # busy: only its feasible insertions
            if inserts:  # busy vehicles' pairs (with meeting points idle ones' too: the
                # rider's walk may hold the pickup back)
                rows, cols, ins = inserts.pairs()
                last = np.zeros(len(slots))
                n_stops = np.zeros(len(slots), np.int64)
                for r in np.unique(rows).tolist():
                    if not planned[r]:  # its pairs were costed into an empty plan (idle, a
                        # holder, or a repositioning drive the pickup replaces): end there
                        continue
                    v = vs[int(slots[r])]
                    times, svcs, _, _, _, earliest = v.plan.arrays(now)
                    n_stops[r] = len(times)
                    last[r] = leave(times[-1], earliest[-1], svcs[-1]) if times else \
                        max(v.free_at, now)
                at_end = ins.j == n_stops[rows]
                done = np.where(at_end, ins.dropoff_at + svc_d[cols],
                                last[rows] + ins.shift2)
                end[rows, cols] = done
        ok = end <= lim[:, None] + TOL
        return np.where(ok, cost, np.inf)

    # ------------------------------------------------------------------ entering, leaving
    def _calendar(self, passive: bool):
        """Process: each vehicle enters at its shift's start (with ``fixed`` sizing; another
        strategy brings pool vehicles in itself) and ends its shift at its end."""
        env = self.env
        moments = sorted([(v.duty.start, 0, v.id) for v in self.fleet.vehicles
                          if v.duty.start > 0.0 and passive]
                         + [(v.duty.end, 1, v.id) for v in self.fleet.vehicles
                            if v.duty.end < math.inf])
        by_id = self.fleet.by_id
        for t, what, vid in moments:
            if t > env.now:
                yield env.timeout(t - env.now)
            v = by_id[vid]
            if what == 0:
                self._enter(v)
            else:
                self._end_shift(v)

    def _enter(self, v: Vehicle) -> None:
        d = v.duty
        if d.on or d.ended:
            return
        d.on, d.since = True, self.env.now
        v.off_duty = False
        self.fleet.refresh(v)
        self.until[v._slot] = d.until
        self.bus.emit(self.env.now, "shift_start", v.id, -1, v.loc)
        self.bus.emit(self.env.now, "idle", v.id, -1, v.loc)
        self.notify()

    def _end_shift(self, v: Vehicle) -> None:
        d = v.duty
        d.ended = True
        self.until[v._slot] = -math.inf
        if d.on and not d.home and self._free(v):
            self._go_home(v)

    def _free(self, v: Vehicle) -> bool:
        """``v`` has nothing left to do (its plan empty, or a repositioning move) and is not
        on a break (a break's stop leaves the plan when it starts: the drive home waits for
        its end, whose ``idle`` event sends it)."""
        return not v.failed and v.serving is None and v.break_since is None and (
            not v.plan or (len(v.plan) == 1 and v.plan[0].kind is REPOSITION))

    def _idle(self, ev) -> None:
        """Bus subscriber: a vehicle whose shift is over (or that the sizing sends home) and
        whose plan just emptied drives home; one that reached its depot leaves."""
        v = self.fleet.by_id[ev.agent_id]
        d = v.duty
        if not d.on:
            return
        if d.home:
            if not v.plan and v.loc == d.depot:
                self._leave(v)
            elif self._free(v) and not v.plan:  # (repaired on its way home: drive on)
                self.operator.to_depot(v, d.depot)
        elif d.ended and self._free(v):
            self._go_home(v)

    def _go_home(self, v: Vehicle) -> None:
        d = v.duty
        d.home = True
        self.until[v._slot] = -math.inf
        v.off_duty = True
        if v.loc == d.depot and v.leg is None and not v.plan:
            self.fleet.refresh(v)
            self._leave(v)
            return
        self.operator.to_depot(v, d.depot)
        self.fleet.refresh(v)

    def _leave(self, v: Vehicle) -> None:
        d, now = v.duty, self.env.now
        d.on, d.home = False, False
        d.seconds += now - d.since
        if d.ended and now > d.until + TOL:
            d.overrun = max(d.overrun, now - d.until)
        v.off_duty = True
        self.fleet.refresh(v)
        self.bus.emit(now, "shift_end", v.id, -1, v.loc)

    # ------------------------------------------------------------------ sizing
    def _totals(self) -> tuple[float, float]:
        """Busy and on-duty vehicle-seconds so far."""
        now, busy, duty = self.env.now, 0.0, 0.0
        for v in self.fleet.vehicles:
            busy += v.busy_seconds + (now - v.busy_since if v.busy else 0.0)
            duty += v.duty.seconds + (now - v.duty.since if v.duty.on else 0.0)
        return busy, duty

    def _pool(self) -> list:
        now = self.env.now
        return [v for v in self.fleet.vehicles if not v.duty.on and not v.duty.ended
                and v.duty.start <= now < v.duty.end and not v.failed]

    def _view(self, on: int, pool: int, utilization: float = math.nan,
              unserved: float = math.nan):
        from dispatch.api.sizer import SizingView

        busy = int(self.fleet.busy_mask.sum()) if on else 0
        return SizingView(float(self.env.now), on, busy, pool, utilization, self.rng, unserved)

    def _count(self, ev) -> None:
        """Bus subscriber: requests released and left unserved since the last look."""
        if ev.kind == "release":
            self._released += 1
        else:
            self._unserved += 1

    def _sizing(self):
        """Process: every ``interval`` s, the strategy's fleet size, by joins and leaves."""
        env, sizer = self.env, self.sizer
        while True:
            yield env.timeout(sizer.interval)
            busy, duty = self._totals()
            du = duty - self._duty_mark
            u = (busy - self._busy_mark) / du if du > 0 else math.nan
            self._busy_mark, self._duty_mark = busy, duty
            unserved = self._unserved / self._released if self._released else math.nan
            self._released = self._unserved = 0
            on = [v for v in self.fleet.vehicles if v.duty.on and not v.duty.home]
            pool = self._pool()
            want = int(sizer.size(self._view(len(on), len(pool), u, unserved)))
            if want > len(on):
                for v in pool[:want - len(on)]:
                    self._enter(v)
            elif want < len(on):
                idle = [v for v in reversed(on) if self._free(v)]
                for v in idle[:len(on) - want]:
                    self._go_home(v)

