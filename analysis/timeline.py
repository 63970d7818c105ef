"""What each vehicle did when, rebuilt from a run's ``events`` table.

Vehicle events (``agent_id`` >= 0) and what they mean for the vehicle:

* ``assign``  a task was given to it (x, y, z: the task's cell);
* ``depart``  it leaves for the pickup, or with the passenger for the drop-off (x, y, z: where
  it is); with task -1 it drives, idle, toward a repositioning target (after a ``reposition``);
* ``move``    it entered the next cell of its path (x, y, z: that cell; on roads, only with
  ``edge_events``: the node it reached);
* ``wait``    it holds its cell on the way (a reservation conflict), until its next ``move``;
* ``pickup``  it reached the task (the trip's pickup) and starts serving it (``arrive`` in
  results written before trips existed);
* ``dropoff`` it reached the trip's drop-off (then serves for the service time);
* ``idle``    it finished the task and is free again (or was repaired);
* ``breakdown`` it failed where it is (``[faults]``); ``down`` until its next ``idle``.

:func:`vehicle_intervals` turns them into ``travel`` / ``service`` (both busy), ``waiting``,
``reposition`` (idle, driving to a repositioning target) and ``idle`` intervals for a Gantt chart; :func:`trajectories` and :func:`positions_at` give where
each vehicle is, for the 3D view and the rendered animation.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: Events whose x, y, z are the vehicle's own position (``assign`` and the task-closing events
#: carry the task's cell instead).
POSITION_EVENTS = ("depart", "move", "wait", "pickup", "dropoff", "arrive", "idle")
STATES = ("travel", "service", "waiting", "reposition", "idle", "down")


def vehicle_intervals(events: pd.DataFrame, vehicles: pd.DataFrame,
                      end: float | None = None) -> pd.DataFrame:
    """Columns agent_id, state (one of :data:`STATES`), start, end, task_id; every vehicle is
    covered from 0 to ``end`` (default: the last event) without gaps or overlaps."""
    e = events.loc[events["agent_id"] >= 0].sort_values("t", kind="stable")
    if end is None:
        end = float(events["t"].max()) if len(events) else 0.0
    rows = []
    by_agent = dict(iter(e.groupby("agent_id", sort=False)))
    for agent in sorted(vehicles["agent_id"].astype(int)):
        state, since, task = "idle", 0.0, -1
        g = by_agent.get(agent)
        for ev in (g.itertuples(index=False) if g is not None else ()):
            new = {"assign": "waiting", "depart": "travel", "move": "travel", "wait": "waiting",
                   "pickup": "service", "dropoff": "service", "arrive": "service",
                   "idle": "idle", "breakdown": "down"}.get(ev.event)
            if ev.task_id < 0 and ev.event in ("depart", "move") and \
                    state in ("idle", "reposition"):  # idle, driving to a reposition target
                new = "reposition" if ev.event == "depart" or state == "reposition" else new
            if new is None or (ev.event == "assign" and state not in ("idle", "reposition")) or (
                    state == "down" and new != "idle"):
                continue
            if new != state:
                if ev.t > since:
                    rows.append((agent, state, since, float(ev.t), task))
                state, since = new, float(ev.t)
            task = int(ev.task_id) if new != "idle" else -1
        if end > since:
            rows.append((agent, state, since, end, task))
    return pd.DataFrame(rows, columns=["agent_id", "state", "start", "end", "task_id"])


def trajectories(events: pd.DataFrame, vehicles: pd.DataFrame) -> dict[int, pd.DataFrame]:
    """Per vehicle: its known positions in time order (columns t, x, y, z), starting with its
    start cell at t = 0. Between two rows it moves in a straight line."""
    e = events.loc[events["event"].isin(POSITION_EVENTS) & (events["agent_id"] >= 0)]
    e = e.sort_values("t", kind="stable")
    by_agent = dict(iter(e.groupby("agent_id", sort=False)))
    out = {}
    for v in vehicles.sort_values("agent_id").itertuples(index=False):
        start = pd.DataFrame({"t": [0.0], "x": [v.x0], "y": [v.y0], "z": [v.z0]})
        g = by_agent.get(v.agent_id)
        parts = [start] if g is None else [start, g[["t", "x", "y", "z"]]]
        out[int(v.agent_id)] = pd.concat(parts, ignore_index=True)
    return out


def positions_at(traj: dict[int, pd.DataFrame], t: float) -> dict[int, np.ndarray]:
    """Each vehicle's position at time ``t`` (linear between its known positions)."""
    out = {}
    for agent, df in traj.items():
        ts = df["t"].to_numpy(dtype=float)
        xyz = df[["x", "y", "z"]].to_numpy(dtype=float)
        i = int(np.searchsorted(ts, t, side="right"))
        if i == 0:
            out[agent] = xyz[0]
        elif i >= len(ts):
            out[agent] = xyz[-1]
        else:
            t0, t1 = ts[i - 1], ts[i]
            a = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
            out[agent] = xyz[i - 1] + a * (xyz[i] - xyz[i - 1])
    return out


# ----------------------------------------------------------------------------- fleet state

#: Fleet states as ride-hailing studies count them (MATSim DRT's occupancy profile, FleetPy's
#: vehicle states), by passengers on board: ``to_pickup`` (a request assigned, nobody on
#: board), ``occupied`` (one on board, or the service at the end of a ride; for the paper's
#: point tasks, serving the task), ``occupied_2`` and ``occupied_3+`` (shared rides: two, three
#: or more passengers on board), ``repositioning`` (idle, driving empty where a repositioning
#: policy sends it), ``failed`` (broken down, until repaired), ``idle``; electric fleets
#: (``[fleet.energy]``): ``to_charger`` (driving to a station: a drive without a task, from
#: idle, that ends at a station or with the battery empty, or that the run's end cuts, in a
#: vehicle without shifts), ``queueing`` (waiting for a plug),
#: ``charging`` (plugged in); drivers' breaks (``[fleet.breaks]``): ``on_break``. A drive home at
#: the end of a shift is ``idle`` here; the replay and its Kepler export lay the shifts over
#: these states (``analysis.replay_duty``).
FLEET_STATES = ("idle", "to_pickup", "occupied", "occupied_2", "occupied_3+", "repositioning",
                "failed", "to_charger", "queueing", "charging", "on_break")
#: the electric fleets' states: plots show them only where some vehicle had them
CHARGING_STATES = ("to_charger", "queueing", "charging")
#: the states of a vehicle with one or more on board (or serving)
OCCUPIED = ("occupied", "occupied_2", "occupied_3+")

_FLEET_EVENTS = ("assign", "reassign", "pickup", "arrive", "dropoff", "idle", "breakdown",
                 "reposition", "depart", "queue", "charge_start", "stranded", "break_start",
                 "break_end")
#: the events that end a drive to a charger: it arrives (and queues or plugs in), or its
#: battery runs out on the way
_AT_CHARGER = ("queue", "charge_start", "stranded")


def _occupied(onboard: int) -> str:
    return "occupied" if onboard <= 1 else "occupied_2" if onboard == 2 else "occupied_3+"


def fleet_states(events: pd.DataFrame, vehicles: pd.DataFrame,
                 end: float | None = None, passengers=None, *,
                 at_end: bool = False) -> pd.DataFrame:
    """Columns run_id, agent_id, state (one of :data:`FLEET_STATES`), start, end, onboard
    (passengers on board): every vehicle of every run covered from 0 to ``end`` (default: the
    run's last event) without gaps or overlaps. ``passengers``: riders per task id (a mapping
    or Series; default 1 each: the tasks table's ``passengers`` column gives them).
    ``at_end``: a vehicle whose state changes at the end instant itself (its last task
    completed as the run ends) gets a last, zero-length row ``[end, end]`` in the new state, so
    that a view of the end instant (the replay's last frame) shows it, not the state before.

    Transitions: ``assign`` -> to_pickup (from idle or repositioning); ``pickup`` -> occupied
    by the passengers on board; ``dropoff`` -> occupied by those left, or to_pickup when nobody
    is left and a pickup is pending, else (the service at the end of a ride) occupied until
    ``idle``; ``breakdown`` -> failed (only ``idle``, after a ``repair``, ends it);
    ``reposition`` -> repositioning (only from idle); ``break_start`` -> on_break,
    ``break_end`` -> to_pickup when a pickup is pending, else idle."""
    cols = ["run_id", "agent_id", "state", "start", "end", "onboard"]
    rows = []
    ev = events.loc[(events["agent_id"] >= 0) & events["event"].isin(list(_FLEET_EVENTS))]
    ev = ev.sort_values(["run_id", "t"], kind="stable")
    ends = {}
    if end is None:
        ends = events.groupby("run_id")["t"].max().to_dict() if len(events) else {}
    riders = {} if passengers is None else {int(k): int(v) for k, v in dict(passengers).items()}
    by_run = dict(iter(ev.groupby("run_id", sort=False)))
    for run, vs in vehicles.groupby("run_id", sort=False):
        stop = float(end if end is not None else ends.get(run, 0.0))
        on_shifts = (set(vs.loc[np.isfinite(vs["shift_end"].to_numpy(dtype=float)),
                                "agent_id"].astype(int))
                     if "shift_end" in vs.columns else set())
        g = by_run.get(run)
        by_agent = dict(iter(g.groupby("agent_id", sort=False))) if g is not None else {}
        for agent in sorted(vs["agent_id"].astype(int)):
            state, since, onboard, pending = "idle", 0.0, 0, set()
            shown = 0  # onboard of the open interval
            mine = by_agent.get(agent)
            if mine is not None:
                kinds = mine["event"].tolist()
                for k, (t, kind, task) in enumerate(zip(mine["t"].to_numpy(dtype=float), kinds,
                                                        mine["task_id"].to_numpy(dtype=np.int64))):
                    task = int(task)
                    new = state
                    if state == "failed" and kind != "idle":
                        continue
                    if kind == "assign":
                        pending.add(task)
                        if state in ("idle", "repositioning"):
                            new = "to_pickup"
                    elif kind == "reassign":
                        pending.discard(task)
                    elif kind in ("pickup", "arrive"):
                        pending.discard(task)
                        onboard += riders.get(task, 1)
                        new = _occupied(onboard)
                    elif kind == "dropoff":
                        onboard = max(onboard - riders.get(task, 1), 0)
                        new = (_occupied(onboard) if onboard else
                               "to_pickup" if pending else "occupied")
                    elif kind == "idle":
                        new, onboard, pending = "idle", 0, set()
                    elif kind == "breakdown":
                        new, onboard, pending = "failed", 0, set()
                    elif kind == "reposition" and state == "idle":
                        new = "repositioning"
                    elif kind == "depart" and task < 0 and state == "idle" and (
                            kinds[k + 1] in _AT_CHARGER if k + 1 < len(kinds)
                            else agent not in on_shifts):
                        # (a repositioning drive starts "repositioning"; a drive home at
                        # the end of a shift ends with an idle, no charger's event; one the
                        # run's end cuts is a charger's unless the vehicle works shifts)
                        new = "to_charger"
                    elif kind == "queue":
                        new = "queueing"
                    elif kind == "charge_start":
                        new = "charging"
                    elif kind == "break_start":
                        new = "on_break"
                    elif kind == "break_end":  # (no one on board: a break holds the seats)
                        new = "to_pickup" if pending else "idle"
                    if new != state or onboard != shown:
                        if t > since:
                            rows.append((run, agent, state, since, min(t, stop), shown))
                        state, since, shown = new, t, onboard
            if stop > since:
                rows.append((run, agent, state, since, stop, shown))
            elif at_end and since == stop and rows and rows[-1][:2] == (run, agent):
                rows.append((run, agent, state, stop, stop, shown))
    return pd.DataFrame(rows, columns=cols)


def hourly_states(states: pd.DataFrame, hour: float = 3600.0) -> pd.DataFrame:
    """Vehicle-seconds per run, clock hour (``hour`` = 0, 1, ...) and state: columns run_id,
    hour, and one column per state of :data:`FLEET_STATES`. Intervals that span an hour
    boundary are split."""
    if states.empty:
        return pd.DataFrame(columns=["run_id", "hour", *FLEET_STATES])
    s = states["start"].to_numpy(dtype=float)
    e = states["end"].to_numpy(dtype=float)
    h0 = np.floor(s / hour).astype(int)
    h1 = np.floor(np.maximum(e - 1e-9, s) / hour).astype(int)
    reps = h1 - h0 + 1
    idx = np.repeat(np.arange(len(states)), reps)
    k = np.arange(idx.size) - np.repeat(np.cumsum(reps) - reps, reps)
    hrs = h0[idx] + k
    lo = np.maximum(s[idx], hrs * hour)
    hi = np.minimum(e[idx], (hrs + 1) * hour)
    df = pd.DataFrame({"run_id": states["run_id"].to_numpy()[idx], "hour": hrs,
                       "state": states["state"].to_numpy()[idx], "seconds": hi - lo})
    out = df.pivot_table(index=["run_id", "hour"], columns="state", values="seconds",
                         aggfunc="sum", fill_value=0.0)
    for st in FLEET_STATES:
        if st not in out.columns:
            out[st] = 0.0
    out = out[list(FLEET_STATES)].reset_index()
    out.columns.name = None
    return out
