"""The run's subscribers that write its rows: events, tasks, decisions and vehicles.

Each table's row is a plain function returning one tuple in the schema's order (the
recorder's fast path), beside the tuple of the columns it fills; each writer checks that tuple
against :data:`dispatch.output.parquet.SCHEMAS` when the run starts (:func:`check_columns`), so a
column added to a schema without a value fails then (a ``KeyError`` naming it), never as values
shifted into the wrong columns.

* :func:`event_writer`: subscribes to the event bus (every event a row of ``events``; where it
  happened is looked up per chunk, for the whole chunk at once);
* :class:`TaskWriter`: subscribes to the task book's closures (one ``tasks`` row per task, as
  it reaches its terminal state);
* :class:`DecisionWriter`: the dispatcher's ``on_decision`` (``decisions`` and
  ``assignments`` rows);
* :func:`write_vehicles`: the ``vehicles`` rows at the end of the run;
* :class:`RunRecording`: one run's wiring of them: the run's metadata and the space's static
  tables, the writers, the summary statistics (:class:`dispatch.output.stats.RunStats`) and the
  end-of-run tables.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from dispatch.decide.meeting import walk_m
from dispatch.fleet.shifts import duty_columns
from dispatch.output import space_files
from dispatch.output.legs import OPTIONAL_SCHEMAS, schema_of
from dispatch.output.parquet import REQUEST_ID, SCHEMAS
from dispatch.output.stats import RunStats

NAN3 = (math.nan, math.nan, math.nan)


def check_columns(table: str, columns: tuple[str, ...]) -> None:
    """KeyError naming the difference unless ``columns`` are ``table``'s columns but ``run_id``,
    in the schema's order: what a row function says it returns (a column added to a schema
    without a value fails when the run starts, never as values shifted into other columns)."""
    names = tuple(n for n in schema_of(table).names if n != "run_id")
    if columns != names:
        missing = [n for n in names if n not in columns]
        extra = [n for n in columns if n not in names]
        raise KeyError(f"{table}: no value for column(s) {missing}; unknown {extra}"
                       + ("" if missing or extra else f"; schema order {list(names)}"))


#: the columns :func:`task_row` returns, in order
TASK_COLUMNS = (
    "task_id", "request_id", "kind", "x", "y", "z", "dropoff_x", "dropoff_y", "dropoff_z",
    "released_at", "max_wait", "snap_m", "dropoff_snap_m", "assigned_at", "agent_id", "cost",
    "picked_up_at", "completed_at", "state", "conflicted", "closed_at", "reassigned", "transfers",
    "passengers", "direct_time", "max_delay", "shared", "booked_at", "promised", "offers", "fare",
    "board_x", "board_y", "alight_x", "alight_y", "walk_to_board_m", "walk_from_alight_m")


def task_row(t, p, d, b=NAN3, a=NAN3, walk=NAN3[:2]) -> tuple:
    """The ``tasks`` row of the task ``t`` with the positions of its pickup ``p`` and drop-off
    ``d``, of where its rider boarded ``b`` and alighted ``a`` and the metres ``walk`` to the
    one and from the other (:data:`TASK_COLUMNS`)."""
    return (t.id, t.request_id, t.kind, p[0], p[1], p[2], d[0], d[1], d[2], t.released_at,
            t.max_wait, t.snap_m, t.dropoff_snap_m, t.assigned_at, t.agent_id, t.cost,
            t.picked_up_at, t.completed_at, t.state._value_, t.conflicted, t.closed_at,
            t.reassigned, t.transfers, t.passengers, t.direct_time, t.max_delay, t.shared,
            t.booked_at, t.promised, t.offers, t.fare, b[0], b[1], a[0], a[1], *walk)


#: the columns :func:`decision_row` returns, in order
DECISION_COLUMNS = (
    "decision", "t", "n_idle", "n_tasks", "n_assigned", "rounds", "messages", "conflicts",
    "total_cost", "cost_seconds", "decide_seconds", "hops", "comm_delay", "agent_seconds",
    "comm_components", "n_cut")


def decision_row(i: int, p, a, *, total: float, cost_s: float, decide_s: float, hops: int,
                 comm_delay: float, agent_seconds: float, components: int, cut: int) -> tuple:
    """The ``decisions`` row of decision ``i``: its problem ``p``, allocation ``a`` and figures
    (:data:`DECISION_COLUMNS`)."""
    return (i, float(p.time), p.n_agents, p.n_tasks, len(a.pairs), a.rounds, a.messages,
            len(a.conflicted_tasks()), total, cost_s, decide_s, hops, comm_delay,
            agent_seconds, components, cut)


#: the columns :func:`assignment_row` returns, in order
ASSIGNMENT_COLUMNS = ("decision", "round", "agent_id", "task_id", "request_id", "cost", "won",
                      "alloc_seconds")


def assignment_row(i: int, r, alloc_s: float, request_id) -> tuple:
    """The ``assignments`` row of the bid ``r`` (:class:`dispatch.api.problem.Bid`) of decision
    ``i``, for the request ``request_id`` (:data:`ASSIGNMENT_COLUMNS`)."""
    return (i, r.round, r.agent_id, r.task_id, request_id, r.cost, r.won, alloc_s)


def request_id_array(tasks, ids, typ: pa.DataType) -> pa.Array:
    """The ``request_id`` column of rows about the tasks ``tasks`` (task ids; -1: about no
    task, a null): ``ids[t]``, the request id of task ``t`` (an int or str, as ``typ``;
    ``ids``: :class:`dispatch.plan.tasks.RequestIds`)."""
    k, ids = len(tasks), ids.values
    valid = np.fromiter((t >= 0 for t in tasks), np.bool_, k)
    nulls = k - int(valid.sum())
    bitmap = None if not nulls else pa.py_buffer(np.packbits(valid, bitorder="little"))
    if typ == pa.string():
        data = [ids[t].encode() if t >= 0 else b"" for t in tasks]
        offsets = np.zeros(k + 1, dtype=np.int64)
        np.cumsum(np.fromiter(map(len, data), np.int64, k), out=offsets[1:])
        if offsets[-1] >= 2**31:
            return pa.array([ids[t] if t >= 0 else None for t in tasks], typ)
        return pa.StringArray.from_buffers(k, pa.py_buffer(offsets.astype(np.int32)),
                                           pa.py_buffer(b"".join(data)), bitmap, nulls)
    values = np.fromiter((ids[t] if t >= 0 else 0 for t in tasks), np.int64, k)
    return pa.Array.from_buffers(typ, k, [bitmap, pa.py_buffer(values)], nulls)


#: the columns :func:`vehicle_row` returns, in order
VEHICLE_COLUMNS = (
    "agent_id", "kind", "speed", "x0", "y0", "z0", "distance", "empty_distance",
    "occupied_distance", "busy_seconds", "tasks_completed", "waits", "replans", "wait_seconds",
    "failures", "down_seconds", "capacity", "passenger_distance", "kwh_drawn", "kwh_charged",
    "charge_seconds", "queue_seconds", "soc_min", "soc_end", "shift_start", "shift_end",
    "vehicle_hours", "overrun_seconds", "break_seconds")


def vehicle_row(v, p, down: float, c, b,
                duty: tuple = (0.0, math.inf, math.nan, 0.0)) -> tuple:
    """The ``vehicles`` row of the vehicle ``v``: its start position ``p``, the seconds it was
    down ``down``, the counts of reservation-based execution ``c``, its battery ``b`` (None:
    no energy model; its columns NaN) and its shift's columns ``duty``
    (:func:`dispatch.fleet.shifts.duty_columns`) (:data:`VEHICLE_COLUMNS`)."""
    if b is None:
        energy = (math.nan,) * 6
    else:
        energy = (b.drawn, b.charged, b.charge_seconds, b.queue_seconds,
                  b.kwh_min / b.capacity, b.soc)
    return (v.id, v.kind, v.speed, p[0], p[1], p[2], v.distance, v.empty_distance,
            v.occupied_distance, v.busy_seconds, v.completed, c["waits"], c["replans"],
            c["wait_seconds"], v.failures, down, v.capacity, v.passenger_distance, *energy,
            *duty, v.break_seconds)


def id_type(recorder) -> pa.DataType:
    """The type of ``recorder``'s ``request_id`` columns (a recorder of no files: int64)."""
    return getattr(recorder, "types", {}).get(REQUEST_ID, SCHEMAS["tasks"].field(REQUEST_ID).type)


class TaskWriter:
    """Subscriber of the task book's closures: the task's ``tasks`` row."""

    def __init__(self, recorder, space) -> None:
        check_columns("tasks", TASK_COLUMNS)
        self.append, self.position = recorder.append, space.position

    def __call__(self, t) -> None:
        p = self.position(t.loc if t.origin is None else t.origin)
        d = NAN3 if t.dropoff is None else self.position(t.dropoff)
        m = t.meeting
        if m is not None and t.agent_id >= 0:  # meeting points (dispatch.decide.meeting)
            b, a = self.position(m.board), self.position(m.alight)
        elif t.agent_id >= 0:  # door to door
            b, a = p, d
        else:
            b = a = NAN3
        self.append("tasks", task_row(t, p, d, b, a, walk_m(t)))


class DecisionWriter:
    """The dispatcher's ``on_decision``: a ``decisions`` row and one ``assignments`` row per
    bid of the decision's rounds."""

    def __init__(self, recorder, request_ids) -> None:
        check_columns("decisions", DECISION_COLUMNS)
        check_columns("assignments", ASSIGNMENT_COLUMNS)
        self.append, self.request_ids = recorder.append, request_ids

    def __call__(self, index: int, problem, allocation, total: float, cost_s: float,
                 decide_s: float, *, hops: int = 0, comm_delay: float = 0.0,
                 agent_seconds: float = math.nan, components: int = 1, cut: int = 0) -> None:
        append, alloc_s, ids = self.append, cost_s + decide_s, self.request_ids
        for r in allocation.requests:
            append("assignments", assignment_row(index, r, alloc_s, ids[r.task_id]))
        append("decisions", decision_row(index, problem, allocation, total=total,
                                         cost_s=cost_s, decide_s=decide_s, hops=hops,
                                         comm_delay=comm_delay, agent_seconds=agent_seconds,
                                         components=components, cut=cut))


def write_vehicles(recorder, space, vehicles, now: float, counts) -> None:
    """The ``vehicles`` rows at the end of a run (``counts(v)``: its waits, replans and
    wait_seconds)."""
    check_columns("vehicles", VEHICLE_COLUMNS)
    for v in vehicles:
        down = v.down_seconds + (now - v.down_since if v.failed else 0.0)
        recorder.append("vehicles", vehicle_row(v, space.position(v.start), down, counts(v),
                                                v.battery, duty_columns(v, now)))


def event_writer(recorder, space, request_ids):
    """The subscriber that writes each event as a row of the ``events`` table (several per
    trip): it keeps the event itself; its position and its task's request id
    (``request_ids[task_id]``) are looked up when the chunk is written, for the whole chunk at
    once (on roads, a gather from the nodes' positions)."""
    position, typ = space.position, id_type(recorder)
    nodes = space.node_positions
    n = len(nodes) if nodes is not None else 0
    xyz = np.array(nodes, dtype=np.float64).reshape(-1, 3) if nodes is not None else None

    def columns(events: list) -> dict:
        k = len(events)
        t, kind, agent, task, locs = zip(*events) if k else ((),) * 5
        types = set(map(type, locs))
        idx = None
        if xyz is not None and k and types <= {int, type(None)}:
            idx = np.fromiter(locs if type(None) not in types else
                              [-1 if loc is None else loc for loc in locs], np.int64, k)
            none = np.array([loc is None for loc in locs]) if type(None) in types else None
            bad = (idx < 0) if none is None else ((idx < 0) & ~none)
            if bad.any() or idx.max() >= n:  # not plain nodes: placed one by one below
                idx = None
        if idx is not None:  # nodes (and None): the same floats as space.position gives
            pos = xyz[np.maximum(idx, 0)]
            if none is not None:
                pos[none] = np.nan
            x, y, z = pos[:, 0].copy(), pos[:, 1].copy(), pos[:, 2].copy()
        else:
            x, y, z = zip(*(NAN3 if loc is None else
                            nodes[loc] if type(loc) is int and 0 <= loc < n else
                            position(loc) for loc in locs)) if k else ((), (), ())
        return {"t": t, "event": kind, "agent_id": agent, "task_id": task,
                "request_id": request_id_array(task, request_ids, typ), "x": x, "y": y, "z": z}

    return recorder.appender("events", columns)


class RunRecording:
    """What one run records into ``recorder`` (its ``out``: the results folder, None for a
    recorder that keeps none): made when the run is built (the space's metadata and its
    static tables' metadata are set at once), :meth:`attach`-ed to the event bus, and finished
    by :meth:`end_tables`, :meth:`chargers` and :meth:`summary`.

    ``stats`` (:class:`dispatch.output.stats.RunStats`) counts the closed tasks; ``on_close`` are
    the task book's closure subscribers (the statistics, then the ``tasks`` row);
    ``decision`` is the dispatcher's ``on_decision``. ``request_ids``: the task book's request
    id of every task, by task id (:attr:`dispatch.plan.tasks.TaskBook.request_ids`), which the
    events and assignments rows carry."""

    def __init__(self, recorder, space, request_ids) -> None:
        self.recorder, self.space, self.request_ids = recorder, space, request_ids
        self.stats = RunStats()
        recorder.metadata.update(space.describe())
        # the space's shared tables (a road network), once per results folder
        recorder.metadata.update(space_files.store(recorder.out, space))
        self.static = space.tables()
        for name, (meta, _rows) in self.static.items():
            recorder.table_metadata[name] = meta
        self.event = None
        self.task = TaskWriter(recorder, space)
        self.decision = DecisionWriter(recorder, request_ids)
        self.on_close = [self.stats.closed, self.task]

    def attach(self, bus) -> None:
        """Write every event of ``bus`` as a row of ``events``."""
        self.event = event_writer(self.recorder, self.space, self.request_ids)
        bus.subscribe(self.event)

    def end_tables(self, vehicles, now: float, counts) -> None:
        """The ``vehicles`` rows (see :func:`write_vehicles`) and the space's static rows."""
        write_vehicles(self.recorder, self.space, vehicles, now, counts)
        for name, (_meta, rows) in self.static.items():
            for row in rows:
                self.recorder.add(name, **row)

    def legs(self, columns: tuple[str, ...], summary_names: tuple[str, ...],
             counts: tuple[str, ...]):
        """``[transit]``: the ``legs`` table written too (its rows' ``columns``:
        :data:`dispatch.decide.rider_legs.LEG_COLUMNS`), and the summary widened by the
        riders' columns ``summary_names`` (int64 those in ``counts``, float64 the others);
        returns what appends one leg's row."""
        check_columns("legs", columns)
        rec = self.recorder
        if hasattr(rec, "add_table"):  # (a recorder that keeps no files has no tables)
            rec.add_table("legs", OPTIONAL_SCHEMAS["legs"])
            summary = rec.schemas["summary"]  # (widened before its one row)
            for n in summary_names:
                summary = summary.append(pa.field(n, pa.int64() if n in counts else pa.float64()))
            rec.add_table("summary", summary)
        return rec.appender("legs")

    def chargers(self, rows) -> None:
        """The ``chargers`` rows: each station's row with its position."""
        for row in rows:
            x, y, _ = self.space.position(row["node"])
            self.recorder.add("chargers", x=x, y=y, **row)

    def summary(self, run: dict, vehicles, dispatcher, now: float, extra: dict) -> dict:
        """The summary row (``run``'s keys, the statistics, then ``extra``), recorded and
        returned."""
        summary = self.stats.summary(run=run, vehicles=vehicles, dispatcher=dispatcher,
                                     sim_time=now)
        summary.update(extra)
        self.recorder.add("summary", **summary)
        return summary
