"""The run's subscribers that write its rows: events, tasks, decisions and vehicles.

Each subscriber builds its table's rows by column *name*: a row builder is made once per run
from :data:`dispatch.recorder.SCHEMAS` and a mapping of column names to what they hold, so a
column added to a schema without saying what it holds fails when the run starts (a
``KeyError`` naming it), never as values shifted into the wrong columns. The builders feed the
recorder's fast path (one tuple per row, in the schema's order).

* :func:`event_writer`: subscribes to the event bus (every event a row of ``events``; where it
  happened is looked up per chunk, for the whole chunk at once);
* :class:`TaskWriter`: subscribes to the task book's closures (one ``tasks`` row per task, as
  it reaches its terminal state);
* :class:`DecisionWriter`: the dispatcher's ``on_decision`` (``decisions`` and
  ``assignments`` rows);
* :func:`write_vehicles`: the ``vehicles`` rows at the end of the run;
* :class:`RunRecording`: one run's wiring of them: the run's metadata and the space's static
  tables, the writers, the summary statistics (:class:`dispatch.stats.RunStats`) and the
  end-of-run tables.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from dispatch import space_files
from dispatch.recorder import SCHEMAS
from dispatch.stats import RunStats

NAN3 = (math.nan, math.nan, math.nan)


def row_builder(table: str, columns: dict[str, str], args: str) -> Callable[..., tuple]:
    """``build(*args) -> row``: a function of ``args`` (its parameter list) returning the
    tuple of ``table``'s columns (all but ``run_id``) in the schema's order, each computed by
    the expression ``columns[name]`` (Python over ``args``). Compiled once: a row costs one
    call, as a hand-written tuple would."""
    names = [n for n in SCHEMAS[table].names if n != "run_id"]
    missing = [n for n in names if n not in columns]
    extra = sorted(set(columns) - set(names))
    if missing or extra:
        raise KeyError(f"{table}: no value for column(s) {missing}; unknown {extra}")
    body = ", ".join(f"({columns[n]})" for n in names)
    scope: dict[str, Any] = {}
    exec(f"def build({args}):\n    return ({body},)\n", scope)  # noqa: S102 - our own text
    return scope["build"]


#: the ``tasks`` table: each column from the task ``t`` and the positions of its pickup ``p``
#: and drop-off ``d``
TASK_COLUMNS = {
    "task_id": "t.id", "kind": "t.kind", "x": "p[0]", "y": "p[1]", "z": "p[2]",
    "dropoff_x": "d[0]", "dropoff_y": "d[1]", "dropoff_z": "d[2]",
    "released_at": "t.released_at", "max_wait": "t.max_wait", "snap_m": "t.snap_m",
    "dropoff_snap_m": "t.dropoff_snap_m", "assigned_at": "t.assigned_at",
    "agent_id": "t.agent_id", "cost": "t.cost", "picked_up_at": "t.picked_up_at",
    "completed_at": "t.completed_at", "state": "t.state._value_", "conflicted": "t.conflicted",
    "closed_at": "t.closed_at", "reassigned": "t.reassigned", "transfers": "t.transfers",
    "passengers": "t.passengers", "direct_time": "t.direct_time", "max_delay": "t.max_delay",
    "shared": "t.shared",
}
#: the ``decisions`` table: from the decision's number ``i``, problem ``p``, allocation ``a``
#: and figures
DECISION_COLUMNS = {
    "decision": "i", "t": "float(p.time)", "n_idle": "p.n_agents", "n_tasks": "p.n_tasks",
    "n_assigned": "len(a.pairs)", "rounds": "a.rounds", "messages": "a.messages",
    "conflicts": "len(a.conflicted_tasks())", "total_cost": "total",
    "cost_seconds": "cost_s", "decide_seconds": "decide_s", "hops": "hops",
    "comm_delay": "comm_delay", "agent_seconds": "agent_seconds",
    "comm_components": "components", "n_cut": "cut",
}
#: the ``assignments`` table: one row per request ``r`` of decision ``i``
ASSIGNMENT_COLUMNS = {
    "decision": "i", "round": "r.round", "agent_id": "r.agent_id", "task_id": "r.task_id",
    "cost": "r.cost", "won": "r.won", "alloc_seconds": "alloc_s",
}
#: the ``vehicles`` table: from the vehicle ``v``, its start position ``p``, the seconds it
#: was down ``down`` and the counts of reservation-based execution ``c``
VEHICLE_COLUMNS = {
    "agent_id": "v.id", "kind": "v.kind", "speed": "v.speed", "x0": "p[0]", "y0": "p[1]",
    "z0": "p[2]", "distance": "v.distance", "empty_distance": "v.empty_distance",
    "occupied_distance": "v.occupied_distance", "busy_seconds": "v.busy_seconds",
    "tasks_completed": "v.completed", "waits": "c['waits']", "replans": "c['replans']",
    "wait_seconds": "c['wait_seconds']", "failures": "v.failures", "down_seconds": "down",
    "capacity": "v.capacity", "passenger_distance": "v.passenger_distance",
    "kwh_drawn": "b.drawn if b else nan", "kwh_charged": "b.charged if b else nan",
    "charge_seconds": "b.charge_seconds if b else nan",
    "queue_seconds": "b.queue_seconds if b else nan",
    "soc_min": "b.kwh_min / b.capacity if b else nan", "soc_end": "b.soc if b else nan",
}


class TaskWriter:
    """Subscriber of the task book's closures: the task's ``tasks`` row."""

    def __init__(self, recorder, space) -> None:
        self.append, self.position = recorder.append, space.position
        self.build = row_builder("tasks", TASK_COLUMNS, "t, p, d")

    def __call__(self, t) -> None:
        p = self.position(t.loc if t.origin is None else t.origin)
        d = NAN3 if t.dropoff is None else self.position(t.dropoff)
        self.append("tasks", self.build(t, p, d))


class DecisionWriter:
    """The dispatcher's ``on_decision``: a ``decisions`` row and one ``assignments`` row per
    request of the decision's rounds."""

    def __init__(self, recorder) -> None:
        self.append = recorder.append
        self.decision = row_builder("decisions", DECISION_COLUMNS,
                                    "i, p, a, total, cost_s, decide_s, hops, comm_delay, "
                                    "agent_seconds, components, cut")
        self.request = row_builder("assignments", ASSIGNMENT_COLUMNS, "i, r, alloc_s")

    def __call__(self, index: int, problem, allocation, total: float, cost_s: float,
                 decide_s: float, *, hops: int = 0, comm_delay: float = 0.0,
                 agent_seconds: float = math.nan, components: int = 1, cut: int = 0) -> None:
        append, alloc_s, request = self.append, cost_s + decide_s, self.request
        for r in allocation.requests:
            append("assignments", request(index, r, alloc_s))
        append("decisions", self.decision(index, problem, allocation, total, cost_s, decide_s,
                                          hops, comm_delay, agent_seconds, components, cut))


def write_vehicles(recorder, space, vehicles, now: float, counts) -> None:
    """The ``vehicles`` rows at the end of a run (``counts(v)``: its waits, replans and
    wait_seconds)."""
    build = row_builder("vehicles", VEHICLE_COLUMNS, "v, p, down, c, b, nan=float('nan')")
    for v in vehicles:
        down = v.down_seconds + (now - v.down_since if v.failed else 0.0)
        recorder.append("vehicles", build(v, space.position(v.start), down, counts(v),
                                          v.battery))


def event_writer(recorder, space):
    """The subscriber that writes each event as a row of the ``events`` table (several per
    trip): it keeps the event itself; its position is looked up when the chunk is written,
    for the whole chunk at once (on roads, a gather from the nodes' positions)."""
    position = space.position
    nodes = getattr(space, "node_positions", None)
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
                "x": x, "y": y, "z": z}

    return recorder.appender("events", columns)


class RunRecording:
    """What one run records into ``recorder``: made when the run is built (the space's
    metadata and its static tables' metadata are set at once), :meth:`attach`-ed to the event
    bus, and finished by :meth:`end_tables`, :meth:`chargers` and :meth:`summary`.

    ``stats`` (:class:`dispatch.stats.RunStats`) counts the closed tasks; ``on_close`` are
    the task book's closure subscribers (the statistics, then the ``tasks`` row);
    ``decision`` is the dispatcher's ``on_decision``."""

    def __init__(self, recorder, space) -> None:
        self.recorder, self.space = recorder, space
        self.stats = RunStats()
        recorder.metadata.update(space.describe())
        # the space's shared tables (a road network), once per results folder
        recorder.metadata.update(space_files.store(getattr(recorder, "out", None), space))
        self.static = space.tables()
        for name, (meta, _rows) in self.static.items():
            recorder.table_metadata[name] = meta
        self.event = None
        self.task = TaskWriter(recorder, space)
        self.decision = DecisionWriter(recorder)
        self.on_close = [self.stats.closed, self.task]

    def attach(self, bus) -> None:
        """Write every event of ``bus`` as a row of ``events``."""
        self.event = event_writer(self.recorder, self.space)
        bus.subscribe(self.event)

    def end_tables(self, vehicles, now: float, counts) -> None:
        """The ``vehicles`` rows (see :func:`write_vehicles`) and the space's static rows."""
        write_vehicles(self.recorder, self.space, vehicles, now, counts)
        for name, (_meta, rows) in self.static.items():
            for row in rows:
                self.recorder.add(name, **row)

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
