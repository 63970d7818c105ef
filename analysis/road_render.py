"""Animating a road (taxi) run on its map with matplotlib (Agg), no PyBullet.

The streets (rebuilt from the run's metadata by :mod:`analysis.network`; left out where that is
not possible) are drawn once; each frame then draws, over a saved copy of them, the vehicles
coloured by fleet state (:func:`analysis.timeline.fleet_states`: idle, driving to a pickup,
with a passenger, repositioning, broken down) and the requests waiting for a vehicle. A
vehicle's position is interpolated in a straight line between the places the events give
(departure, pickup, drop-off; with ``[world] edge_events = true`` every node it passes, so it
follows the streets).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.taxi_plots import FLEET_COLOURS, FLEET_LABELS
from analysis.timeline import FLEET_STATES, fleet_states, positions_at, trajectories


def _clock(t: float) -> str:
    t = round(t)
    return f"{t // 3600:02d}:{t // 60 % 60:02d}:{t % 60:02d}"


def road_frames(run: dict, network, *, end: float, n_frames: int, size: tuple[int, int],
                title: str) -> list:
    """The frames (PIL images of ``size`` pixels) of one road run (``run``: its tables, as
    :meth:`analysis.io.Results.run` gives them) from t = 0 to ``end``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from PIL import Image

    events, vehicles, tasks = run["events"], run["vehicles"], run["tasks"]
    dpi = 100
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.01, 0.01, 0.98, 0.86))
    pts = [vehicles[["x0", "y0"]].to_numpy(dtype=float), tasks[["x", "y"]].to_numpy(dtype=float)]
    if network is not None:
        pts.append(network.xy)
        segs = np.stack([network.xy[network.edges[:, 0]], network.xy[network.edges[:, 1]]], axis=1)
        ax.add_collection(LineCollection(segs, colors="0.75",
                                         linewidths=0.3 if len(segs) > 5000 else 0.7))
    allxy = np.vstack([p for p in pts if len(p)]) if any(len(p) for p in pts) else np.zeros((1, 2))
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    pad = 0.03 * float(max(hi - lo) or 1.0)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    small = max(6.0, size[0] / 80)
    handles = [Line2D([], [], marker="o", linestyle="", color=FLEET_COLOURS[s],
                      label=FLEET_LABELS[s]) for s in FLEET_STATES if s != "idle"]
    handles = [Line2D([], [], marker="o", linestyle="", color="#7f7f7f", label="idle"),
               *handles, Line2D([], [], marker="x", linestyle="", color="black",
                                label="request waiting")]
    fig.legend(handles=handles, loc="upper center", ncol=3, fontsize=small * 0.85,
               frameon=False, bbox_to_anchor=(0.5, 0.955), handletextpad=0.2, columnspacing=0.8)
    head = fig.text(0.01, 0.995, "", va="top", fontsize=small, family="monospace")
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)

    traj = trajectories(events, vehicles)
    agents = sorted(traj)
    states = fleet_states(events.assign(run_id="r"), vehicles.assign(run_id="r"), end=end)
    s_agent = states["agent_id"].to_numpy()
    s_start, s_end = states["start"].to_numpy(dtype=float), states["end"].to_numpy(dtype=float)
    s_state = states["state"].to_numpy()
    colour = {**FLEET_COLOURS, "idle": "#7f7f7f"}
    released = tasks["released_at"].to_numpy(dtype=float)
    gone = np.fmin(tasks["picked_up_at"].to_numpy(dtype=float),
                   tasks["closed_at"].to_numpy(dtype=float))
    gone = np.where(np.isnan(gone), np.inf, gone)
    txy = tasks[["x", "y"]].to_numpy(dtype=float)
    marker = max(4.0, min(30.0, 4000.0 / max(len(agents), 1)))
    cars = ax.scatter(np.zeros(len(agents)), np.zeros(len(agents)), s=marker, zorder=3,
                      edgecolor="black", linewidth=0.2)
    waiting = ax.scatter([], [], marker="x", s=marker * 0.8, color="black", linewidth=0.8,
                         zorder=4)
    frames = []
    for k in range(n_frames):
        t = end * k / max(n_frames - 1, 1)
        pos = positions_at(traj, t)
        xy = np.array([pos[a][:2] for a in agents]) if agents else np.zeros((0, 2))
        now = (s_start <= t) & ((t < s_end) | ((t == end) & (s_end == end)))
        by_agent = dict(zip(s_agent[now], s_state[now]))
        cars.set_offsets(xy)
        cars.set_facecolor([colour[by_agent.get(a, "idle")] for a in agents])
        open_now = (released <= t) & (t < gone)
        waiting.set_offsets(txy[open_now] if open_now.any() else np.zeros((0, 2)))
        counts = pd.Series(list(by_agent.values())).value_counts()
        busy = counts.get("to_pickup", 0) + counts.get("occupied", 0)
        head.set_text(f"{title}   {_clock(t)}   busy {busy}/{len(agents)}   "
                      f"waiting {int(open_now.sum())}")
        canvas.restore_region(background)
        ax.draw_artist(cars)
        ax.draw_artist(waiting)
        fig.draw_artist(head)
        rgba = np.asarray(canvas.buffer_rgba())
        frames.append(Image.fromarray(rgba[:, :, :3].copy()))
    return frames
