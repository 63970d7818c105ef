"""Driver shifts for the replay: when each vehicle is off shift or driving home to its depot,
rebuilt from a run's ``events`` (``shift_start``, ``shift_end``) and ``vehicles``
(``vehicle_hours``) tables, and laid over the fleet states of
:func:`analysis.timeline.fleet_states`.

A vehicle (see ``dispatch.fleet.shifts``) is **off shift** before it enters the fleet and after it
leaves it: from a ``shift_end`` event to its next ``shift_start`` event (or the run's end).
At time 0 it is off shift when its first shift event is a ``shift_start``, or, without any
shift event, when it was never on duty (``vehicle_hours`` 0: a vehicle a sizing strategy
never called in). It is **driving to its depot** from the last ``depart`` without a task
(task id -1) before a ``shift_end``, if no event of a task (task id >= 0) lies between them,
to that ``shift_end`` (a vehicle already at its depot leaves at once: no such drive). Runs
without shifts have no shift event: every vehicle is on duty throughout, as before.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: the replay's vehicle states beyond :data:`analysis.timeline.FLEET_STATES`
DUTY_STATES = ("to_depot", "off_shift")


def duty_spells(events: pd.DataFrame, vehicles: pd.DataFrame, end: float) -> pd.DataFrame:
    """Columns agent_id, state (one of :data:`DUTY_STATES`), start, end: the spells each
    vehicle spends driving home or off shift (see the module), none overlapping, sorted by
    vehicle and start; empty for a run without shift events."""
    cols = ["agent_id", "state", "start", "end"]
    shift = events.loc[events["event"].isin(["shift_start", "shift_end"])
                       & (events["agent_id"] >= 0)]
    hours = (dict(zip(vehicles["agent_id"].astype(int), vehicles["vehicle_hours"].astype(float)))
             if "vehicle_hours" in vehicles.columns else {})
    never = {a for a, h in hours.items() if h == 0.0}
    if shift.empty and not never:
        return pd.DataFrame(columns=cols)
    ev = events.loc[events["agent_id"] >= 0].sort_values(["agent_id", "t"], kind="stable")
    by_agent = dict(iter(ev.groupby("agent_id", sort=False)))
    rows = []
    for agent in sorted(vehicles["agent_id"].astype(int)):
        g = by_agent.get(agent)
        if g is None:
            if agent in never:
                rows.append((agent, "off_shift", 0.0, end))
            continue
        t = g["t"].to_numpy(dtype=float)
        kind = g["event"].to_numpy()
        task = g["task_id"].to_numpy(dtype=np.int64)
        marks = np.flatnonzero((kind == "shift_start") | (kind == "shift_end"))
        if marks.size == 0:
            if agent in never:
                rows.append((agent, "off_shift", 0.0, end))
            continue
        off_since = 0.0 if kind[marks[0]] == "shift_start" else None
        for m in marks:
            if kind[m] == "shift_start":
                if off_since is not None and t[m] > off_since:
                    rows.append((agent, "off_shift", off_since, float(t[m])))
                off_since = None
                continue
            # shift_end: the drive home is the last task-less depart since the last task event
            home = None
            for k in range(m - 1, -1, -1):
                if task[k] >= 0 or kind[k] in ("shift_start", "shift_end"):
                    break
                if kind[k] == "depart":
                    home = float(t[k])
                    break
            if home is not None and t[m] > home:
                rows.append((agent, "to_depot", home, float(t[m])))
            off_since = float(t[m])
        if off_since is not None and end > off_since:
            rows.append((agent, "off_shift", off_since, end))
    return pd.DataFrame(rows, columns=cols)


def overlay(states: pd.DataFrame, spells: pd.DataFrame) -> pd.DataFrame:
    """``states`` (columns agent_id, state, start, end, onboard and any more, one vehicle's
    rows covering its time without overlaps) with each of ``spells`` (see
    :func:`duty_spells`) put over them: rows cut where a spell begins and ends, the spell's
    state (with nobody on board) in between. Sorted by vehicle and start."""
    if spells.empty:
        return states
    out = []
    spell_by = dict(iter(spells.groupby("agent_id", sort=False)))
    for agent, g in states.groupby("agent_id", sort=False):
        sp = spell_by.get(agent)
        if sp is None:
            out.append(g)
            continue
        rows = g.to_dict("records")
        for s in sp.itertuples(index=False):
            cut = []
            for r in rows:
                if r["end"] <= s.start or r["start"] >= s.end:
                    cut.append(r)
                    continue
                if r["start"] < s.start:
                    cut.append({**r, "end": s.start})
                if r["end"] > s.end:
                    cut.append({**r, "start": s.end})
            cut.append({**rows[0], "state": s.state, "start": float(s.start), "end": float(s.end),
                        "onboard": 0})
            rows = sorted(cut, key=lambda r: r["start"])
        out.append(pd.DataFrame(rows, columns=g.columns))
    res = pd.concat(out, ignore_index=True)
    return res.sort_values(["agent_id", "start"], kind="stable").reset_index(drop=True)


def duty_at(spells: pd.DataFrame, agents, t: float) -> dict[str, int]:
    """How many of ``agents`` are driving to their depot and off shift at time ``t``."""
    inside = spells.loc[(spells["start"] <= t) & (t < spells["end"])
                        & spells["agent_id"].isin(list(agents))]
    return {s: int((inside["state"] == s).sum()) for s in DUTY_STATES}
