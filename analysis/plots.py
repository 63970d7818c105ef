"""The report's figures, drawn with matplotlib's object API on the Agg canvas.

Each function takes DataFrames (from :mod:`analysis.metrics` / :mod:`analysis.timeline`),
writes one PNG and returns its path. No pyplot: nothing here touches the global backend, so
the functions are safe to call from a notebook or a server. matplotlib is imported inside the
functions, so importing this module costs nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from paired.compare import allocator_order
from analysis.timeline import STATES, trajectories, vehicle_intervals

DPI = 120
STATE_COLOURS = {"travel": "#1f77b4", "service": "#2ca02c", "waiting": "#ff7f0e",
                 "reposition": "#9edae5", "idle": "#d9d9d9", "down": "#d62728"}
MARKERS = ("o", "s", "^", "D", "v", "P", "X")
TASK_COLOURS = {"completed": "#2ca02c", "expired": "#d62728", "unreachable": "#7f7f7f",
                "cut_off": "#9467bd", "rejected": "#ff7f0e", "failed": "#8c564b"}
#: How a legend names a task state: the state ``cut_off`` is a task the run's end cut off.
TASK_LABELS = {"cut_off": "cut off by the end"}


def _figure(w: float = 6.4, h: float = 4.2):
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), dpi=DPI, layout="constrained")


def _save(fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=DPI)
    tmp.replace(path)
    return path


def _colours(names) -> dict:
    """A colour per name, none used twice: tab10 up to 10 names, tab20 up to 20, past that
    evenly spaced along a perceptually ordered map (turbo). Figures with many series draw
    small multiples instead (:mod:`analysis.taxi_plots`), where colours stay few."""
    from matplotlib import colormaps

    names = list(names)
    if len(names) > 20:
        cmap = colormaps["turbo"]
        return {n: cmap(0.05 + 0.9 * i / (len(names) - 1)) for i, n in enumerate(names)}
    cmap = colormaps["tab10" if len(names) <= 10 else "tab20"]
    return {n: cmap(i % cmap.N) for i, n in enumerate(names)}


def _series(df: pd.DataFrame):
    """(label, rows sorted by N) per line: an allocator, plus scenario / planner when the
    results hold more than one of them."""
    multi = [k for k in ("scenario", "planner") if k in df and df[k].nunique() > 1]
    order = allocator_order(df["allocator"].unique())
    colours = _colours(order)
    for a, alloc in enumerate(order):
        sub = df.loc[df["allocator"] == alloc]
        groups = sub.groupby(multi, sort=True) if multi else [((), sub)]
        for i, (key, g) in enumerate(groups):
            key = key if isinstance(key, tuple) else (key,)
            label = alloc + (f" ({', '.join(map(str, key))})" if multi else "")
            # a marker per allocator too, so that lines lying on each other stay visible
            yield (label, g.sort_values("n_agents"), colours[alloc],
                   ("-", "--", ":", "-.")[i % 4], MARKERS[a % len(MARKERS)])


def metric_vs_n(metrics: pd.DataFrame, column: str, path: Path, *, ylabel: str, title: str,
                ci: str | None = None, log: bool = False, scale: float = 1.0,
                ylim: tuple[float, float] | None = None) -> Path:
    """One line per allocator of ``column`` against N, with ``ci`` as error bars."""
    fig = _figure()
    ax = fig.add_subplot()
    for k, (label, g, colour, style, marker) in enumerate(_series(metrics)):
        y = g[column].to_numpy(dtype=float) * scale
        err = g[ci].to_numpy(dtype=float) * scale if ci else None
        if err is not None:
            err = np.where(np.isfinite(err), err, 0.0)
            if log:  # a log axis cannot show a bar below zero: clip the lower half
                err = np.vstack([np.minimum(err, 0.9 * y), err])
        ax.errorbar(g["n_agents"], y, yerr=err, label=label, color=colour, linestyle=style,
                    marker=marker, markersize=7 - min(k, 3), capsize=3, linewidth=1.5,
                    markerfacecolor="none" if k % 2 else colour)
    ns = sorted(metrics["n_agents"].unique())
    ax.set_xticks(ns)
    ax.set_xlabel("fleet size N (agents)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if log:
        from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullFormatter

        ax.set_yscale("log")
        lo, hi = ax.get_ylim()
        plain = FuncFormatter(lambda v, _: f"{v:g}")
        if hi / lo < 10:  # less than a decade: evenly spaced round values read better
            ticks = [v for v in MaxNLocator(nbins=6).tick_values(lo, hi) if lo <= v <= hi]
            ax.yaxis.set_major_locator(FixedLocator(ticks))
            ax.yaxis.set_minor_formatter(NullFormatter())
        else:
            ax.yaxis.set_minor_formatter(FuncFormatter(
                lambda v, _: f"{v:g}" if f"{v:.1e}"[0] in "25" else ""))
        ax.yaxis.set_major_formatter(plain)
    if ylim:
        ax.set_ylim(*ylim)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    return _save(fig, path)


def cost_vs_n(metrics: pd.DataFrame, path: Path) -> Path:
    return metric_vs_n(metrics, "total_cost_mean", path, ci="total_cost_ci95",
                       ylabel="total travel cost (s)",
                       title="Total travel cost vs N (mean, 95 % CI over seeds)")


def success_vs_n(metrics: pd.DataFrame, path: Path) -> Path:
    return metric_vs_n(metrics, "conflict_free_rate_mean", path, ci="conflict_free_rate_ci95",
                       scale=100, ylim=(-2, 105), ylabel="conflict-free success rate (%)",
                       title="Conflict-free success rate vs N (mean, 95 % CI)")


def alloc_time_vs_n(metrics: pd.DataFrame, path: Path) -> Path:
    return metric_vs_n(metrics, "alloc_seconds_mean", path, ci="alloc_seconds_ci95", log=True,
                       scale=1000, ylabel="allocation time (ms, log scale)",
                       title="Allocation time of the first decision vs N")


def wait_distribution(waits: pd.DataFrame, path: Path) -> Path:
    """Left: the empirical CDF of wait times (release -> pickup) per allocator, all N pooled;
    right: box plots per allocator and N."""
    fig = _figure(10, 4.2)
    left, right = fig.subplots(1, 2)
    order = allocator_order(waits["allocator"].unique()) if len(waits) else []
    colours = _colours(order)
    for alloc in order:
        w = np.sort(waits.loc[waits["allocator"] == alloc, "wait"].to_numpy(dtype=float))
        if len(w):
            left.step(w, np.arange(1, len(w) + 1) / len(w), where="post", label=alloc,
                      color=colours[alloc])
    left.set_xlabel("wait time: release → pickup (s)")
    left.set_ylabel("share of tasks")
    left.set_title("Wait-time distribution (ECDF)")
    left.grid(True, alpha=0.3)
    if order:
        left.legend(fontsize="small")
    ns = sorted(waits["n_agents"].unique()) if len(waits) else []
    width = 0.8 / max(len(order), 1)
    for i, alloc in enumerate(order):
        data = [waits.loc[(waits["allocator"] == alloc) & (waits["n_agents"] == n), "wait"]
                .to_numpy(dtype=float) for n in ns]
        pos = [j + (i - (len(order) - 1) / 2) * width for j in range(len(ns))]
        keep = [k for k, d in enumerate(data) if len(d)]
        if not keep:
            continue
        bp = right.boxplot([data[k] for k in keep], positions=[pos[k] for k in keep],
                           widths=width * 0.9, patch_artist=True, showfliers=False,
                           manage_ticks=False)
        for box in bp["boxes"]:
            box.set_facecolor(colours[alloc])
            box.set_alpha(0.6)
        for med in bp["medians"]:
            med.set_color("black")
    right.set_xticks(range(len(ns)), [str(n) for n in ns])
    right.set_xlabel("fleet size N")
    right.set_ylabel("wait time (s)")
    right.set_title("Wait time per allocator and N (box: quartiles)")
    right.grid(True, axis="y", alpha=0.3)
    return _save(fig, path)


def gantt(events: pd.DataFrame, vehicles: pd.DataFrame, path: Path, title: str = "",
          end: float | None = None) -> Path:
    """A vehicle timeline: one row per vehicle, travel / service / waiting / idle bars."""
    iv = vehicle_intervals(events, vehicles, end)
    n = len(vehicles)
    fig = _figure(10, max(2.5, 0.9 + 0.32 * n))
    ax = fig.add_subplot()
    kinds = dict(zip(vehicles["agent_id"].astype(int), vehicles["kind"]))
    for row, agent in enumerate(sorted(kinds)):
        mine = iv.loc[iv["agent_id"] == agent]
        for state in STATES:
            seg = mine.loc[mine["state"] == state]
            if len(seg):
                ax.broken_barh(list(zip(seg["start"], seg["end"] - seg["start"])),
                               (row - 0.4, 0.8), facecolors=STATE_COLOURS[state])
    ax.set_yticks(range(len(kinds)), [f"{a} {kinds[a]}" for a in sorted(kinds)],
                  fontsize="small")
    ax.set_ylim(-0.6, len(kinds) - 0.4)
    ax.invert_yaxis()
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("vehicle")
    ax.set_title(title or "Vehicle timeline")
    ax.grid(True, axis="x", alpha=0.3)
    from matplotlib.patches import Patch

    busy = {"travel": "busy: travelling", "service": "busy: serving", "waiting": "waiting",
            "reposition": "idle: repositioning", "idle": "idle", "down": "broken down"}
    shown = [s for s in STATES if s != "reposition" or (iv["state"] == s).any()]
    fig.legend(handles=[Patch(color=STATE_COLOURS[s], label=busy[s]) for s in shown],
               loc="outside lower center", ncol=len(shown), fontsize="small", frameon=False)
    return _save(fig, path)


def _box_faces(b) -> list[list[tuple[float, float, float]]]:
    x0, y0, z0, x1, y1, z1 = b
    c = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    idx = [(0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 3, 7, 4)]
    return [[c[i] for i in f] for f in idx]


def paths_3d(events: pd.DataFrame, vehicles: pd.DataFrame, obstacles: pd.DataFrame,
             tasks: pd.DataFrame, path: Path, world: tuple[float, float, float] | None = None,
             title: str = "") -> Path:
    """Obstacles (grey boxes), each vehicle's path (UAV solid, UGV dashed; circle/square at
    the start) and the tasks (x, coloured by final state), in 3D."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = _figure(8, 6.5)
    ax = fig.add_subplot(projection="3d")
    faces = [f for b in obstacles[["x0", "y0", "z0", "x1", "y1", "z1"]].itertuples(index=False)
             for f in _box_faces(tuple(b))]
    if faces:
        ax.add_collection3d(Poly3DCollection(faces, facecolor=(0.55, 0.55, 0.6, 0.25),
                                             edgecolor=(0.3, 0.3, 0.35, 0.5), linewidths=0.4))
    traj = trajectories(events, vehicles)
    colours = _colours(sorted(traj))
    kinds = dict(zip(vehicles["agent_id"].astype(int), vehicles["kind"]))
    busy = sum(len(d) for d in traj.values()) > 600  # long runs: thinner, lighter lines
    for agent, df in traj.items():
        uav = kinds.get(agent) == "uav"
        ax.plot(df["x"], df["y"], df["z"], color=colours[agent], linewidth=0.7 if busy else 1.4,
                alpha=0.7 if busy else 1.0, linestyle="-" if uav else "--")
        ax.scatter([df["x"].iloc[0]], [df["y"].iloc[0]], [df["z"].iloc[0]], color=colours[agent],
                   marker="o" if uav else "s", s=28, depthshade=False)
    for state, g in tasks.groupby("state"):
        ax.scatter(g["x"], g["y"], g["z"], marker="x", s=36 if len(tasks) <= 60 else 12,
                   depthshade=False,
                   color=TASK_COLOURS.get(state, "black"),
                   label=f"task {TASK_LABELS.get(state, state)}")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.2", linestyle="-", marker="o", label="UAV path / start"),
               Line2D([], [], color="0.2", linestyle="--", marker="s", label="UGV path / start")]
    handles += [h for h in ax.get_legend_handles_labels()[0]]
    ax.legend(handles=handles, fontsize="small", loc="upper left")
    if world is None:
        pts = np.vstack([obstacles[["x1", "y1", "z1"]].to_numpy(dtype=float),
                         *(d[["x", "y", "z"]].to_numpy(dtype=float) for d in traj.values())])
        world = tuple(float(v) for v in np.ceil(pts.max(axis=0))) if len(pts) else (1, 1, 1)
    ax.set_xlim(0, world[0])
    ax.set_ylim(0, world[1])
    ax.set_zlim(0, world[2])
    ax.set_box_aspect(world)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.view_init(elev=28, azim=-60)
    ax.set_title(title or "Vehicle paths and obstacles")
    return _save(fig, path)
