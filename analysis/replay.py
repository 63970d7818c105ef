"""``dispatch replay``: one run (or two, side by side) as one self-contained HTML page that
plays the run in the browser, offline.

The page is the hand-written canvas renderer ``replay_assets/replay.js`` (with its style sheet
and page skeleton, package data) and the run's data, embedded at write time; it fetches
nothing (its Content-Security-Policy allows no network request and only the page's own
script, by hash). The data are compact: numeric columns as little-endian typed arrays in
base64, vehicles as keyframes (time, position) with state change points, tasks as one row
each. Text from the input files (scenario name, station ids) travels inside a JSON block in
which ``<``, ``>`` and ``&`` are escaped, and the script puts it on the page as text only.

Where a vehicle is between its recorded positions (``depart``, ``pickup``, ``dropoff``,
``idle``, ...; on roads ``move`` at each node only with ``[output] edge_events``; in the voxel
world every cell) the page interpolates in a straight line.

Counts the panel shows (``data-kpi``), from the tasks table, at time ``t``: ``waiting``:
released at or before ``t``, not picked up and not closed by ``t``; ``onboard``: picked up
at or before ``t`` and not closed by ``t``; ``delivered``: completed at or before ``t``;
``rejected``: closed at or before ``t`` in state ``rejected`` or ``expired``
(:data:`REFUSED_STATES`); ``declined``: closed at or before ``t`` in state ``declined`` (the
rider declined the offer, ``dispatch.api.acceptor``); ``cutoff``: closed at or before ``t`` in state
``cut_off`` (:data:`CUT_OFF_STATE`: the run's end cut it off, labelled "cut off" as in the
report); ``booked``: booked ahead (``booked_at``) at or before ``t``, not picked up and not
closed by ``t`` (``dispatch.decide.prebook``); ``walking``: riders on foot at ``t`` (meeting points,
``dispatch.decide.meeting``): from release to the boarding point (``walk_to_board_m`` at the walking
speed, until the pickup or the close if sooner) and from the alighting point after the
drop-off (``walk_from_alight_m``). The walking speed is the scenario's ``[tasks] walk_speed``
(default 1.4 m/s; a trace's per-row speeds are not in the results). :func:`counts_at`
computes them in Python (the tests compare the page with it).

Vehicles with driver shifts (``dispatch.fleet.shifts``) are also ``off_shift`` (not drawn) and
``to_depot`` (driving home): :mod:`analysis.replay_duty`.
"""

from __future__ import annotations

import base64
import hashlib
import html
import json
import logging
import math
import re
import time
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.replay_data import ReplayInputError, RunFiles, choose_run, read_table, transit_of
from analysis.replay_duty import DUTY_STATES, duty_spells, overlay
from analysis.timeline import FLEET_STATES, fleet_states

log = logging.getLogger(__name__)

#: task states that count as refused in the panel's ``rejected`` count
REFUSED_STATES = ("rejected", "expired")
#: the task state of a request the run's end cut off (the page and the report say "cut off")
CUT_OFF_STATE = "cut_off"
#: task states in the page's order (code = index; anything else: "open")
TASK_STATES = ("completed", "rejected", "expired", "unreachable", "cut_off", "failed",
               "declined", "open")
#: the riders' walking speed (m/s) where the scenario does not set ``[tasks] walk_speed``
WALK_SPEED = 1.4
#: the panel's counts (``data-kpi``), in its order
KPIS = ("waiting", "onboard", "delivered", "rejected", "declined", "cutoff", "booked", "walking")
#: vehicle events whose x, y, z are the vehicle's own position
POSITION_EVENTS = ("depart", "move", "wait", "pickup", "dropoff", "arrive", "complete", "idle",
                   "breakdown", "repair", "queue", "charge_start", "charge_end", "stranded",
                   "reassign", "insert", "break_start", "break_end")
#: event kinds the page can jump to (those the run has)
JUMP_EVENTS = ("release", "assign", "pickup", "dropoff", "reject", "expire", "reassign",
               "insert", "reposition", "queue", "charge_start", "breakdown", "repair",
               "stranded", "decline", "shift_start", "shift_end", "break_start")
ASSETS = "replay_assets"


# ----------------------------------------------------------------------------- counts
def _col(tasks: pd.DataFrame, name: str) -> np.ndarray:
    """A float column of the tasks table, all NaN where the run has none (older results)."""
    if name in tasks.columns:
        return tasks[name].to_numpy(dtype=float)
    return np.full(len(tasks), np.nan)


def walk_spells(tasks: pd.DataFrame, speed: float) -> tuple[np.ndarray, ...]:
    """(start, end) of each rider's walk to the boarding point and (start, end) of the walk
    from the alighting point, NaN where there is none (see the module docstring)."""
    rel, pick = _col(tasks, "released_at"), _col(tasks, "picked_up_at")
    close, done = _col(tasks, "closed_at"), _col(tasks, "completed_at")
    to, frm = _col(tasks, "walk_to_board_m"), _col(tasks, "walk_from_alight_m")
    with np.errstate(invalid="ignore"):
        stop = np.fmin(np.fmin(rel + to / speed, pick), close)
        s1 = np.where(to > 0, rel, np.nan)
        e1 = np.where(to > 0, stop, np.nan)
        s2 = np.where((frm > 0) & np.isfinite(done), done, np.nan)
        e2 = s2 + frm / speed
    return s1, e1, s2, e2


def counts_at(tasks: pd.DataFrame, t: float, walk_speed: float = WALK_SPEED) -> dict[str, int]:
    """The panel's counts (:data:`KPIS`) at time ``t`` from a run's tasks table (see the
    module docstring for their definitions)."""
    rel = tasks["released_at"].to_numpy(dtype=float)
    pick = tasks["picked_up_at"].to_numpy(dtype=float)
    done = tasks["completed_at"].to_numpy(dtype=float)
    close = tasks["closed_at"].to_numpy(dtype=float)
    booked = _col(tasks, "booked_at")
    s1, e1, s2, e2 = walk_spells(tasks, walk_speed)
    state = tasks["state"]
    with np.errstate(invalid="ignore"):
        picked = pick <= t
        closed = close <= t
        waiting = (rel <= t) & ~picked & ~closed
        onboard = picked & ~closed
        delivered = done <= t
        refused = state.isin(REFUSED_STATES).to_numpy() & closed
        walking = ((s1 <= t) & (t < e1)) | ((s2 <= t) & (t < e2))
        return {"waiting": int(waiting.sum()), "onboard": int(onboard.sum()),
                "delivered": int(delivered.sum()), "rejected": int(refused.sum()),
                "declined": int(((state == "declined").to_numpy() & closed).sum()),
                "cutoff": int(((state == CUT_OFF_STATE).to_numpy() & closed).sum()),
                "booked": int(((booked <= t) & ~picked & ~closed).sum()),
                "walking": int(walking.sum())}


def walk_speed_of(run: RunFiles) -> float:
    """The scenario's ``[tasks] walk_speed`` (m/s), else :data:`WALK_SPEED`."""
    try:
        import tomllib

        scen = tomllib.loads(run.metadata.get("dispatch.scenario", ""))
    except ValueError:
        return WALK_SPEED
    v = scen.get("tasks", {}).get("walk_speed", WALK_SPEED)
    return float(v) if isinstance(v, (int, float)) and v > 0 else WALK_SPEED


# ----------------------------------------------------------------------------- encoding
def _arr(a, dtype) -> dict:
    """A typed array for the page: ``{"t": dtype, "b": base64 of its little-endian bytes}``."""
    a = np.ascontiguousarray(np.asarray(a, dtype=np.dtype(dtype).newbyteorder("<")))
    return {"t": np.dtype(dtype).name, "b": base64.b64encode(a.tobytes()).decode("ascii")}


def _json_for_html(obj) -> str:
    """JSON that can sit inside a ``<script type="application/json">`` element: no ``<``,
    ``>`` or ``&`` (so no ``</script>``), no line separators JavaScript dislikes."""
    s = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    return (s.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
            .replace("\u2028", "\\u2028").replace("\u2029", "\\u2029"))


def _clean(v):
    """A JSON-safe scalar (NaN and inf as None)."""
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


# ----------------------------------------------------------------------------- the run
def _scenario_name(run: RunFiles, summary: pd.DataFrame) -> str:
    if len(summary) and "scenario" in summary.columns:
        return str(summary["scenario"].iloc[0])
    try:
        import tomllib

        return str(tomllib.loads(run.metadata.get("dispatch.scenario", "")).get("name", ""))
    except ValueError:
        return ""


#: at most this many keyframes from routing legs along the streets (else straight lines)
ROUTE_BUDGET = 2_000_000
#: a recorded position this close (metres) to a node is at that node
AT_NODE = 1.0


def route_keyframes(kf: pd.DataFrame, x: np.ndarray, y: np.ndarray, u: np.ndarray,
                    v: np.ndarray, seconds: np.ndarray,
                    budget: int = ROUTE_BUDGET) -> pd.DataFrame:
    """``kf`` (see :func:`keyframes`) with each drive between two nodes that are not
    neighbours replaced by the fastest path's nodes, timed in proportion to their free-flow
    seconds over the drive's recorded duration (a run records where a vehicle departs and
    arrives, not the streets between unless ``[output] edge_events``). Unchanged where the
    paths would add more than ``budget`` keyframes (then the page draws straight lines)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree

    n = len(x)
    if n == 0 or len(kf) < 2:
        return kf
    a = kf["agent_id"].to_numpy()
    t = kf["t"].to_numpy(dtype=float)
    pts = kf[["x", "y"]].to_numpy(dtype=float)
    dist, node = cKDTree(np.column_stack([x, y])).query(pts)
    at = dist <= AT_NODE
    legs = np.flatnonzero((a[1:] == a[:-1]) & at[1:] & at[:-1] & (node[1:] != node[:-1])
                          & (t[1:] > t[:-1]))
    graph = csr_matrix((seconds, (u, v)), shape=(n, n))
    adjacent = np.asarray(graph[node[legs], node[legs + 1]]).ravel() > 0
    legs = legs[~adjacent]
    if legs.size == 0:
        return kf
    if legs.size * max(2.0, np.sqrt(n)) > budget:  # a grid's mean path: ~sqrt(n) nodes
        log.info("%d drives: straight lines (routing them would exceed %d keyframes)",
                 legs.size, budget)
        return kf
    src = node[legs]
    uniq, inv = np.unique(src, return_inverse=True)
    add_t, add_x, add_y, add_a, added = [], [], [], [], 0
    for s in range(0, uniq.size, 256):
        dist_b, pred = dijkstra(graph, indices=uniq[s:s + 256], return_predecessors=True)
        for j in np.flatnonzero((inv >= s) & (inv < s + 256)):
            k, row = legs[j], inv[j] - s
            b = node[k + 1]
            if not np.isfinite(dist_b[row, b]):
                continue
            path = [b]
            while path[-1] != node[k] and len(path) <= n:
                path.append(pred[row, path[-1]])
            path = path[::-1]
            cum = dist_b[row, path]
            total = cum[-1]
            if total <= 0 or len(path) < 3:
                continue
            frac = cum[1:-1] / total
            add_t.append(t[k] + frac * (t[k + 1] - t[k]))
            add_x.append(x[path[1:-1]])
            add_y.append(y[path[1:-1]])
            add_a.append(np.full(len(path) - 2, a[k]))
            added += len(path) - 2
            if added > budget:
                log.info("routing past %d keyframes: straight lines", budget)
                return kf
    if not added:
        return kf
    extra = pd.DataFrame({"agent_id": np.concatenate(add_a), "t": np.concatenate(add_t),
                          "x": np.concatenate(add_x), "y": np.concatenate(add_y), "z": 0.0})
    out = pd.concat([kf.assign(o=0), extra.assign(o=1)], ignore_index=True)
    return (out.sort_values(["agent_id", "t", "o"], kind="stable")
            .drop(columns="o").reset_index(drop=True))


def _network(run: RunFiles):
    """(node x, y arrays, undirected edge index pairs, directed edges u, v, seconds) of a
    road run, or None."""
    rel = run.metadata.get("dispatch.output.space_files")
    if not rel:
        return None
    folder = run.root / rel
    nodes, edges = folder / "nodes.parquet", folder / "edges.parquet"
    if not (nodes.is_file() and edges.is_file()):
        log.warning("%s: the run's network is not there; the map has no streets", folder)
        return None
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        n = pq.read_table(nodes)
        e = pq.read_table(edges, columns=["u", "v", "seconds"])
    except (pa.ArrowInvalid, OSError) as err:
        raise ReplayInputError(f"{folder}: network files not readable "
                               f"({' '.join(str(err).split())})") from None
    u = e.column("u").to_numpy().astype(np.int64)
    v = e.column("v").to_numpy().astype(np.int64)
    a, b = np.minimum(u, v), np.maximum(u, v)
    pairs = np.unique(np.column_stack([a, b]), axis=0) if len(a) else np.zeros((0, 2), np.int64)
    return (n.column("x").to_numpy().astype(float), n.column("y").to_numpy().astype(float),
            pairs, u, v, e.column("seconds").to_numpy().astype(float))


def keyframes(events: pd.DataFrame, vehicles: pd.DataFrame) -> pd.DataFrame:
    """Every vehicle's known positions in time order: columns ``agent_id``, ``t``, ``x``,
    ``y``, ``z``, starting with its start position at 0. Rows in the middle of a run of equal
    positions (a vehicle standing) and repeated rows are left out: the page interpolates
    linearly between the rows kept, so what it draws is the same."""
    e = events.loc[(events["agent_id"] >= 0) & events["event"].isin(POSITION_EVENTS),
                   ["agent_id", "t", "x", "y", "z"]]
    start = pd.DataFrame({"agent_id": vehicles["agent_id"].astype(np.int64), "t": 0.0,
                          "x": vehicles["x0"].astype(float), "y": vehicles["y0"].astype(float),
                          "z": vehicles["z0"].astype(float)})
    k = pd.concat([start.assign(o=0), e.assign(o=1)], ignore_index=True)
    k = k.sort_values(["agent_id", "t", "o"], kind="stable").reset_index(drop=True)

    def same(k):
        a = k["agent_id"].to_numpy()
        xyz = k[["x", "y", "z"]].to_numpy(dtype=float)
        return (a[1:] == a[:-1]) & np.all(xyz[1:] == xyz[:-1], axis=1)

    if len(k) > 1:  # first repeated rows (same time and place), then standing still
        t = k["t"].to_numpy(dtype=float)
        dup = np.concatenate([[False], same(k) & (t[1:] == t[:-1])])
        k = k.loc[~dup].reset_index(drop=True)
    if len(k) > 2:
        eq = same(k)
        middle = np.concatenate([[False], eq[1:] & eq[:-1], [False]])
        k = k.loc[~middle]
    return k[["agent_id", "t", "x", "y", "z"]].reset_index(drop=True)


def _offsets(ids: np.ndarray, order: np.ndarray) -> np.ndarray:
    """CSR offsets (len(order) + 1) of rows grouped by ``ids`` (sorted) in vehicle ``order``."""
    starts = np.searchsorted(ids, order, side="left")
    ends = np.searchsorted(ids, order, side="right")
    if len(order) and not np.array_equal(starts[1:], ends[:-1]):
        raise ValueError("rows of vehicles outside the vehicles table")
    return np.concatenate([[0], ends]).astype(np.int32) if len(order) else np.zeros(1, np.int32)


def build_run(run: RunFiles, route: bool = True) -> dict:
    """The page's data of one run (a JSON-able dict; see the module docstring); ``route``:
    drives between recorded positions follow the fastest streets (:func:`route_keyframes`)."""
    summary = read_table(run, "summary")
    tasks = read_table(run, "tasks")
    vehicles = read_table(run, "vehicles")
    events = read_table(run, "events")
    if vehicles.empty:
        raise ReplayInputError(f"{run.root}: run {run.run_id} has no vehicles table")
    if events.empty:
        events = pd.DataFrame({"t": pd.Series(dtype=float), "event": pd.Series(dtype=str),
                               "agent_id": pd.Series(dtype=np.int64),
                               "task_id": pd.Series(dtype=np.int64),
                               **{c: pd.Series(dtype=float) for c in "xyz"}})
    space = run.metadata.get("dispatch.space", "road")
    vehicles = vehicles.sort_values("agent_id").reset_index(drop=True)
    vid = vehicles["agent_id"].to_numpy(dtype=np.int64)
    end = float(max(events["t"].max() if len(events) else 0.0,
                    np.nanmax(tasks["closed_at"]) if len(tasks) and
                    tasks["closed_at"].notna().any() else 0.0, 1.0))

    # positions
    kf = keyframes(events, vehicles)
    xs = [kf["x"].to_numpy(), vehicles["x0"].to_numpy(dtype=float)]
    ys = [kf["y"].to_numpy(), vehicles["y0"].to_numpy(dtype=float)]
    if len(tasks):
        xs += [tasks["x"].to_numpy(dtype=float), tasks["dropoff_x"].to_numpy(dtype=float)]
        ys += [tasks["y"].to_numpy(dtype=float), tasks["dropoff_y"].to_numpy(dtype=float)]
    net = _network(run) if space == "road" else None
    if net is not None and route:
        kf = route_keyframes(kf, net[0], net[1], *net[3:])
    if net is not None:
        xs.append(net[0])
        ys.append(net[1])
    allx, ally = np.concatenate(xs), np.concatenate(ys)
    allx, ally = allx[np.isfinite(allx)], ally[np.isfinite(ally)]
    if space == "voxel":
        size = json.loads(run.metadata.get("dispatch.world_size", "[0, 0, 0]"))
        bounds = [0.0, 0.0, float(size[0]), float(size[1])]
    else:
        bounds = [float(allx.min()), float(ally.min()), float(allx.max()), float(ally.max())]
    ox, oy = bounds[0], bounds[1]  # positions relative to the corner: float32 keeps cm

    # fleet states (the analysis' own definitions: analysis.timeline)
    riders = (dict(zip(tasks["task_id"].astype(int), tasks["passengers"].fillna(1).astype(int)))
              if len(tasks) and "passengers" in tasks.columns else None)
    # (at_end: the last frame shows the state a vehicle ended in, e.g. idle after its last
    # task completed at the run's last instant, not "at its task" with nothing left)
    st = fleet_states(events.assign(run_id=run.run_id), vehicles.assign(run_id=run.run_id),
                      end=end, passengers=riders, at_end=True)
    st = st.sort_values(["agent_id", "start"], kind="stable")
    st = overlay(st, duty_spells(events, vehicles, end))
    states = (*FLEET_STATES, *DUTY_STATES)
    code = {s: i for i, s in enumerate(states)}

    kinds = sorted(vehicles["kind"].astype(str).unique()) if "kind" in vehicles else ["vehicle"]
    veh = {
        "id": _arr(vid, np.int32),
        "kindNames": kinds,
        "kind": _arr(vehicles["kind"].astype(str).map({k: i for i, k in enumerate(kinds)}),
                     np.uint8),
        "cap": _arr(vehicles["capacity"].fillna(1) if "capacity" in vehicles else
                    np.ones(len(vid)), np.int32),
        "kfOff": _arr(_offsets(kf["agent_id"].to_numpy(), vid), np.int32),
        "kfT": _arr(kf["t"], np.float64),
        "kfX": _arr(kf["x"] - ox, np.float32),
        "kfY": _arr(kf["y"] - oy, np.float32),
        "kfZ": _arr(kf["z"], np.float32),
        "stOff": _arr(_offsets(st["agent_id"].to_numpy(), vid), np.int32),
        "stT": _arr(st["start"], np.float64),
        "stCode": _arr(st["state"].map(code), np.uint8),
        "stOn": _arr(np.minimum(st["onboard"], 255), np.uint8),
    }

    # tasks
    if len(tasks):
        tasks = tasks.sort_values("released_at", kind="stable").reset_index(drop=True)
        sc = {s: i for i, s in enumerate(TASK_STATES)}
        tk = {
            "id": _arr(tasks["task_id"], np.int32),
            "x": _arr(tasks["x"] - ox, np.float32), "y": _arr(tasks["y"] - oy, np.float32),
            "dx": _arr(tasks["dropoff_x"] - ox, np.float32),
            "dy": _arr(tasks["dropoff_y"] - oy, np.float32),
            "rel": _arr(tasks["released_at"], np.float64),
            "asg": _arr(tasks["assigned_at"], np.float64),
            "pick": _arr(tasks["picked_up_at"], np.float64),
            "done": _arr(tasks["completed_at"], np.float64),
            "close": _arr(tasks["closed_at"], np.float64),
            "state": _arr(tasks["state"].map(lambda s: sc.get(s, sc["open"])), np.uint8),
            "agent": _arr(tasks["agent_id"].fillna(-1), np.int32),
            "pax": _arr(tasks["passengers"].fillna(1) if "passengers" in tasks else
                        np.ones(len(tasks)), np.uint8),
            "kind": sorted(tasks["kind"].astype(str).unique()),
        }
        tk["kindCode"] = _arr(tasks["kind"].astype(str).map(
            {k: i for i, k in enumerate(tk["kind"])}), np.uint8)
        # prebooking, offers, meeting points (absent columns: none of them)
        booked = _col(tasks, "booked_at")
        walk_to, walk_from = _col(tasks, "walk_to_board_m"), _col(tasks, "walk_from_alight_m")
        walks = bool(np.nansum(walk_to) + np.nansum(walk_from) > 0)
        tk["features"] = {
            "booked": bool(np.isfinite(booked).any()),
            "offers": bool(np.nansum(_col(tasks, "offers")) > 0
                           or (tasks["state"] == "declined").any()),
            "walks": walks}
        if tk["features"]["booked"]:
            tk["bk"] = _arr(booked, np.float64)
            tk["promised"] = _arr(tasks["promised"].fillna(False).astype(bool)
                                  if "promised" in tasks else np.zeros(len(tasks)), np.uint8)
        if walks:
            tk["walkSpeed"] = walk_speed_of(run)
            tk["wTo"] = _arr(np.nan_to_num(walk_to), np.float32)
            tk["wFrom"] = _arr(np.nan_to_num(walk_from), np.float32)
            for key, col, o in (("bx", "board_x", ox), ("by", "board_y", oy),
                                ("ax", "alight_x", ox), ("ay", "alight_y", oy)):
                tk[key] = _arr(_col(tasks, col) - o, np.float32)
    else:
        tk = None

    # jumps: times of the events of each kind the run has
    jumps = {}
    for kind in JUMP_EVENTS:
        ts = np.sort(events.loc[events["event"] == kind, "t"].to_numpy(dtype=float))
        if ts.size:
            jumps[kind] = _arr(np.unique(ts), np.float64)

    # decisions concerning each vehicle: the assignments it won (decision time, task, cost)
    wins = read_table(run, "assignments", won_only=True)
    decisions = read_table(run, "decisions")
    dec = None
    if len(wins) and len(decisions):
        when = dict(zip(decisions["decision"].astype(int), decisions["t"].astype(float)))
        wins = wins.assign(t=wins["decision"].astype(int).map(when)).sort_values(
            ["agent_id", "t"], kind="stable")
        dec = {"off": _arr(_offsets(wins["agent_id"].to_numpy(), vid), np.int32),
               "t": _arr(wins["t"].fillna(-1), np.float64),
               "task": _arr(wins["task_id"], np.int32),
               "cost": _arr(wins["cost"].replace([np.inf, -np.inf], np.nan), np.float32),
               "n": int(len(decisions))}

    # state of charge: each vehicle's samples (0-255; 255: none) and the fleet's quantiles
    soc = read_table(run, "soc")
    socd = None
    if len(soc):
        piv = soc.pivot_table(index="t", columns="agent_id", values="soc", aggfunc="last")
        piv = piv.reindex(columns=vid)
        m = piv.to_numpy(dtype=float)
        q = np.nanquantile(m, [0.1, 0.5, 0.9], axis=1) if m.size else np.zeros((3, 0))
        enc = np.where(np.isfinite(m), np.clip(np.round(m * 250), 0, 250), 255)
        socd = {"t": _arr(piv.index.to_numpy(dtype=float), np.float64),
                "p10": _arr(q[0], np.float32), "p50": _arr(q[1], np.float32),
                "p90": _arr(q[2], np.float32), "v": _arr(enc, np.uint8)}

    chargers = read_table(run, "chargers")
    stations = None
    if len(chargers):
        stations = {"id": [str(s) for s in chargers["station_id"]],
                    "x": _arr(chargers["x"] - ox, np.float32),
                    "y": _arr(chargers["y"] - oy, np.float32),
                    "plugs": _arr(chargers["plugs"], np.int32)}

    obstacles = None
    if space == "voxel":
        ob = read_table(run, "obstacles")
        if len(ob):
            obstacles = {c: _arr(ob[c], np.float32) for c in ("x0", "y0", "z0", "x1", "y1", "z1")}

    s0 = summary.iloc[0] if len(summary) else pd.Series(dtype=object)
    info = {k: _clean(s0[k]) for k in ("allocator", "planner", "n_agents", "seed",
                                         "batch_window", "reposition") if k in s0.index}
    return {
        "runId": run.run_id, "scenario": _scenario_name(run, summary), "info": info,
        "writer": run.metadata.get("dispatch.version", ""), "space": space,
        "t0": 0.0, "t1": end, "bounds": [0.0, 0.0, bounds[2] - ox, bounds[3] - oy],
        "origin": [ox, oy], "crs": run.metadata.get("dispatch.crs"),
        "worldZ": (json.loads(run.metadata.get("dispatch.world_size", "[0,0,1]"))[2]
                   if space == "voxel" else None),
        "net": None if net is None else {"x": _arr(net[0] - ox, np.float32),
                                         "y": _arr(net[1] - oy, np.float32),
                                         "e": _arr(net[2].ravel(), np.int32)},
        "obstacles": obstacles, "vehicles": veh, "tasks": tk, "jumps": jumps,
        "decisions": dec, "soc": socd, "stations": stations,
        "transit": transit_of(read_table(run, "legs"), ox, oy, _arr),
        "fleetStates": list(states), "taskStates": list(TASK_STATES),
        "refused": list(REFUSED_STATES), "cutOff": CUT_OFF_STATE,
    }


# ----------------------------------------------------------------------------- the page
def _asset(name: str) -> str:
    return resources.files("analysis").joinpath(ASSETS, name).read_text(encoding="utf-8")


def project_version() -> str:
    """The installed project's version (``dispatch-sim``), else ``unknown``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("dispatch-sim")
    except PackageNotFoundError:
        return "unknown"


def page(runs: list[dict]) -> str:
    """The HTML page of one or two runs' data (see :func:`build_run`)."""
    js, css = _asset("replay.js"), _asset("replay.css")
    data = _json_for_html({"version": project_version(), "runs": runs})

    def sha(s: str) -> str:
        return "'sha256-" + base64.b64encode(hashlib.sha256(s.encode()).digest()).decode() + "'"

    csp = (f"default-src 'none'; script-src {sha(js)}; style-src {sha(css)}; "
           "img-src data: blob:; connect-src 'none'; font-src 'none'; base-uri 'none'; "
           "form-action 'none'")
    parts = {"CSP": csp, "TITLE": "dispatch replay", "CSS": css, "DATA": data, "JS": js,
             "GENERATOR": html.escape(f"dispatch {project_version()} (dispatch replay)"),
             "RUNIDS": html.escape(" ".join(r["runId"] for r in runs))}
    # one pass: text put in is never searched again (a scenario named "{{JS}}" stays text)
    return re.sub(r"\{\{([A-Z]+)\}\}", lambda m: parts[m.group(1)], _asset("replay.html"))


def write_replay(folder: str | Path, out: str | Path | None = None, *,
                 run_id: str | None = None, compare: str | Path | None = None,
                 compare_run: str | None = None) -> Path:
    """Write the replay page of the run ``run_id`` of ``folder`` (its only run by default),
    beside another folder's run with ``compare``; returns the page's path (default:
    ``folder/replay.html``)."""
    t = time.perf_counter()
    runs = [build_run(choose_run(folder, run_id))]
    if compare is not None:
        runs.append(build_run(choose_run(compare, compare_run)))
    path = Path(out) if out is not None else Path(folder) / "replay.html"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(page(runs), encoding="utf-8")
    tmp.replace(path)
    log.info("replay written in %.1f s: %s", time.perf_counter() - t, path)
    return path
