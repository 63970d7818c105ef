"""``benchmarks/peers.py``'s runner for SUMO's taxi device (run by ``benchmarks/.peers-venv``).

``python benchmarks/peers_sumo.py WORKLOAD_DIR OUT.json [instant]`` (``instant``: the same
with taxis that accelerate and brake within one step, to measure what acceleration costs).

* Net: ``netgenerate --grid`` with the workload's intersections and block, one lane per
  direction at ``speed`` m/s, junctions ``unregulated`` (no traffic lights, no right of way:
  nobody brakes for anybody at a junction) and no internal links (a junction is crossed without
  an internal lane, so no turn-speed limits; each lane is exactly ``block`` metres long).
* Taxis: ``personCapacity 1``; ``sigma 0`` and ``speedFactor 1`` (no dawdling, drive at the
  limit); SUMO's default car-following (Krauss: accelerate 2.6 m/s², brake 4.5 m/s²), so every
  stop costs time the project's constant-speed model does not have. Pick-up, drop-off and
  boarding durations 0 (SUMO's drop-off default is 60 s); stops park off the lane (SUMO's taxi
  default), so nobody queues behind a taxi. A taxi starts standing at the end of an edge into its
  start intersection (free to leave it in any direction, U-turn included).
* Requests: one person per trip, ``<ride lines="taxi">``, departing at the release time (SUMO
  steps are 1 s: a release at 12.3 s is seen at 13 s). The person waits 5 m (a car length) into
  the first edge of a shortest path from its origin towards its destination, and is dropped at
  the end of the last edge of such a path, so no leg needs a detour round a block; the taxi to
  it only needs to reach the origin intersection.
* Dispatch: ``--device.taxi.dispatch-algorithm greedy`` every ``--device.taxi.dispatch-period
  1`` s; idle taxis stop where they are.

Wall time: the ``sumo`` process (it reads the net and the routes and simulates to the end);
the net and route files are written before the clock starts. Waits: boarding time (the ride's
``depart``) minus the exact release time. Vehicle km: the taxis' ``routeLength`` (tripinfo,
unfinished taxis included). Peak RSS: the ``sumo`` child's.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from peers_workload import Workload, metrics, read, save_pickups

BIN = Path(sys.executable).parent


def build_net(w: Workload, folder: Path) -> Path:
    """The grid as a SUMO net (``netgenerate``); returns its path."""
    net = folder / "grid.net.xml"
    subprocess.run([str(BIN / "netgenerate"), "--grid", "--grid.x-number", str(w.columns),
                    "--grid.y-number", str(w.rows), "--grid.length", str(w.block),
                    "--default.lanenumber", "1", "--default.speed", str(w.speed),
                    "--default.junctions.type", "unregulated", "--no-internal-links",
                    "--output-file", str(net)], check=True, capture_output=True)
    return net


def edge_table(w: Workload, net: Path) -> dict[tuple[int, int], str]:
    """``(from_node, to_node) -> edge id`` in the project's node numbering (junction at
    ``(column, row) * block``)."""
    node = {}
    edges = {}
    for _, el in ET.iterparse(net):
        if el.tag == "junction" and el.get("type") != "internal":
            c, r = round(float(el.get("x")) / w.block), round(float(el.get("y")) / w.block)
            node[el.get("id")] = r * w.columns + c
        elif el.tag == "edge" and el.get("function") != "internal":
            edges[el.get("id")] = (el.get("from"), el.get("to"))
    return {(node[a], node[b]): e for e, (a, b) in edges.items()}


def first_last_edges(w: Workload, o: int, d: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The first and the last edge (as node pairs) of one monotone shortest path o -> d:
    first along x when the columns differ, last along y when the rows differ."""
    (oc, orow), (dc, drow) = w.node_xy(o), w.node_xy(d)
    oc, orow, dc, drow = int(oc), int(orow), int(dc), int(drow)
    step_c, step_r = int(np.sign(dc - oc)), int(np.sign(drow - orow))
    first = o + step_c if step_c else o + step_r * w.columns
    last = d - step_r * w.columns if step_r else d - step_c
    return (o, first), (last, d)


def write_routes(w: Workload, t, origin, dest, start, edges, folder: Path,
                 instant: bool = False) -> Path:
    """Taxis and persons, sorted by departure, as SUMO routes (``instant``: taxis accelerate
    and brake at 1000 m/s², i.e. within one step, to measure what acceleration costs)."""
    into = {}
    for (a, b), e in sorted(edges.items()):
        into.setdefault(b, e)
    path = folder / ("taxis_instant.rou.xml" if instant else "taxis.rou.xml")
    with open(path, "w") as fh:
        kinematics = ('accel="1000" decel="1000" emergencyDecel="1000" ' if instant else "")
        fh.write('<routes>\n  <vType id="taxi" vClass="taxi" personCapacity="1" sigma="0" '
                 f'{kinematics}speedFactor="1" speedDev="0" boardingDuration="0">\n'
                 '    <param key="has.taxi.device" value="true"/>\n'
                 '    <param key="device.taxi.pickUpDuration" value="0"/>\n'
                 '    <param key="device.taxi.dropOffDuration" value="0"/>\n  </vType>\n')
        fh.writelines(f'  <vehicle id="taxi{i}" type="taxi" depart="0" line="taxi" '
                     f'departPos="{w.block}" departSpeed="0"><route edges="{into[s]}"/>'
                     f'<stop lane="{into[s]}_0" endPos="{w.block}" triggered="person" '
                     f'parking="true"/></vehicle>\n' for i, s in enumerate(start.tolist()))
        for i, (ti, o, d) in enumerate(zip(t.tolist(), origin.tolist(), dest.tolist())):
            first, last = first_last_edges(w, o, d)
            fh.write(f'  <person id="p{i}" depart="{ti:.3f}" departPos="5">'
                     f'<ride from="{edges[first]}" to="{edges[last]}" arrivalPos="{w.block}" '
                     f'lines="taxi"/></person>\n')
        fh.write("</routes>\n")
    return path


def stop_lags(stops: Path, t: np.ndarray) -> dict:
    """From SUMO's stop output, two costs per pick-up the project's model does not have:
    ``lag_leave``: release -> the dispatched taxi leaves the stop it idled at (the release seen
    at the next step, the dispatch step, the stop left at a step), over the pick-ups whose taxi
    was already standing there at the release; ``lag_board``: the taxi
    reaches the pick-up stop -> the person is on board (boarding happens at the next step)."""
    last: dict[str, tuple[float, float]] = {}
    leave, board = [], []
    for _, el in ET.iterparse(stops):
        if el.tag != "stopinfo":
            continue
        taxi, act = el.get("id"), el.get("actType", "")
        started, ended = float(el.get("started")), float(el.get("ended", "-1"))
        if act.startswith("pickup") and taxi in last:
            person = int(act.split()[1][1:])
            if last[taxi][0] <= t[person]:
                leave.append(last[taxi][1] - t[person])
            if ended >= 0:
                board.append(ended - started)
        last[taxi] = (started, ended)
        el.clear()
    return {"lag_leave": float(np.mean(leave)) if leave else float("nan"),
            "lag_board": float(np.mean(board)) if board else float("nan")}


def _child_cpu() -> float:
    """CPU seconds (user + system) of the finished children of this process."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main(folder: Path, out: Path, variant: str = "") -> None:
    w, t, origin, dest, start = read(folder)
    net = build_net(w, folder)
    routes = write_routes(w, t, origin, dest, start, edge_table(w, net), folder,
                          instant=variant == "instant")
    tripinfo = folder / f"sumo{variant}_tripinfo.xml"
    stops = folder / f"sumo{variant}_stops.xml"
    cmd = [str(BIN / "sumo"), "-n", str(net), "-r", str(routes), "--end", str(w.end),
           "--device.taxi.dispatch-algorithm", "greedy", "--device.taxi.dispatch-period", "1",
           "--device.taxi.idle-algorithm", "stop", "--tripinfo-output", str(tripinfo),
           "--tripinfo-output.write-unfinished", "--stop-output", str(stops), "--seed", str(w.seed % 2**31),
           "--no-step-log", "--no-warnings", "--duration-log.disable"]
    env = dict(os.environ, SUMO_HOME=str(Path(sys.executable).parents[1] / "lib" /
                                         f"python{sys.version_info[0]}.{sys.version_info[1]}" /
                                         "site-packages" / "sumo"))
    t0, c0 = time.perf_counter(), _child_cpu()
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    wall, cpu = time.perf_counter() - t0, _child_cpu() - c0

    picked = np.full(t.size, np.nan)
    completed = np.full(t.size, np.nan)
    vehicle = np.full(t.size, -1)
    metres = 0.0
    for _, el in ET.iterparse(tripinfo):
        if el.tag == "personinfo":
            i = int(el.get("id")[1:])
            ride = el.find("ride")
            if ride is not None and float(ride.get("depart", -1)) >= 0:
                picked[i] = float(ride.get("depart"))
                vehicle[i] = int(ride.get("vehicle")[len("taxi"):])
                if float(ride.get("arrival", -1)) >= 0:
                    completed[i] = float(ride.get("arrival"))
            el.clear()
        elif el.tag == "tripinfo":
            metres += float(el.get("routeLength"))
            el.clear()
    row = metrics(t, picked, completed, metres)
    row.update(wall_s=wall, cpu_s=cpu,
               rss_mb=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)
    row.update(stop_lags(stops, t))
    save_pickups(out.with_suffix(".npz"), t, picked, vehicle)
    out.write_text(json.dumps(row))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), *sys.argv[3:])
