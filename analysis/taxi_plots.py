"""The figures of a taxi (road network) study, drawn with matplotlib's object API (Agg).

* :func:`network_map`: the streets (thin grey), the density of pickups (hexagon bins, log
  colour scale) and where the fleet starts;
* :func:`hourly`: per time bin, demand and served trips, rejection rate, wait percentiles, per
  allocator (and N);
* :func:`fleet_state`: the fleet's state over time, stacked (idle, to pickup, occupied,
  repositioning, failed), one panel per allocator and N;
* :func:`wait_by_group`: wait-time distributions per allocator and N (ECDF and box plots).

Each takes DataFrames from :mod:`analysis.metrics` / :mod:`analysis.timeline`, writes one PNG
and returns its path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.metrics import allocator_order
from analysis.plots import _colours, _figure, _save
from analysis.timeline import FLEET_STATES

FLEET_COLOURS = {"idle": "#c7c7c7", "to_pickup": "#ff7f0e", "occupied": "#1f77b4",
                 "repositioning": "#9467bd", "failed": "#d62728"}
FLEET_LABELS = {"idle": "idle", "to_pickup": "driving to a pickup", "occupied":
                "with a passenger", "repositioning": "repositioning", "failed": "broken down"}


def time_bin(horizon_s: float) -> float:
    """Bin width (s) for per-time plots: an hour for runs of 6 h or more, else 15 minutes
    (5 under an hour), so that a short run still shows a curve."""
    if horizon_s >= 6 * 3600:
        return 3600.0
    return 900.0 if horizon_s >= 3600 else 300.0


def _km(ax) -> None:
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v / 1000:g}")
    ax.xaxis.set_major_formatter(fmt)
    ax.yaxis.set_major_formatter(fmt)
    ax.set_xlabel("x (km)")
    ax.set_ylabel("y (km)")


def network_map(path: Path, *, pickups: np.ndarray, starts: np.ndarray,
                xy: np.ndarray | None = None, edges: np.ndarray | None = None,
                title: str = "") -> Path:
    """The map: streets (``xy`` node positions in metres, ``edges`` index pairs; left out when
    None), pickups as hexagon-binned density (log scale) and the fleet's start positions."""
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm
    from matplotlib.lines import Line2D

    fig = _figure(7.5, 6.8)
    ax = fig.add_subplot()
    pts = [p for p in (pickups, starts, xy) if p is not None and len(p)]
    allxy = np.vstack([p[:, :2] for p in pts]) if pts else np.zeros((1, 2))
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    span = float(max(hi - lo)) or 1.0
    if xy is not None and edges is not None and len(edges):
        segs = np.stack([xy[edges[:, 0], :2], xy[edges[:, 1], :2]], axis=1)
        lw = 0.25 if len(edges) > 5000 else 0.6
        ax.add_collection(LineCollection(segs, colors="0.6", linewidths=lw, zorder=1))
    handles = []
    if len(pickups):
        grid = 60 if len(pickups) > 2000 else 25
        hb = ax.hexbin(pickups[:, 0], pickups[:, 1], gridsize=grid, mincnt=1, cmap="YlOrRd",
                       norm=LogNorm(), alpha=0.85, zorder=2,
                       extent=(lo[0], hi[0], lo[1], hi[1]))
        cb = fig.colorbar(hb, ax=ax, shrink=0.8)
        cb.set_label("pickups per hexagon (log scale)")
        from matplotlib.ticker import FuncFormatter

        plain = FuncFormatter(lambda v, _: f"{v:g}")
        cb.ax.yaxis.set_major_formatter(plain)
        cb.ax.yaxis.set_minor_formatter(FuncFormatter(
            lambda v, _: f"{v:g}" if f"{v:.1e}"[0] in "25" else ""))
    if len(starts):
        ax.scatter(starts[:, 0], starts[:, 1], s=14 if len(starts) > 200 else 28, marker="^",
                   facecolor="#1f77b4", edgecolor="white", linewidth=0.4, zorder=3)
        handles.append(Line2D([], [], marker="^", linestyle="", color="#1f77b4",
                              label=f"fleet start ({len(starts)} vehicles)"))
    if xy is not None:
        handles.append(Line2D([], [], color="0.6", label="streets"))
    ax.set_xlim(lo[0] - 0.03 * span, hi[0] + 0.03 * span)
    ax.set_ylim(lo[1] - 0.03 * span, hi[1] + 0.03 * span)
    ax.set_aspect("equal")
    _km(ax)
    ax.set_title(title or "Network, demand and fleet")
    if handles:
        ax.legend(handles=handles, loc="upper left", fontsize="small", framealpha=0.9)
    return _save(fig, path)


def _group_label(key, multi_n: bool) -> str:
    alloc, n = key
    return f"{alloc}, N = {n}" if multi_n else str(alloc)


def _groups(df: pd.DataFrame):
    """((allocator, N), rows) in the paper's allocator order, then N."""
    order = allocator_order(df["allocator"].unique()) if len(df) else []
    rank = {a: i for i, a in enumerate(order)}
    keys = sorted(df.groupby(["allocator", "n_agents"]).groups, key=lambda k: (rank[k[0]], k[1]))
    for k in keys:
        yield k, df.loc[(df["allocator"] == k[0]) & (df["n_agents"] == k[1])]


def hourly(customers: pd.DataFrame, path: Path, *, bin_s: float, runs: dict,
           title: str = "") -> Path:
    """Three panels against time of release: requests and served trips per bin (mean per
    run), rejection rate, and wait median / p90 per allocator and N. ``customers``: rows of
    :func:`analysis.metrics.hourly_customers` with ``t_h`` (bin start, hours); ``runs``:
    (allocator, N) -> number of runs pooled."""
    fig = _figure(11, 8.4)
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    multi_n = customers["n_agents"].nunique() > 1
    keys = [k for k, _ in _groups(customers)]
    colours = _colours([_group_label(k, multi_n) for k in keys])
    width = bin_s / 3600
    first = True
    markers = ("o", "s", "^", "D", "v", "P", "X", "*")
    for i, (key, g) in enumerate(_groups(customers)):
        label = _group_label(key, multi_n)
        c = colours[label]
        # allocators that decide alike draw on top of each other: the first ones are drawn
        # wider, each with its own marker, so every line stays visible
        lw, mk = max(3.2 - 0.6 * i, 1.0), markers[i % len(markers)]
        n = runs.get(key, 1)
        g = g.sort_values("t_h")
        x = g["t_h"].to_numpy(dtype=float) + width / 2
        if first:  # the demand is the same for every allocator of a seed: one set of bars
            a1.bar(g["t_h"], g["requests"] / n, width=width, align="edge", color="0.85",
                   edgecolor="0.6", linewidth=0.5, label="requests")
            first = False
        style = {"color": c, "linewidth": lw, "marker": mk, "markersize": 4}
        a1.plot(x, g["rides"] / n, label=f"served: {label}", **style)
        a2.plot(x, 100 * g["rejectionRate"], label=label, **style)
        a3.plot(x, g["wait_median"] / 60, label=f"{label}: median", **style)
        a3.plot(x, g["wait_p90"] / 60, linestyle="--", label=f"{label}: p90",
                **{**style, "marker": None})
    unit = "hour" if bin_s == 3600 else f"{bin_s / 60:g} min"
    a1.set_ylabel(f"trips per {unit}\n(mean per run)")
    a1.set_title(title or "Demand, service and waiting over the day")
    a1.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1))
    a2.set_ylabel("rejected (%)\n(at once or expired)")
    a2.set_ylim(bottom=0)
    a2.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1))
    a3.set_ylabel("wait, release → pickup\n(min)")
    a3.set_ylim(bottom=0)
    a3.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1))
    a3.set_xlabel("time of release (h)")
    for ax in (a1, a2, a3):
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def fleet_state(fleet: pd.DataFrame, path: Path, *, bin_s: float, title: str = "") -> Path:
    """Stacked areas of the mean number of vehicles in each fleet state per time bin, one panel
    per allocator and N (at most 8 panels: the first ones in the paper's order). ``fleet``:
    rows of :func:`analysis.metrics.hourly_fleet` with ``t_h``."""
    groups = list(_groups(fleet))[:8]
    cols = 1 if len(groups) == 1 else 2
    rows = math.ceil(len(groups) / cols)
    fig = _figure(10 if cols == 2 else 8, 1.0 + 2.6 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)).ravel()
    multi_n = fleet["n_agents"].nunique() > 1
    width = bin_s / 3600
    for ax, (key, g) in zip(axes, groups):
        g = g.sort_values("t_h")
        x = np.r_[g["t_h"].to_numpy(dtype=float), g["t_h"].to_numpy(dtype=float)[-1] + width]
        ys = [np.r_[g[s].to_numpy(dtype=float), g[s].to_numpy(dtype=float)[-1]]
              for s in FLEET_STATES]
        ax.stackplot(x, ys, step="post", colors=[FLEET_COLOURS[s] for s in FLEET_STATES],
                     labels=[FLEET_LABELS[s] for s in FLEET_STATES], linewidth=0)
        ax.set_title(_group_label(key, multi_n) + f" (N = {key[1]})" * (not multi_n),
                     fontsize="medium")
        ax.grid(True, alpha=0.3)
        ax.set_xlim(x[0], x[-1])
    for ax in axes[len(groups):]:
        ax.set_visible(False)
    for ax in axes[::cols]:
        ax.set_ylabel("vehicles (mean)")
    for ax in axes[max(0, len(groups) - cols):len(groups)]:
        ax.set_xlabel("time (h)")
        ax.tick_params(labelbottom=True)
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h[::-1], lab[::-1], loc="outside right upper", fontsize="small", frameon=False)
    fig.suptitle(title or "Fleet state over time (stacked)")
    return _save(fig, path)


def wait_by_group(waits: pd.DataFrame, path: Path, title: str = "") -> Path:
    """Left: ECDF of the wait (release -> pickup, minutes) per allocator and N; right: box
    plots (quartiles, whiskers at 1.5 IQR, no fliers) per allocator and N."""
    fig = _figure(10.5, 4.6)
    left, right = fig.subplots(1, 2, width_ratios=[1.2, 1])
    multi_n = waits["n_agents"].nunique() > 1 if len(waits) else False
    groups = list(_groups(waits)) if len(waits) else []
    labels = [_group_label(k, multi_n) for k, _ in groups]
    colours = _colours(labels)
    data = []
    for (key, g), label in zip(groups, labels):
        w = np.sort(g["wait"].to_numpy(dtype=float) / 60)
        w = w[np.isfinite(w)]
        data.append(w)
        if len(w):
            left.step(w, np.arange(1, len(w) + 1) / len(w), where="post", color=colours[label],
                      linewidth=max(3.0 - 0.6 * len(data), 1.0) + 0.6,
                      label=f"{label} (median {np.median(w):.1f} min)")
    left.set_xlabel("wait, release → pickup (min)")
    left.set_ylabel("share of the requests picked up")
    left.set_ylim(0, 1.01)
    left.set_xlim(left=0)
    left.grid(True, alpha=0.3)
    if groups:
        left.legend(fontsize="x-small", loc="lower right")
    left.set_title("Wait distribution (ECDF)")
    keep = [i for i, d in enumerate(data) if len(d)]
    if keep:
        bp = right.boxplot([data[i] for i in keep], orientation="horizontal", patch_artist=True,
                           showfliers=False, widths=0.6)
        for box, i in zip(bp["boxes"], keep):
            box.set_facecolor(colours[labels[i]])
            box.set_alpha(0.6)
        for med in bp["medians"]:
            med.set_color("black")
        right.set_yticks(range(1, len(keep) + 1), [labels[i] for i in keep], fontsize="small")
        right.invert_yaxis()
    right.set_xlabel("wait (min)")
    right.set_title("Per allocator (box: quartiles)")
    right.grid(True, axis="x", alpha=0.3)
    if title:
        fig.suptitle(title)
    return _save(fig, path)
