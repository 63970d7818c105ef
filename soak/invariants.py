"""The promises of a run's Parquet tables, checked from the files alone (and the scenario
document that made them): nothing of the engine is imported, so the checks hold for any engine
that writes these tables. ``docs/reference/invariants.md`` says what each promise is.

:func:`check` returns the violations, each ``(invariant, message)``; :data:`INVARIANTS` names
every invariant in the order the soak's table prints them.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

#: seconds (and metres) of slack in every comparison: float sums of legs and waits
TOL = 1e-6
#: wall-clock columns: the only ones two runs of one seed may differ in
WALL_COLUMNS = {"alloc_seconds", "cost_seconds", "decide_seconds", "first_decision_seconds",
                "agent_seconds"}
#: each terminal state and its event (``cancelled`` / ``cancel``: what older versions wrote
#: for ``cut_off``)
TERMINAL_EVENT = {"completed": "complete", "expired": "expire", "rejected": "reject",
                  "unreachable": "unreachable", "cut_off": "cut_off", "cancelled": "cancel",
                  "failed": "failed", "declined": "decline"}
#: events whose position is the vehicle's own (others give the task's pickup or a target)
AT_VEHICLE = {"depart", "pickup", "dropoff", "complete", "idle", "charge_start", "charge_end",
              "queue", "stranded", "breakdown", "break_start", "break_end", "move", "wait"}
INVARIANTS = ("one_terminal_state", "pickup_not_early", "wait_limit", "delay_limit",
              "capacity", "walk_limit", "shift", "break_empty", "energy_balance", "soc_floor",
              "promise_kept", "reachable", "assign_open_only", "summary_counts", "legs_in_order",
              "same_seed")
SUMMARY_STATES = {"tasks_completed": "completed", "tasks_expired": "expired",
                  "tasks_rejected": "rejected", "tasks_unreachable": "unreachable",
                  "tasks_cut_off": "cut_off", "tasks_cancelled": "cancelled",
                  "tasks_failed": "failed",
                  "tasks_declined": "declined"}


def read_tables(out: Path) -> dict[str, pd.DataFrame]:
    """Every table of the one run in ``out`` (``OUT/<table>/<partition>/part-0.parquet``), and
    as ``_edges`` the road network's edges the run wrote once beside them
    (``OUT/_spaces/road-*/edges.parquet``: ``u``, ``v``, free-flow ``seconds``, ``metres``)."""
    tables = {}
    for folder in sorted(Path(out).iterdir()):
        if folder.name.startswith("_") or not folder.is_dir():
            continue
        parts = sorted(folder.rglob("part-0.parquet"))
        if len(parts) == 1:
            tables[folder.name] = pq.read_table(parts[0]).to_pandas()
    edges = sorted(Path(out).glob("_spaces/road-*/edges.parquet"))
    if len(edges) == 1:
        tables["_edges"] = pq.read_table(edges[0]).to_pandas()
    return tables


def check(doc: dict, tables: dict[str, pd.DataFrame]) -> list[tuple[str, str]]:
    """The violations of one run's ``tables``, written from the scenario ``doc``."""
    found: list[tuple[str, str]] = []
    tasks, events, vehicles = tables["tasks"], tables["events"], tables["vehicles"]
    events = events.sort_values("t", kind="stable")
    tdoc = doc.get("tasks", {})
    for name, fn in CHECKS:
        for message in fn(doc, tdoc, tables, tasks, events, vehicles):
            found.append((name, message))
    return found


def _terminal(doc, tdoc, tables, tasks, events, vehicles):
    if tasks.task_id.duplicated().any():
        yield f"tasks {sorted(tasks.task_id[tasks.task_id.duplicated()])[:5]} have two rows"
    bad = ~tasks.state.isin(list(TERMINAL_EVENT))
    if bad.any():
        yield f"tasks in no terminal state: {tasks[bad].state.unique().tolist()}"
    released = set(events.task_id[events.event == "release"])
    if released != set(tasks.task_id):
        yield (f"{len(released ^ set(tasks.task_id))} tasks released without a row or a row "
               f"without release")
    ends = events[events.event.isin([e for e in TERMINAL_EVENT.values() if e != "decline"])]
    n = ends.groupby("task_id").size()
    for t in tasks.itertuples():
        want = TERMINAL_EVENT.get(t.state)
        if want == "decline":
            if n.get(t.task_id, 0) != 0:
                yield f"task {t.task_id} declined with a terminal event too"
            continue
        got = ends[ends.task_id == t.task_id].event.tolist() if n.get(t.task_id, 0) != 1 \
            else None
        if got is not None:
            yield f"task {t.task_id} ({t.state}): terminal events {got}"
        elif ends.event[ends.task_id == t.task_id].iloc[0] != want:
            yield f"task {t.task_id} ({t.state}): terminal event is not {want}"


def _walk_speed(tdoc) -> float:
    return float(tdoc.get("walk_speed", 1.4))


def _untransferred(tasks):
    return tasks[(tasks.transfers == 0) & tasks.picked_up_at.notna()]


def _pickup_early(doc, tdoc, tables, tasks, events, vehicles):
    up = tasks[tasks.picked_up_at.notna()]
    walk = np.nan_to_num(up.walk_to_board_m.to_numpy(float)) / _walk_speed(tdoc)
    earliest = up.released_at.to_numpy(float) + walk
    for t, e in zip(up.itertuples(), earliest):
        if t.picked_up_at < e - TOL:
            yield (f"task {t.task_id} picked up at {t.picked_up_at:.3f} s before its earliest "
                   f"{e:.3f} s (release {t.released_at:.3f}, walk {t.walk_to_board_m:.1f} m)")


def _wait(doc, tdoc, tables, tasks, events, vehicles):
    up = _untransferred(tasks)
    up = up[up.max_wait.notna()]
    late = up.picked_up_at - up.released_at - up.max_wait
    for t, d in zip(up.itertuples(), late):
        if d > TOL:
            yield (f"task {t.task_id} picked up {d:.3f} s past release + max_wait "
                   f"(booked: {t.booked_at == t.booked_at}, agent {t.agent_id})")


def _drop_times(events) -> dict[int, float]:
    d = events[events.event == "dropoff"]
    return dict(zip(d.task_id, d.t))


def _delay(doc, tdoc, tables, tasks, events, vehicles):
    done = tasks[(tasks.state == "completed") & (tasks.transfers == 0)
                 & tasks.max_delay.notna() & tasks.direct_time.notna()]
    drops = _drop_times(events)
    speed = _walk_speed(tdoc)
    for t in done.itertuples():
        at = drops.get(t.task_id)
        if at is None:
            yield f"task {t.task_id} completed without a dropoff event"
            continue
        walk = 0.0 if t.walk_from_alight_m != t.walk_from_alight_m else t.walk_from_alight_m
        late = at + walk / speed - (t.released_at + t.direct_time + t.max_delay)
        if late > TOL:
            yield (f"task {t.task_id} dropped off {late:.3f} s past release + direct + "
                   f"max_delay (booked: {t.booked_at == t.booked_at}, agent {t.agent_id})")


def _capacity(doc, tdoc, tables, tasks, events, vehicles):
    riders = dict(zip(tasks.task_id, tasks.passengers))
    seats = dict(zip(vehicles.agent_id, vehicles.capacity))
    mine = events[(events.agent_id >= 0) & events.event.isin(
        ["pickup", "dropoff", "complete", "breakdown", "failed", "reopen"])]
    for agent, ev in mine.groupby("agent_id", sort=True):
        aboard: dict[int, int] = {}  # (a point task of the voxel world leaves at `complete`)
        for e in ev.itertuples():
            if e.event == "pickup":
                aboard[e.task_id] = riders.get(e.task_id, 1)
                if sum(aboard.values()) > seats.get(agent, 1):
                    yield (f"vehicle {agent}: {sum(aboard.values())} riders aboard at "
                           f"{e.t:.3f} s, {seats.get(agent)} seats")
                    break
            elif e.event == "breakdown":
                aboard.clear()  # riders aboard are transferred or fail
            else:
                aboard.pop(e.task_id, None)


def _walk(doc, tdoc, tables, tasks, events, vehicles):
    limit = float(tdoc.get("max_walk", 0.0))
    for col in ("walk_to_board_m", "walk_from_alight_m"):
        over = tasks[tasks[col].notna() & (tasks[col] > limit + TOL)]
        for t in over.itertuples():
            yield f"task {t.task_id}: {col} {getattr(t, col):.2f} m over max_walk {limit} m"


def _shift(doc, tdoc, tables, tasks, events, vehicles):
    grace = float(doc.get("fleet", {}).get("shift_grace", 0.0))
    service = events[events.event.isin(["pickup", "dropoff"]) & (events.agent_id >= 0)]
    shifts = vehicles.set_index("agent_id")[["shift_start", "shift_end"]]
    for e in service.itertuples():
        s, end = shifts.loc[e.agent_id]
        if e.t < s - TOL or e.t > end + grace + TOL:
            yield (f"vehicle {e.agent_id}: {e.event} of task {e.task_id} at {e.t:.3f} s outside "
                   f"its shift {s:.1f}-{end:.1f} s (+{grace} s grace)")


def _break(doc, tdoc, tables, tasks, events, vehicles):
    riders = dict(zip(tasks.task_id, tasks.passengers))
    mine = events[(events.agent_id >= 0) & events.event.isin(
        ["pickup", "dropoff", "breakdown", "break_start", "break_end", "depart"])]
    for agent, ev in mine.groupby("agent_id", sort=True):
        aboard: dict[int, int] = {}
        on_break = False
        for e in ev.itertuples():
            if e.event == "break_start":
                on_break = True
                if aboard:
                    yield f"vehicle {agent}: break at {e.t:.3f} s with riders {sorted(aboard)}"
            elif e.event in ("break_end", "breakdown"):
                on_break = False  # (a breakdown cuts a break: the rest is the repair's)
            elif on_break:
                yield f"vehicle {agent}: {e.event} at {e.t:.3f} s during its break"
                on_break = False
            if e.event == "pickup":
                aboard[e.task_id] = riders.get(e.task_id, 1)
            elif e.event == "dropoff":
                aboard.pop(e.task_id, None)
            elif e.event == "breakdown":
                aboard.clear()


def _energy(doc, tdoc, tables, tasks, events, vehicles):
    energy = doc.get("fleet", {}).get("energy")
    if not energy:
        return
    battery = float(energy.get("battery_kwh", 50.0))
    soc0 = float(energy.get("soc0", 1.0))
    for v in vehicles.itertuples():
        lhs = soc0 * battery + v.kwh_charged - v.kwh_drawn
        if abs(lhs - v.soc_end * battery) > 1e-6:
            yield (f"vehicle {v.agent_id}: {soc0 * battery:.6f} + {v.kwh_charged:.6f} - "
                   f"{v.kwh_drawn:.6f} kWh != soc_end {v.soc_end * battery:.6f} kWh")
    s = tables["summary"].iloc[0]
    for col in ("kwh_drawn", "kwh_charged"):
        if abs(s[col] - vehicles[col].sum()) > 1e-6:
            yield f"summary {col} {s[col]:.6f} != the vehicles' {vehicles[col].sum():.6f}"


def _soc(doc, tdoc, tables, tasks, events, vehicles):
    if not doc.get("fleet", {}).get("energy"):
        return
    stranded = set(events.agent_id[events.event == "stranded"])
    for v in vehicles.itertuples():
        if v.soc_min < -TOL and v.agent_id not in stranded:
            yield f"vehicle {v.agent_id}: soc_min {v.soc_min:.6f} without a stranding"
    soc = tables.get("soc")
    if soc is not None and len(soc):
        low = soc[(soc.soc < -TOL) & ~soc.agent_id.isin(stranded)]
        for r in low.head(3).itertuples():
            yield f"vehicle {r.agent_id}: soc {r.soc:.6f} at {r.t} s without a stranding"


def _promise(doc, tdoc, tables, tasks, events, vehicles):
    if "promised" not in tasks:
        return
    # a promise fails only by a breakdown: re-opened by one (its vehicle broke down before
    # the pickup), or aboard the vehicle that broke down (on_board = "fail")
    reopened = set(events.task_id[events.event == "reopen"])
    downs = events[events.event == "breakdown"]
    ended = ["completed", "cut_off", "cancelled"]
    broken = tasks[tasks.promised.astype(bool) & ~tasks.state.isin(ended)]
    for t in broken.itertuples():
        named = t.task_id in reopened or bool(
            ((downs.agent_id == t.agent_id) & (downs.t <= t.closed_at + TOL)).any())
        if t.state != "failed" or not named:
            yield (f"promise {t.task_id} ended {t.state}"
                   + ("" if named else " with no breakdown of its vehicle"))


def _reachable(doc, tdoc, tables, tasks, events, vehicles):
    walking = float(tdoc.get("max_walk", 0.0)) > 0
    speed = _top_speed(doc, tables, vehicles)
    voxel = "network" not in doc.get("world", {})
    kinds = AT_VEHICLE - ({"pickup", "dropoff", "complete"} if walking else set())
    mine = events[(events.agent_id >= 0) & events.event.isin(kinds | {"repair", "shift_start"})]
    for agent, ev in mine.groupby("agent_id", sort=True):
        v = speed.get(agent, math.inf)
        xyz = ev[["x", "y", "z"]].to_numpy(float)
        t = ev.t.to_numpy(float)
        kind = ev.event.to_numpy()
        step = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
        since = t[:-1]
        if voxel:  # an event names the cell the vehicle stands in or is stepping out of (a
            # `depart` mid-step): it may have left that cell from its first event there on
            first = np.where(np.r_[True, step > 1e-9], np.arange(len(t)), 0)
            since = t[np.maximum.accumulate(first)[:-1]]
        allowed = v * (t[1:] - since) * (1 + 1e-9) + 1e-6
        # a tow (repair after a stranding) and a shift's start at the depot move without
        # driving
        jump = np.isin(kind[1:], ["repair", "shift_start"])
        bad = np.flatnonzero((step > allowed) & ~jump)
        for i in bad[:1]:
            yield (f"vehicle {agent}: {step[i]:.1f} m from {kind[i]} at {t[i]:.3f} s to "
                   f"{kind[i + 1]} at {t[i + 1]:.3f} s, at most {v:.6g} m/s")


def _top_speed(doc, tables, vehicles) -> dict[int, float]:
    """Each vehicle's top speed: in a voxel world its own ``speed``; on roads the fastest edge
    of the network the run wrote (``_edges``: metres over free-flow seconds; a generated grid
    without that file: its ``[world] speed``), faster still by an hourly congestion factor
    below 1."""
    world = doc.get("world", {})
    if "network" not in world:
        return dict(zip(vehicles.agent_id, vehicles.speed))
    edges = tables.get("_edges")
    if edges is not None and len(edges):
        moves = edges[edges.metres > 0]
        timed = moves.seconds > 0
        top = (0.0 if not len(moves) else math.inf if not timed.all()
               else float((moves.metres / moves.seconds).max()))
    else:
        top = float(world.get("speed", 10.0))  # the generated grid: every street at `speed`
    factors = world.get("congestion")
    if isinstance(factors, list) and factors:
        top /= min(1.0, min(float(f) for f in factors))
    return {a: top for a in vehicles.agent_id}


def _assign_open(doc, tdoc, tables, tasks, events, vehicles):
    closed = dict(zip(tasks.task_id, tasks.closed_at))
    a = events[events.event.isin(["assign", "insert"])]
    for e in a.itertuples():
        c = closed.get(e.task_id, math.inf)
        if e.t > c + TOL:
            yield f"task {e.task_id} assigned at {e.t:.3f} s, closed at {c:.3f} s"


def _summary(doc, tdoc, tables, tasks, events, vehicles):
    s = tables["summary"].iloc[0]
    counts = tasks.state.value_counts()
    if s.n_tasks != len(tasks):
        yield f"summary n_tasks {s.n_tasks} != {len(tasks)} task rows"
    for col, state in SUMMARY_STATES.items():
        if col in s and s[col] != counts.get(state, 0):
            yield f"summary {col} {s[col]} != {counts.get(state, 0)} rows {state}"
    pairs = {"decisions": len(tables.get("decisions", ())),
             "failures": int(vehicles.failures.sum()),
             "strandings": int((events.event == "stranded").sum()),
             "charges": int((events.event == "charge_start").sum()),
             "tasks_reassigned": int((tasks.reassigned > 0).sum()),
             "tasks_transferred": int((tasks.transfers > 0).sum())}
    if tasks.reassigned.sum() != (events.event == "reopen").sum():
        yield (f"tasks.reassigned sums to {tasks.reassigned.sum()}, "
               f"{(events.event == 'reopen').sum()} reopen events")
    if "promised" in tasks:
        pairs["promises"] = int(tasks.promised.astype(bool).sum())
    for col, want in pairs.items():
        if col in s and s[col] != want:
            yield f"summary {col} {s[col]} != {want} from the tables"
    done = tasks.state == "completed"
    if "tasks_unfinished" in s and s.tasks_unfinished != len(tasks) - done.sum():
        yield f"summary tasks_unfinished {s.tasks_unfinished} != {len(tasks) - done.sum()}"


def _legs(doc, tdoc, tables, tasks, events, vehicles):
    """[transit]: each rider's legs numbered 0, 1, ... in time order, each from where and no
    sooner than the one before ended; a train leg names its trip and stops; a fleet leg is a
    completed task of the rider with its vehicle; riders and those served as the summary's."""
    legs = tables.get("legs")
    if legs is None:
        return
    done = tasks.loc[tasks.state == "completed"]
    ride = dict(zip(zip(done.request_id, done.agent_id), done.picked_up_at))
    for rid, g in legs.sort_values(["request_id", "leg"]).groupby("request_id"):
        if list(g.leg) != list(range(len(g))):
            yield f"request {rid}: legs numbered {list(g.leg)}"
        start, end = g.start.to_numpy(), g.end.to_numpy()
        if (end < start - TOL).any() or (start[1:] < end[:-1] - TOL).any():
            yield f"request {rid}: legs out of time order"
        xy = g[["from_x", "from_y", "to_x", "to_y"]].to_numpy()
        if not np.allclose(xy[1:, :2], xy[:-1, 2:]):
            yield f"request {rid}: a leg starts away from where the one before ended"
        for leg in g.itertuples():
            if leg.mode == "train" and (leg.trip_id is None or leg.from_stop_id is None
                                        or leg.to_stop_id is None):
                yield f"request {rid}: train leg {leg.leg} names no trip or stop"
            if leg.mode == "fleet" and ride.get((rid, leg.agent_id)) != leg.start:
                yield f"request {rid}: fleet leg {leg.leg} is no completed ride of its vehicle"
    s = tables["summary"].iloc[0]
    if "riders" in s and legs.request_id.nunique() > s.riders:
        yield f"{legs.request_id.nunique()} riders with legs, summary riders {s.riders}"


CHECKS = (("one_terminal_state", _terminal), ("pickup_not_early", _pickup_early),
          ("wait_limit", _wait), ("delay_limit", _delay), ("capacity", _capacity),
          ("walk_limit", _walk), ("shift", _shift), ("break_empty", _break),
          ("energy_balance", _energy), ("soc_floor", _soc), ("promise_kept", _promise),
          ("reachable", _reachable), ("assign_open_only", _assign_open),
          ("summary_counts", _summary), ("legs_in_order", _legs))


def same_tables(a: dict[str, pd.DataFrame], b: dict[str, pd.DataFrame]) -> list[str]:
    """The tables in which two runs of one scenario and seed differ, wall-clock columns
    aside (values compared exactly, NaN equal to NaN)."""
    diff = []
    for name in sorted(set(a) | set(b)):
        if name not in a or name not in b:
            diff.append(f"{name}: in one run only")
            continue
        x, y = _timeless(a[name]), _timeless(b[name])
        if not x.equals(y):
            diff.append(name)
    return diff


def _timeless(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` without its wall-clock columns (and the wall-clock entries, ``*seconds*``, of an
    allocator's ``allocator_info`` JSON)."""
    df = df.drop(columns=[c for c in WALL_COLUMNS if c in df])
    if "allocator_info" in df:
        df = df.assign(allocator_info=[
            {k: v for k, v in json.loads(s).items() if "seconds" not in k}
            if isinstance(s, str) and s.startswith("{") else s for s in df.allocator_info])
    return df


def counts_by(found) -> dict[str, int]:
    """Violations per invariant."""
    out: dict[str, int] = defaultdict(int)
    for name, _ in found:
        out[name] += 1
    return dict(out)
