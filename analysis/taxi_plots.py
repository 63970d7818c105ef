"""The figures of a taxi (road network) study, drawn with matplotlib's object API (Agg).

* :func:`network_map`: the streets (thin grey), the density of pickups (hexagon bins, log
  colour scale) and where the fleet starts, the whole region and zoomed on the demand;
* :func:`hourly`: per time bin, demand and served trips, rejection rate, wait percentiles, per
  series;
* :func:`fleet_state`: the fleet's state over time, stacked (idle, to pickup, occupied,
  repositioning, failed), one panel per series;
* :func:`wait_by_group`: wait-time distributions per series (ECDF and box plots).

A series (:func:`series`) is one allocator, fleet size N, scenario variant (a swept batch
window), planner and repositioner; its label names what differs between the figure's series.

Each takes DataFrames from :mod:`analysis.metrics` / :mod:`analysis.timeline`, writes one PNG
and returns its path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.metrics import allocator_order, variant_name, variant_rank
from analysis.plots import _colours, _figure, _save
from analysis.timeline import CHARGING_STATES, FLEET_STATES

FLEET_COLOURS = {"idle": "#c7c7c7", "to_pickup": "#ff7f0e", "occupied": "#1f77b4",
                 "occupied_2": "#17becf", "occupied_3+": "#2ca02c",
                 "repositioning": "#9467bd", "failed": "#d62728", "to_charger": "#bcbd22",
                 "queueing": "#8c564b", "charging": "#e377c2"}
FLEET_LABELS = {"idle": "idle", "to_pickup": "driving to a pickup", "occupied":
                "1 on board", "occupied_2": "2 on board", "occupied_3+": "3+ on board",
                "repositioning": "repositioning", "failed": "broken down",
                "to_charger": "driving to a charger", "queueing": "queueing at a charger",
                "charging": "charging"}


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


def demand_box(pickups: np.ndarray, q: float = 0.01, margin: float = 0.1):
    """(lo, hi) corners of the box holding the pickups between the ``q`` and ``1 - q``
    quantiles of x and of y, grown by ``margin`` of its span on every side (at least 500 m),
    so that a few far-away pickups do not stretch it."""
    lo = np.quantile(pickups[:, :2], q, axis=0)
    hi = np.quantile(pickups[:, :2], 1 - q, axis=0)
    pad = np.maximum(margin * (hi - lo), 500.0)
    return lo - pad, hi + pad


def _map_panel(ax, lo, hi, *, pickups, starts, xy, edges, zoomed: bool):
    from matplotlib.collections import LineCollection
    from matplotlib.colors import LogNorm

    if xy is not None and edges is not None and len(edges):
        segs = np.stack([xy[edges[:, 0], :2], xy[edges[:, 1], :2]], axis=1)
        if zoomed:  # only the streets with an end in the box: thicker, and fewer to draw
            inside = ((segs >= lo) & (segs <= hi)).all(axis=2).any(axis=1)
            segs = segs[inside]
        lw = 0.25 if len(segs) > 5000 else 0.6
        ax.add_collection(LineCollection(segs, colors="0.55" if zoomed else "0.6",
                                         linewidths=lw * (1.6 if zoomed else 1), zorder=1))
    hb = None
    if len(pickups):
        p = pickups
        if zoomed:
            p = p[((p[:, :2] >= lo) & (p[:, :2] <= hi)).all(axis=1)]
        grid = 60 if len(p) > 2000 else 25
        hb = ax.hexbin(p[:, 0], p[:, 1], gridsize=grid, mincnt=1, cmap="YlOrRd",
                       norm=LogNorm(), alpha=0.8 if zoomed else 0.85, zorder=2,
                       extent=(lo[0], hi[0], lo[1], hi[1]))
    if len(starts):
        st = starts
        if zoomed:
            st = st[((st[:, :2] >= lo) & (st[:, :2] <= hi)).all(axis=1)]
        ax.scatter(st[:, 0], st[:, 1], s=14 if len(starts) > 200 else 28, marker="^",
                   facecolor="#1f77b4", edgecolor="white", linewidth=0.4, zorder=3)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    _km(ax)
    return hb


def network_map(path: Path, *, pickups: np.ndarray, starts: np.ndarray,
                xy: np.ndarray | None = None, edges: np.ndarray | None = None,
                title: str = "") -> Path:
    """The map: streets (``xy`` node positions in metres, ``edges`` index pairs; left out when
    None), pickups as hexagon-binned density (log scale) and the fleet's start positions.
    Left: the whole region; right (when there are pickups and their :func:`demand_box` is
    smaller than the region): zoomed on the demand, the box drawn on the left panel."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle
    from matplotlib.ticker import FuncFormatter

    pts = [p for p in (pickups, starts, xy) if p is not None and len(p)]
    allxy = np.vstack([p[:, :2] for p in pts]) if pts else np.zeros((1, 2))
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    span = float(max(hi - lo)) or 1.0
    lo, hi = lo - 0.03 * span, hi + 0.03 * span
    box = demand_box(pickups) if len(pickups) >= 10 else None
    zoom = box is not None and float(np.prod(box[1] - box[0])) < 0.6 * float(np.prod(hi - lo))
    if zoom:
        box = (np.maximum(box[0], lo), np.minimum(box[1], hi))
    fig = _figure(13.5 if zoom else 7.5, 7.0)
    axes = fig.subplots(1, 2, width_ratios=[1, 1.15]) if zoom else [fig.add_subplot()]
    kw = {"pickups": pickups, "starts": starts, "xy": xy, "edges": edges}
    hb = _map_panel(axes[0], lo, hi, zoomed=False, **kw)
    axes[0].set_title("whole region", fontsize="medium")
    if zoom:
        hb = _map_panel(axes[1], box[0], box[1], zoomed=True, **kw)
        axes[0].add_patch(Rectangle(box[0], *(box[1] - box[0]), fill=False, edgecolor="black",
                                    linewidth=1.0, linestyle="--", zorder=4))
        axes[1].set_title("zoomed on the demand (1st–99th percentile of pickups, + 10 %)",
                          fontsize="medium")
    if hb is not None:
        cb = fig.colorbar(hb, ax=axes[-1], shrink=0.8)
        cb.set_label("pickups per hexagon (log scale)")
        cb.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        cb.ax.yaxis.set_minor_formatter(FuncFormatter(
            lambda v, _: f"{v:g}" if f"{v:.1e}"[0] in "25" else ""))
    handles = []
    if len(starts):
        handles.append(Line2D([], [], marker="^", linestyle="", color="#1f77b4",
                              label=f"fleet start ({len(starts)} vehicles)"))
    if xy is not None:
        handles.append(Line2D([], [], color="0.6", label="streets"))
    if handles:
        axes[0].legend(handles=handles, loc="upper left", fontsize="small", framealpha=0.9)
    fig.suptitle(title or "Network, demand and fleet", wrap=True)
    return _save(fig, path)


#: The columns that tell the series of a taxi study apart, in the order their labels name them.
SERIES_COLUMNS = ("allocator", "n_agents", "scenario", "planner", "reposition")


def series_columns(df: pd.DataFrame) -> list[str]:
    """The columns of :data:`SERIES_COLUMNS` that ``df`` has."""
    return [c for c in SERIES_COLUMNS if c in df.columns]


def scenario_title(names) -> str:
    """The scenarios of a figure, for its title: one name, or the base name of batch-window
    variants with their windows (``chicago_taxi (imm, 30s)``), or the names joined."""
    names = sorted({str(n) for n in names}, key=variant_rank)
    if len(names) == 1:
        return names[0]
    bases = {n.rpartition("-")[0] for n in names}
    if len(bases) == 1 and all(variant_name(n) != n for n in names):
        return f"{bases.pop()} ({', '.join(variant_name(n) for n in names)})"
    return ", ".join(names)


def series(df: pd.DataFrame) -> list[tuple[tuple, str, pd.DataFrame]]:
    """(key, label, rows) per series of ``df``: the key is the values of
    :func:`series_columns` (allocator, N, scenario, planner, repositioner); the label names the
    allocator and whatever else differs between the series of ``df``: ``N = 500``, the batch
    window of a scenario variant (``imm``, ``30s``) or the scenario, the planner, and a
    repositioner other than ``stay`` (``+ demand``), e.g. ``fcfs 30s + demand``. Ordered by
    allocator (the paper's order), N, scenario, planner, repositioner (``stay`` first)."""
    if df.empty:
        return []
    cols = series_columns(df)
    d = df.assign(reposition=df["reposition"].fillna("stay").astype(str)) \
        if "reposition" in cols else df
    rank = {a: i for i, a in enumerate(allocator_order(d["allocator"].unique()))}
    varies = {c: d[c].nunique() > 1 for c in cols}

    def order(key):
        k = dict(zip(cols, key))
        rep = k.get("reposition", "stay")
        return (rank[k["allocator"]], k["n_agents"], variant_rank(k.get("scenario", "")),
                str(k.get("planner", "")), rep != "stay", rep)

    out = []
    for key, rows in sorted(d.groupby(cols, sort=False), key=lambda kv: order(kv[0])):
        k = dict(zip(cols, key))
        parts = [str(k["allocator"])]
        if varies.get("n_agents"):
            parts.append(f"N={k['n_agents']}")
        if varies.get("scenario"):
            parts.append(variant_name(k["scenario"]))
        if varies.get("planner"):
            parts.append(str(k["planner"]))
        label = " ".join(parts)
        if varies.get("reposition") and k["reposition"] != "stay":
            label += f" + {k['reposition']}"
        out.append((tuple(key), label, rows))
    return out


def per_run(customers: pd.DataFrame,
            runs: dict | None = None) -> list[tuple[str, pd.DataFrame]]:
    """(label, rows) per series (:func:`series`), rows sorted by ``t_h``, with ``requests``
    and ``rides`` as the mean per run of the series: divided by the series' ``runs`` column
    (:func:`analysis.metrics.hourly_customers` writes it), else by ``runs[key]`` (series key
    -> number of runs pooled), else left as they are (one run). What :func:`hourly` draws."""
    out = []
    for key, label, g in series(customers):
        if "runs" in g.columns:
            n = g["runs"].to_numpy(dtype=float)
        else:
            n = float((runs or {}).get(key, 1))
        g = g.assign(requests=g["requests"] / n, rides=g["rides"] / n).sort_values("t_h")
        out.append((label, g))
    return out


def _same_demand(groups: list[tuple[str, pd.DataFrame]]) -> bool:
    """Whether every series has the same requests per run in every bin."""
    ref = groups[0][1].set_index("t_h")["requests"]
    return all(g.set_index("t_h")["requests"].reindex(ref.index).equals(ref)
               and len(g) == len(ref) for _, g in groups[1:])


def hourly(customers: pd.DataFrame, path: Path, *, bin_s: float, runs: dict | None = None,
           title: str = "") -> Path:
    """Three panels against time of release: requests and served trips per bin (mean per
    run, :func:`per_run`), rejection rate, and wait median / p90 per series (:func:`series`).
    The requests are one set of bars when every series has the same (the seeds' demand, as
    in a study of allocators), else a dotted line per series. ``customers``: rows of
    :func:`analysis.metrics.hourly_customers` with ``t_h`` (bin start, hours); ``runs``:
    series key -> number of runs pooled, for rows without a ``runs`` column."""
    fig = _figure(11, 8.4)
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    groups = per_run(customers, runs)
    colours = _colours([label for label, _ in groups])
    width = bin_s / 3600
    markers = ("o", "s", "^", "D", "v", "P", "X", "*")
    same = bool(groups) and _same_demand(groups)
    if same:  # one set of bars: the demand every series saw
        g = groups[0][1]
        a1.bar(g["t_h"], g["requests"], width=width, align="edge", color="0.85",
               edgecolor="0.6", linewidth=0.5, label="requests")
    for i, (label, g) in enumerate(groups):
        c = colours[label]
        # allocators that decide alike draw on top of each other: the first ones are drawn
        # wider, each with its own marker, so every line stays visible
        lw, mk = max(3.2 - 0.6 * i, 1.0), markers[i % len(markers)]
        x = g["t_h"].to_numpy(dtype=float) + width / 2
        if not same:  # series of different demand: each its own requests
            a1.plot(x, g["requests"], color=c, linewidth=1.0, linestyle=":")
        style = {"color": c, "linewidth": lw, "marker": mk, "markersize": 4}
        a1.plot(x, g["rides"], label=label, **style)
        a2.plot(x, 100 * g["rejectionRate"], **style)
        a3.plot(x, g["wait_median"] / 60, **style)
        a3.plot(x, g["wait_p90"] / 60, linestyle="--", **{**style, "marker": None})
    unit = "hour" if bin_s == 3600 else f"{bin_s / 60:g} min"
    a1.set_ylabel(f"trips per {unit}, mean per run\n(" + ("bars" if same else "dotted")
                  + ": requests;\nlines: served)")
    fig.suptitle(title or "Demand, service and waiting over the day")  # above the legend
    a2.set_ylabel("rejected (%)\n(at once or expired)")
    a2.set_ylim(bottom=0)
    a3.set_ylabel("wait, release → pickup (min)\nsolid: median, dashed: p90")
    a3.set_ylim(bottom=0)
    # one legend for the three panels (a series has the same colour and marker in each), in
    # two columns past 20 series so that a whole study's series fit beside the panels
    h, lab = a1.get_legend_handles_labels()
    fig.legend(h, lab, loc="outside right center", fontsize="x-small",
               ncols=1 if len(lab) <= 20 else 2, frameon=False)
    a3.set_xlabel("time of release (h)")
    for ax in (a1, a2, a3):
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def fleet_state(fleet: pd.DataFrame, path: Path, *, bin_s: float, title: str = "",
                max_panels: int = 40) -> Path:
    """Stacked areas of the mean number of vehicles in each fleet state per time bin, one panel
    per series (:func:`series`; at most ``max_panels``, the first ones in its order, the title
    says how many are left out). ``fleet``: rows of :func:`analysis.metrics.hourly_fleet` with
    ``t_h``."""
    every = series(fleet)
    groups = every[:max_panels]
    k = len(groups)
    cols = 1 if k == 1 else 2 if k <= 8 else 3 if k <= 18 else 4
    rows = max(1, math.ceil(k / cols))
    fig = _figure({1: 8, 2: 10, 3: 13, 4: 16}[cols], 1.4 + (2.4 if cols <= 2 else 2.1) * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)).ravel()
    width = bin_s / 3600
    # by passengers on board: the shared-ride states only where some vehicle had them
    shown = [s for s in FLEET_STATES if s not in ("occupied_2", "occupied_3+", *CHARGING_STATES)
             or (s in fleet and (fleet[s].fillna(0) > 0).any())]
    for ax, (key, label, g) in zip(axes, groups):
        g = g.sort_values("t_h")
        x = np.r_[g["t_h"].to_numpy(dtype=float), g["t_h"].to_numpy(dtype=float)[-1] + width]
        ys = [np.r_[g[s].to_numpy(dtype=float), g[s].to_numpy(dtype=float)[-1]]
              for s in shown]
        ax.stackplot(x, ys, step="post", colors=[FLEET_COLOURS[s] for s in shown],
                     labels=[FLEET_LABELS[s] for s in shown], linewidth=0)
        n = dict(zip(series_columns(g), key))["n_agents"]
        ax.set_title(label if "N=" in label else f"{label} (N = {n})", fontsize="medium")
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
    # below the panels, in one row: a legend in the upper right corner would run into the title
    fig.legend(h, lab, loc="outside lower center", ncols=min(len(lab), 4), fontsize="small",
               frameon=False)
    more = len(every) - len(groups)
    fig.suptitle((title or "Fleet state over time (stacked)")
                 + (f"\n(the first {len(groups)} of {len(every)} series)" if more else ""))
    return _save(fig, path)


def wait_by_group(waits: pd.DataFrame, path: Path, title: str = "") -> Path:
    """Left: ECDF of the wait (release -> pickup, minutes) per series (:func:`series`);
    right: box plots (quartiles, whiskers at 1.5 IQR, no fliers) per series."""
    groups = series(waits)
    fig = _figure(10.5 if len(groups) <= 10 else 13, max(4.6, 1.4 + 0.24 * len(groups)))
    left, right = fig.subplots(1, 2, width_ratios=[1.2, 1])
    labels = [label for _, label, _ in groups]
    colours = _colours(labels)
    data = []
    for _key, label, g in groups:
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
    if groups and len(groups) <= 10:
        left.legend(fontsize="x-small", loc="lower right")
    left.set_title("Wait distribution (ECDF)" if len(groups) <= 10 else
                   "Wait distribution (ECDF; colours as in the box plot)")
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
    right.set_title("Per series (box: quartiles)")
    right.grid(True, axis="x", alpha=0.3)
    if title:
        fig.suptitle(title)
    return _save(fig, path)
