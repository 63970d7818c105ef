"""The figures of a taxi (road network) study, drawn with matplotlib's object API (Agg).

* :func:`network_map`: the streets (thin grey), the density of pickups (hexagon bins, log
  colour scale) and where the fleet starts, the whole region and zoomed on the demand, one
  row per scenario (:class:`MapPanel`);
* :func:`hourly`: per time bin, demand and served trips, rejection rate, wait percentiles, per
  series;
* :func:`fleet_state`: the fleet's state over time, stacked (idle, to pickup, occupied,
  repositioning, failed), one panel per series;
* :func:`wait_by_group`: wait-time distributions per series (ECDF and box plots).

A series (:func:`series`) is one allocator, fleet size N, batch window, scenario, planner and
repositioner (the run keys but the seed); its label names what differs between the figure's
series.

Each takes DataFrames from :mod:`analysis.metrics` / :mod:`analysis.timeline`, writes one PNG
and returns its path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.metrics import series_keys
from paired.compare import allocator_order, window_label
from analysis.plots import _colours, _figure, _save
from analysis.timeline import CHARGING_STATES, FLEET_STATES

FLEET_COLOURS = {"idle": "#c7c7c7", "to_pickup": "#ff7f0e", "occupied": "#1f77b4",
                 "occupied_2": "#17becf", "occupied_3+": "#2ca02c",
                 "repositioning": "#9467bd", "failed": "#d62728", "to_charger": "#bcbd22",
                 "queueing": "#8c564b", "charging": "#e377c2", "on_break": "#7f7f7f"}
FLEET_LABELS = {"idle": "idle", "to_pickup": "driving to a pickup", "occupied":
                "1 on board", "occupied_2": "2 on board", "occupied_3+": "3+ on board",
                "repositioning": "repositioning", "failed": "broken down",
                "to_charger": "driving to a charger", "queueing": "queueing at a charger",
                "charging": "charging", "on_break": "driver on a break"}


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


@dataclass(frozen=True)
class MapPanel:
    """One scenario's row of :func:`network_map`: its title, pickups and fleet start (x, y
    metres) and its streets (``xy`` node positions, ``edges`` index pairs; None: none)."""

    title: str
    pickups: np.ndarray
    starts: np.ndarray
    xy: np.ndarray | None = None
    edges: np.ndarray | None = None


def _extent(m: MapPanel):
    pts = [p for p in (m.pickups, m.starts, m.xy) if p is not None and len(p)]
    allxy = np.vstack([p[:, :2] for p in pts]) if pts else np.zeros((1, 2))
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    span = float(max(hi - lo)) or 1.0
    lo, hi = lo - 0.03 * span, hi + 0.03 * span
    box = demand_box(m.pickups) if len(m.pickups) >= 10 else None
    zoom = box is not None and float(np.prod(box[1] - box[0])) < 0.6 * float(np.prod(hi - lo))
    if zoom:
        box = (np.maximum(box[0], lo), np.minimum(box[1], hi))
    return lo, hi, box if zoom else None


def network_map(path: Path, panels: list[MapPanel], title: str = "") -> Path:
    """The map, one row per panel (a scenario): streets, pickups as hexagon-binned density
    (log scale) and the fleet's start positions. Left: the whole region; right (when there
    are pickups and their :func:`demand_box` is smaller than the region): zoomed on the
    demand, the box drawn on the left panel. Panels are as wide as their region is, so a
    tall city leaves no empty band between them."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle
    from matplotlib.ticker import FuncFormatter

    rows = [(m, *_extent(m)) for m in panels]
    row_h = 6.2
    aspects = []
    for _m, lo, hi, box in rows:
        a = [float((hi - lo)[0] / max((hi - lo)[1], 1e-9))]
        if box is not None:
            a.append(float((box[1] - box[0])[0] / max((box[1] - box[0])[1], 1e-9)))
        aspects.append(a)
    ncols = max(len(a) for a in aspects)
    # each panel about as wide as its map at the row's height (+ axis labels, colour bar)
    widths = [max(a[k] if k < len(a) else 0.0 for a in aspects) for k in range(ncols)]
    widths = [min(max(w, 0.45), 2.2) for w in widths]
    fig = _figure(min(row_h * sum(widths) + 1.2 + 1.0 * ncols, 16.0),
                  row_h * len(rows) + 0.6)
    axes = fig.subplots(len(rows), ncols, squeeze=False, width_ratios=widths)
    for r, (m, lo, hi, box) in enumerate(rows):
        kw = {"pickups": m.pickups, "starts": m.starts, "xy": m.xy, "edges": m.edges}
        ax = axes[r]
        hb = _map_panel(ax[0], lo, hi, zoomed=False, **kw)
        ax[0].set_title(f"{m.title}; whole region" if m.title else "whole region",
                        fontsize="medium")
        if box is not None:
            hb = _map_panel(ax[1], box[0], box[1], zoomed=True, **kw)
            ax[0].add_patch(Rectangle(box[0], *(box[1] - box[0]), fill=False,
                                      edgecolor="black", linewidth=1.0, linestyle="--",
                                      zorder=4))
            ax[1].set_title("zoomed on the demand\n(1st–99th percentile of pickups, + 10 %)",
                            fontsize="medium")
        for extra in ax[(2 if box is not None else 1):]:
            extra.set_visible(False)
        last = ax[1] if box is not None else ax[0]
        if hb is not None:
            cb = fig.colorbar(hb, ax=last, shrink=0.8)
            cb.set_label("pickups per hexagon (log scale)")
            cb.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            cb.ax.yaxis.set_minor_formatter(FuncFormatter(
                lambda v, _: f"{v:g}" if f"{v:.1e}"[0] in "25" else ""))
        handles = []
        if len(m.starts):
            handles.append(Line2D([], [], marker="^", linestyle="", color="#1f77b4",
                                  label=f"fleet start ({len(m.starts)} vehicles)"))
        if m.xy is not None:
            handles.append(Line2D([], [], color="0.6", label="streets"))
        if handles:
            ax[0].legend(handles=handles, loc="upper left", fontsize="small", framealpha=0.9)
    fig.suptitle(title or "Network, demand and fleet", wrap=True)
    return _save(fig, path)


#: The columns a series label names first, in this order (then any other run key).
LABEL_ORDER = ("allocator", "n_agents", "batch_window", "scenario", "planner", "reposition")
SERIES_COLUMNS = LABEL_ORDER  # its older name


def series_columns(df: pd.DataFrame) -> list[str]:
    """The columns that tell the series of ``df`` apart (its run keys but the seed,
    :func:`analysis.metrics.series_keys`), in :data:`LABEL_ORDER`."""
    keys = series_keys(df)
    return [c for c in LABEL_ORDER if c in keys] + [c for c in keys if c not in LABEL_ORDER]


def scenario_title(names) -> str:
    """The scenarios of a figure, for its title: their names joined."""
    return ", ".join(sorted({str(n) for n in names}))


def series(df: pd.DataFrame) -> list[tuple[tuple, str, pd.DataFrame]]:
    """(key, label, rows) per series of ``df``: the key is the values of
    :func:`series_columns` (allocator, N, batch window, scenario, planner, repositioner); the
    label names the allocator and whatever else differs between the series of ``df``:
    ``N = 500``, the batch window (``imm``, ``30s``), the scenario, the planner, and a
    repositioner other than ``stay`` (``+ demand``), e.g. ``fcfs 30s + demand``. Ordered by
    allocator (the paper's order), N, batch window, scenario, planner, repositioner (``stay``
    first)."""
    if df.empty:
        return []
    cols = series_columns(df)
    d = df.assign(reposition=df["reposition"].fillna("stay").astype(str)) \
        if "reposition" in cols else df
    if "batch_window" in cols:
        d = d.assign(batch_window=pd.to_numeric(d["batch_window"]).astype(float).fillna(0.0))
    rank = {a: i for i, a in enumerate(allocator_order(d["allocator"].unique()))}
    varies = {c: d[c].nunique() > 1 for c in cols}

    def order(key):
        k = dict(zip(cols, key))
        rep = k.get("reposition", "stay")
        return (rank[k["allocator"]], k["n_agents"], k.get("batch_window", 0.0),
                str(k.get("scenario", "")), str(k.get("planner", "")), rep != "stay", rep)

    out = []
    for key, rows in sorted(d.groupby(cols, sort=False), key=lambda kv: order(kv[0])):
        k = dict(zip(cols, key))
        rest = panel_name(k, varies)
        label = f"{k['allocator']} {rest}" if rest else str(k["allocator"])
        out.append((tuple(key), label, rows))
    return out


def panel_name(k: dict, varies: dict) -> str:
    """What tells a series apart besides its allocator: ``N=500 30s + demand`` (empty when
    only the allocator differs); the title of its panel in small multiples."""
    parts = []
    if varies.get("n_agents"):
        parts.append(f"N={k['n_agents']}")
    if varies.get("batch_window"):
        parts.append(window_label(k["batch_window"]))
    if varies.get("scenario"):
        parts.append(str(k["scenario"]))
    if varies.get("planner"):
        parts.append(str(k["planner"]))
    name = " ".join(parts)
    if varies.get("reposition") and k.get("reposition", "stay") != "stay":
        name += f" + {k['reposition']}"
    return name.strip()


#: More series than this and the per-time and wait figures switch to small multiples: one
#: panel per combination of N, batch window, planner and repositioner, the allocators in it
#: coloured alike in every panel.
MANY = 8


def select(groups: list, patterns) -> list:
    """The series of ``groups`` (:func:`series` triples) whose label matches one of the glob
    ``patterns`` (``fnmatch``, case-insensitive: ``"hungarian*"``, ``"* 30s*"``,
    ``"*+ demand"``); all of them when ``patterns`` is empty or None."""
    from fnmatch import fnmatch

    if not patterns:
        return groups
    pats = [p.lower() for p in ([patterns] if isinstance(patterns, str) else patterns)]
    kept = [g for g in groups if any(fnmatch(g[1].lower(), p) for p in pats)]
    if groups and not kept:
        raise ValueError(f"no series matches {', '.join(map(repr, pats))}; the series: "
                         f"{', '.join(g[1] for g in groups[:12])}"
                         + (f" and {len(groups) - 12} more" if len(groups) > 12 else ""))
    return kept


def twins(groups: list, values) -> dict[str, str]:
    """label -> the label of the first earlier series with the same ``values(rows)`` (arrays
    equal, NaN equal to NaN): series that lie exactly on each other in a figure, e.g. two
    allocators that decide alike one request at a time. The figures mark them."""
    seen: list[tuple[str, np.ndarray]] = []
    out = {}
    for _key, label, rows in groups:
        v = np.asarray(values(rows), dtype=float)
        for other, w in seen:
            if v.shape == w.shape and np.array_equal(v, w, equal_nan=True):
                out[label] = other
                break
        else:
            seen.append((label, v))
    return out


def _panels(groups: list) -> list[tuple[str, list]]:
    """``groups`` split into small multiples: (panel title, its series) in series order."""
    if not groups:
        return []
    cols = series_columns(groups[0][2])
    keys = [dict(zip(cols, key)) for key, _, _ in groups]
    varies = {c: len({str(k.get(c)) for k in keys}) > 1 for c in cols}
    panels: dict[str, list] = {}
    for k, g in zip(keys, groups):
        name = panel_name(k, varies)
        if varies.get("reposition") and k.get("reposition", "stay") == "stay":
            name = f"{name} (stay)".strip()  # the panel beside '+ demand' names its own
        panels.setdefault(name or "all series", []).append(g)
    return list(panels.items())


def _allocator_styles(groups: list) -> tuple[dict, dict]:
    """A colour and a marker per allocator (the same in every panel)."""
    allocs = allocator_order({dict(zip(series_columns(g), k))["allocator"]
                              for k, _, g in groups})
    colours = _colours(allocs)
    markers = ("o", "s", "^", "D", "v", "P", "X", "*", "h", "<")
    return colours, {a: markers[i % len(markers)] for i, a in enumerate(allocs)}


def _allocator_of(group) -> str:
    key, _, rows = group
    return str(dict(zip(series_columns(rows), key))["allocator"])


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


def _hourly_values(g: pd.DataFrame) -> np.ndarray:
    return g[["t_h", "requests", "rides", "rejectionRate", "wait_median", "wait_p90"]] \
        .to_numpy(dtype=float)


def hourly(customers: pd.DataFrame, path: Path, *, bin_s: float, runs: dict | None = None,
           title: str = "", only=None) -> Path:
    """Three panels against time of release: requests and served trips per bin (mean per
    run, :func:`per_run`), rejection rate, and wait median / p90 per series (:func:`series`).
    The requests are one set of bars when every series has the same (the seeds' demand, as
    in a study of allocators), else a dotted line per series. ``customers``: rows of
    :func:`analysis.metrics.hourly_customers` with ``t_h`` (bin start, hours); ``runs``:
    series key -> number of runs pooled, for rows without a ``runs`` column; ``only``: glob
    patterns of the series to draw (:func:`select`).

    A series identical to an earlier one (:func:`twins`) is drawn dashed over it and its
    legend entry says ``= <the other>``. Past :data:`MANY` series the figure is small
    multiples (:func:`_hourly_panels`)."""
    labelled = {label: g for label, g in per_run(customers, runs)}
    groups = [(k, label, labelled[label]) for k, label, _ in select(series(customers), only)]
    if len(groups) > MANY and len(_panels(groups)) > 1:
        return _hourly_panels(groups, path, bin_s=bin_s, title=title)
    same_as = twins(groups, _hourly_values)
    fig = _figure(11, 8.4)
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    colours = _colours([label for _, label, _ in groups])
    width = bin_s / 3600
    markers = ("o", "s", "^", "D", "v", "P", "X", "*")
    pairs = [(label, g) for _, label, g in groups]
    same = bool(pairs) and _same_demand(pairs)
    if same:  # one set of bars: the demand every series saw
        g = pairs[0][1]
        a1.bar(g["t_h"], g["requests"], width=width, align="edge", color="0.85",
               edgecolor="0.6", linewidth=0.5, label="requests")
    for i, (label, g) in enumerate(pairs):
        c = colours[label]
        # allocators that decide alike draw on top of each other: the first ones are drawn
        # wider, each with its own marker, and an identical series dashed, so every line
        # stays visible
        lw, mk = max(3.2 - 0.6 * i, 1.0), markers[i % len(markers)]
        x = g["t_h"].to_numpy(dtype=float) + width / 2
        if not same:  # series of different demand: each its own requests
            a1.plot(x, g["requests"], color=c, linewidth=1.0, linestyle=":")
        twin = same_as.get(label)
        style = {"color": c, "linewidth": 1.4 if twin else lw, "marker": mk, "markersize": 4,
                 "linestyle": (0, (4, 2)) if twin else "-", "zorder": 3 if twin else 2}
        a1.plot(x, g["rides"], label=f"{label} (= {twin})" if twin else label, **style)
        a2.plot(x, 100 * g["rejectionRate"], **style)
        a3.plot(x, g["wait_median"] / 60, **style)
        a3.plot(x, g["wait_p90"] / 60, **{**style, "linestyle": "--", "marker": None})
    unit = "hour" if bin_s == 3600 else f"{bin_s / 60:g} min"
    a1.set_ylabel(f"trips per {unit}, mean per run\n(" + ("bars" if same else "dotted")
                  + ": requests;\nlines: served)")
    fig.suptitle(title or "Demand, service and waiting over the day")  # above the legend
    a2.set_ylabel("rejected (%)\n(at once or expired)")
    a2.set_ylim(bottom=0)
    a3.set_ylabel("wait, release → pickup (min)\nsolid: median, dashed: p90")
    a3.set_ylim(bottom=0)
    # one legend for the three panels (a series has the same colour and marker in each)
    h, lab = a1.get_legend_handles_labels()
    fig.legend(h, lab, loc="outside right center", fontsize="x-small",
               ncols=1 if len(lab) <= 20 else 2, frameon=False)
    a3.set_xlabel("time of release (h)")
    for ax in (a1, a2, a3):
        ax.grid(True, alpha=0.3)
    return _save(fig, path)


def _hourly_panels(groups: list, path: Path, *, bin_s: float, title: str) -> Path:
    """:func:`hourly` as small multiples: a column of three panels (served trips, rejection
    rate, wait median and p90) per combination of N, batch window and repositioner
    (:func:`_panels`), at most four columns a row; in each the allocators, coloured and marked
    alike in every panel; a series identical to another of its panel dashed, the panel saying
    which."""
    from matplotlib.lines import Line2D

    panels = _panels(groups)
    ncol = min(4, len(panels))
    nrow = math.ceil(len(panels) / ncol)
    fig = _figure(3.9 * ncol + 1.8, 1.2 + 5.6 * nrow)
    axes = fig.subplots(3 * nrow, ncol, sharex=True, squeeze=False)
    colours, markers = _allocator_styles(groups)
    width = bin_s / 3600
    same = _same_demand([(label, g) for _, label, g in groups])
    for ax in axes[1::3].ravel():
        ax.sharey(axes[1, 0])
    for ax in axes[2::3].ravel():
        ax.sharey(axes[2, 0])
    for ax in axes[0::3].ravel():
        ax.sharey(axes[0, 0])
    everywhere = twins(groups, _hourly_values)
    panel_of = {label: name for name, members in panels for _k, label, _g in members}
    for p, (name, members) in enumerate(panels):
        r, c = divmod(p, ncol)
        a1, a2, a3 = axes[3 * r, c], axes[3 * r + 1, c], axes[3 * r + 2, c]
        same_as = twins(members, _hourly_values)
        others = {panel_of.get(everywhere.get(label)) for _k, label, _g in members}
        if len(others) == 1 and None not in others:  # the whole panel repeats another
            name = f"{name} (= {others.pop()})"
        if same:
            g = members[0][2]
            a1.bar(g["t_h"], g["requests"], width=width, align="edge", color="0.88",
                   edgecolor="0.7", linewidth=0.4)
        for grp in members:
            _, label, g = grp
            alloc = _allocator_of(grp)
            twin = same_as.get(label)
            style = {"color": colours[alloc], "marker": markers[alloc], "markersize": 3,
                     "linewidth": 1.2 if twin else 2.0, "zorder": 3 if twin else 2,
                     "linestyle": (0, (3, 2)) if twin else "-"}
            x = g["t_h"].to_numpy(dtype=float) + width / 2
            if not same:
                a1.plot(x, g["requests"], color=colours[alloc], linewidth=0.8, linestyle=":")
            a1.plot(x, g["rides"], **style)
            a2.plot(x, 100 * g["rejectionRate"], **style)
            a3.plot(x, g["wait_median"] / 60, **style)
            a3.plot(x, g["wait_p90"] / 60, **{**style, "linewidth": 0.9, "linestyle": "--",
                                              "marker": None})
        a1.set_title(name, fontsize="medium")
        if same_as:
            a1.text(0.02, 0.97, "identical: " + "; ".join(
                f"{_short(a)} = {_short(b)}" for a, b in same_as.items()),
                transform=a1.transAxes, va="top", fontsize="x-small",
                bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
        for ax in (a1, a2, a3):
            ax.grid(True, alpha=0.3)
        a2.set_ylim(bottom=0)
        a3.set_ylim(bottom=0)
    for p in range(len(panels), nrow * ncol):
        r, c = divmod(p, ncol)
        for k in range(3):
            axes[3 * r + k, c].set_visible(False)
    unit = "hour" if bin_s == 3600 else f"{bin_s / 60:g} min"
    for r in range(nrow):
        axes[3 * r, 0].set_ylabel(f"served per {unit}\n(mean per run)")
        axes[3 * r + 1, 0].set_ylabel("rejected (%)")
        axes[3 * r + 2, 0].set_ylabel("wait (min)\nmedian, p90 --")
    for ax in axes[-1]:
        ax.set_xlabel("time of release (h)")
    handles = [Line2D([], [], color=colours[a], marker=markers[a], linewidth=2, label=a)
               for a in colours]
    handles.append(Line2D([], [], color="0.3", linestyle=(0, (3, 2)),
                          label="identical to another\nseries of its panel"))
    if same:
        from matplotlib.patches import Patch

        handles.append(Patch(facecolor="0.88", edgecolor="0.7", label="requests"))
    fig.legend(handles=handles, loc="outside right center", fontsize="small", frameon=False)
    fig.suptitle((title or "Demand, service and waiting over the day")
                 + f"\n{len(groups)} series, one panel per fleet size / window / repositioner")
    return _save(fig, path)


def _short(label: str) -> str:
    return label.split(" ")[0]


def fleet_state(fleet: pd.DataFrame, path: Path, *, bin_s: float, title: str = "",
                max_panels: int = 40, only=None) -> Path:
    """Stacked areas of the mean number of vehicles in each fleet state per time bin, one panel
    per series (:func:`series`, those matching ``only``: :func:`select`; at most
    ``max_panels``, the first ones in its order, the title says how many are left out); a
    series identical to an earlier one says so in its title. ``fleet``: rows of
    :func:`analysis.metrics.hourly_fleet` with ``t_h``."""
    every = select(series(fleet), only)
    groups = every[:max_panels]
    same_as = twins(groups, lambda g: g.sort_values("t_h")[
        ["t_h", *(c for c in FLEET_STATES if c in g.columns)]].to_numpy(dtype=float))
    k = len(groups)
    cols = 1 if k == 1 else 2 if k <= 8 else 3 if k <= 18 else 4
    rows = max(1, math.ceil(k / cols))
    fig = _figure({1: 8, 2: 10, 3: 13, 4: 16}[cols], 1.4 + (2.4 if cols <= 2 else 2.1) * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)).ravel()
    width = bin_s / 3600
    # by passengers on board: the shared-ride states only where some vehicle had them
    shown = [s for s in FLEET_STATES
             if s not in ("occupied_2", "occupied_3+", *CHARGING_STATES, "on_break")
             or (s in fleet and (fleet[s].fillna(0) > 0).any())]
    for ax, (key, label, g) in zip(axes, groups):
        g = g.sort_values("t_h")
        x = np.r_[g["t_h"].to_numpy(dtype=float), g["t_h"].to_numpy(dtype=float)[-1] + width]
        ys = [np.r_[g[s].to_numpy(dtype=float), g[s].to_numpy(dtype=float)[-1]]
              for s in shown]
        ax.stackplot(x, ys, step="post", colors=[FLEET_COLOURS[s] for s in shown],
                     labels=[FLEET_LABELS[s] for s in shown], linewidth=0)
        n = dict(zip(series_columns(g), key))["n_agents"]
        name = label if "N=" in label else f"{label} (N = {n})"
        ax.set_title(name + (f"\n(= {same_as[label]})" if label in same_as else ""),
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
    # below the panels, in one row: a legend in the upper right corner would run into the title
    fig.legend(h, lab, loc="outside lower center", ncols=min(len(lab), 4), fontsize="small",
               frameon=False)
    more = len(every) - len(groups)
    fig.suptitle((title or "Fleet state over time (stacked)")
                 + (f"\n(the first {len(groups)} of {len(every)} series)" if more else ""))
    return _save(fig, path)


def wait_by_group(waits: pd.DataFrame, path: Path, title: str = "", only=None) -> Path:
    """Left: ECDF of the wait (release -> pickup, minutes) per series (:func:`series`, those
    matching ``only``: :func:`select`); right: box plots (quartiles, whiskers at 1.5 IQR, no
    fliers) per series. A series with exactly the waits of an earlier one (:func:`twins`) is
    drawn dashed and labelled ``= <the other>``. Past :data:`MANY` series the ECDFs are small
    multiples (one panel per N / window / repositioner, allocators coloured alike)."""
    groups = select(series(waits), only)
    labels = [label for _, label, _ in groups]
    data = []
    for _key, _label, g in groups:
        w = np.sort(g["wait"].to_numpy(dtype=float) / 60)
        data.append(w[np.isfinite(w)])
    waits_of = dict(zip(labels, data))
    same_as = twins(groups, lambda g: np.sort(g["wait"].to_numpy(dtype=float)))
    panels = _panels(groups) if len(groups) > MANY else []
    many = len(panels) > 1
    fig = _figure(10.5 if len(groups) <= 10 else 15 if many else 13,
                  max(4.6, 1.4 + 0.24 * len(groups)))
    if many:
        left_fig, right_fig = fig.subfigures(1, 2, width_ratios=[1.5, 1])
        ncol = min(3, len(panels))
        nrow = math.ceil(len(panels) / ncol)
        lefts = left_fig.subplots(nrow, ncol, sharex=True, sharey=True, squeeze=False).ravel()
        right = right_fig.subplots()
        colours_a, _ = _allocator_styles(groups)
        colours = {label: colours_a[_allocator_of(g)] for g, label in zip(groups, labels)}
    else:
        left, right = fig.subplots(1, 2, width_ratios=[1.2, 1])
        colours = _colours(labels)

    def ecdf(ax, label, i, same):
        w = waits_of[label]
        if not len(w):
            return
        twin = same.get(label)
        if many:  # in a panel: allocator names (the panel's title says the rest)
            label_shown = _allocator_of_label(label, groups)
            twin_shown = _allocator_of_label(twin, groups) if twin else None
            width = 1.8
        else:
            label_shown, twin_shown, width = label, twin, max(3.0 - 0.6 * i, 1.0) + 0.6
        ax.step(w, np.arange(1, len(w) + 1) / len(w), where="post", color=colours[label],
                linewidth=1.3 if twin else width,
                linestyle=(0, (3, 2)) if twin else "-", zorder=3 if twin else 2,
                label=f"{label_shown} (median {np.median(w):.1f} min)"
                      + (f" = {twin_shown}" if twin else ""))

    if many:
        panel_of = {label: name for name, members in panels for _k, label, _g in members}
        for ax, (name, members) in zip(lefts, panels):
            here = twins(members, lambda g: np.sort(g["wait"].to_numpy(dtype=float)))
            for i, (_k, label, _g) in enumerate(members):
                ecdf(ax, label, i, here)
            # a whole panel identical to another one (a repositioner that never moved, say)
            others = {panel_of.get(same_as.get(label)) for _k, label, _g in members}
            twin_panel = others.pop() if len(others) == 1 else None
            ax.set_title(name + (f"\n(identical to {twin_panel})" if twin_panel else ""),
                         fontsize="small")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize="xx-small", loc="lower right")
            ax.set_ylim(0, 1.01)
            ax.set_xlim(left=0)
        for ax in lefts[len(panels):]:
            ax.set_visible(False)
        left_fig.supxlabel("wait, release → pickup (min)", fontsize="small")
        left_fig.supylabel("share of the requests picked up", fontsize="small")
        left_fig.suptitle("Wait distribution (ECDF), one panel per N / window / "
                          "repositioner; dashed: identical to another series", fontsize="small")
    else:
        for i, label in enumerate(labels):
            ecdf(left, label, i, same_as)
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
            if labels[i] in same_as:
                box.set_hatch("///")
        for med in bp["medians"]:
            med.set_color("black")
        right.set_yticks(range(1, len(keep) + 1),
                         [labels[i] + (f"  (= {same_as[labels[i]]})" if labels[i] in same_as
                                       else "") for i in keep], fontsize="small")
        right.invert_yaxis()
    right.set_xlabel("wait (min)")
    right.set_title("Per series (box: quartiles;\nhatched: identical to another)"
                    if same_as else "Per series (box: quartiles)", loc="right",
                    fontsize="medium")
    right.grid(True, axis="x", alpha=0.3)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def _allocator_of_label(label: str, groups: list) -> str:
    for g in groups:
        if g[1] == label:
            return _allocator_of(g)
    return label
