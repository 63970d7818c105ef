"""The figures of an electric fleet (``[fleet.energy]``), from the ``soc`` and ``chargers``
tables (Parquet only):

* :func:`soc_over_day`: the fleet's state of charge over the day, one panel per scenario with
  charge data: per series (named in words: ``hungarian N=800``) the median over the vehicles
  and the band (or, with several series in a panel, the lines) of the 10th and 90th
  percentiles;
* :func:`station_map`: the stations on the streets, one panel per scenario: a disc per
  station with its area proportional to the energy delivered and its colour the mean number
  of vehicles queueing (a scale from 0 to at least one vehicle, so that a rare wait does not
  look like a queue), each station named in a column beside the map with a leader line, so
  that labels of stations close together do not overlap.

:func:`energy_section` draws both into a report folder and returns the report items; it gives
nothing for runs without energy (empty tables).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.plots import _colours, _figure, _save

ENERGY_FIGURES = ("soc.png", "stations.png")


def soc_quantiles(soc: pd.DataFrame, keys: list[str]) -> pd.DataFrame:
    """Per series (``keys``) and sample time: the 10 %, 50 % and 90 % quantiles of the
    vehicles' state of charge (seeds pooled)."""
    g = soc.groupby([*keys, "t"], sort=True)["soc"]
    out = g.quantile([0.1, 0.5, 0.9]).unstack()
    out.columns = ["p10", "median", "p90"]
    return out.reset_index()


def soc_over_day(q: pd.DataFrame, path: Path, title: str = "") -> Path:
    """``q`` (:func:`soc_quantiles` rows with the series keys) drawn as one panel per
    scenario; each series labelled in words (:func:`analysis.taxi_plots.series`)."""
    from matplotlib.lines import Line2D

    from analysis.taxi_plots import series

    groups = series(q)
    scenarios = sorted({str(s) for s in q["scenario"]}) if "scenario" in q else [""]
    labels = list(dict.fromkeys(label for _, label, _ in groups))
    colours = _colours(labels)
    fig = _figure(8.5, 1.2 + 3.2 * len(scenarios))
    axes = fig.subplots(len(scenarios), 1, sharex=True, squeeze=False)[:, 0]
    for ax, scen in zip(axes, scenarios):
        mine = [(label, g) for _, label, g in groups
                if not scen or str(g["scenario"].iloc[0]) == scen]
        band = len(mine) <= 2  # bands of more series cover each other: lines instead
        for label, g in mine:
            g = g.sort_values("t")
            h = g["t"].to_numpy(dtype=float) / 3600
            c = colours[label]
            if band:
                ax.fill_between(h, 100 * g["p10"], 100 * g["p90"], color=c, alpha=0.18,
                                linewidth=0)
            else:
                for p in ("p10", "p90"):
                    ax.plot(h, 100 * g[p], color=c, linewidth=0.8, linestyle=":")
            ax.plot(h, 100 * g["median"], color=c, linewidth=1.8, label=_short(label, scen))
        ax.set_ylabel("state of charge (%)")
        ax.set_ylim(0, 100)
        ax.grid(True, alpha=0.3)
        if len(scenarios) > 1:
            ax.set_title(scen, fontsize="medium")
        handles = [Line2D([], [], color=colours[label], linewidth=1.8,
                          label=_short(label, scen)) for label, _ in mine]
        handles.append(Line2D([], [], color="0.3", linewidth=1.8, label="median vehicle"))
        handles.append(
            Line2D([], [], color="0.3", linewidth=6, alpha=0.25,
                   label="10th to 90th percentile of the vehicles") if band else
            Line2D([], [], color="0.3", linewidth=0.8, linestyle=":",
                   label="10th and 90th percentile of the vehicles"))
        ax.legend(handles=handles, fontsize="small", loc="upper left",
                  bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    axes[-1].set_xlabel("time (h)")
    fig.suptitle(title or "State of charge of the fleet", wrap=True)
    return _save(fig, path)


def _short(label: str, scenario: str) -> str:
    """A series label without the scenario its panel already names."""
    return " ".join(w for w in label.split(" ") if w != scenario) if scenario else label


@dataclass(frozen=True)
class StationPanel:
    """One scenario's stations (``chargers`` rows of one run) on its streets (``xy`` node
    positions, ``edges`` index pairs; None: no streets drawn)."""

    title: str
    chargers: pd.DataFrame
    xy: np.ndarray | None = None
    edges: np.ndarray | None = None


def spread(targets: np.ndarray, gap: float, lo: float, hi: float) -> np.ndarray:
    """Label positions for ``targets`` (any order): as near each target as a spacing of at
    least ``gap`` between neighbours allows, in the targets' order, inside [lo, hi] where the
    labels fit in it (else from ``lo`` up)."""
    order = np.argsort(targets, kind="stable")
    t = np.asarray(targets, dtype=float)[order]
    p = np.clip(t, lo, hi)
    for i in range(1, len(p)):  # upward: each at least gap above the one below
        p[i] = max(p[i], p[i - 1] + gap)
    if len(p) and p[-1] > hi:  # over the top: push down, keeping the spacing
        p[-1] = hi
        for i in range(len(p) - 2, -1, -1):
            p[i] = min(p[i], p[i + 1] - gap)
        if p[0] < lo:  # more labels than fit: from the bottom up, the spacing kept
            p = lo + gap * np.arange(len(p))
    out = np.empty_like(p)
    out[order] = p
    return out


def queue_scale(chargers: list[pd.DataFrame]) -> float:
    """The top of the queue colour scale: at least one vehicle queueing, so that 0.0003
    vehicles (one short wait in a day) looks like nothing, which it is."""
    return max([1.0, *(float(ch["mean_queue"].max()) for ch in chargers if len(ch))])


def station_map(panels: list[StationPanel], path: Path, *, title: str = "") -> Path:
    """The stations of each panel on its streets, side by side, one colour scale (mean
    vehicles queueing, from 0 to at least 1) and one size key (kWh delivered)."""
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    kmax = max(float(p.chargers["kwh_delivered"].max()) for p in panels) if panels else 1.0
    kmax = max(kmax, 1e-9)
    qmax = queue_scale([p.chargers for p in panels])
    fig = _figure(4.6 * len(panels) + 1.6, 8.6)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    sc = None
    for ax, p in zip(axes, panels):
        ch, xy = p.chargers, p.xy
        if xy is not None and p.edges is not None and len(p.edges):
            segs = np.stack([xy[p.edges[:, 0], :2], xy[p.edges[:, 1], :2]], axis=1)
            ax.add_collection(LineCollection(segs, colors="0.75", linewidths=0.3, zorder=1))
        pts = ch[["x", "y"]].to_numpy(dtype=float)
        ext = xy[:, :2] if xy is not None and len(xy) else pts
        lo, hi = ext.min(axis=0), ext.max(axis=0)
        span = np.maximum(hi - lo, 1.0)
        kwh = ch["kwh_delivered"].to_numpy(dtype=float)
        sc = ax.scatter(pts[:, 0], pts[:, 1], s=15 + 700 * kwh / kmax, c=ch["mean_queue"],
                        cmap="viridis_r", vmin=0.0, vmax=qmax, edgecolor="black",
                        linewidth=0.5, zorder=3)
        # the labels in a column right of the map, each joined to its station by a line
        label_x = hi[0] + 0.08 * span[0]
        gap = span[1] / 42  # a line of 7-point text on a map about 7 inches high
        ys = spread(pts[:, 1], gap, lo[1], hi[1])
        for (x, y), ly, r in zip(pts, ys, ch.itertuples()):
            ax.plot([x, label_x], [y, ly], color="0.45", linewidth=0.4, zorder=2)
            ax.annotate(f"{r.station_id}  {r.kwh_delivered:,.0f} kWh", (label_x, ly),
                        fontsize=7, va="center", ha="left", zorder=4,
                        xytext=(2, 0), textcoords="offset points")
        ax.set_xlim(lo[0] - 0.03 * span[0], hi[0] + 0.55 * span[0])
        ax.set_ylim(lo[1] - 0.02 * span[1], hi[1] + 0.02 * span[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(p.title, fontsize="medium", wrap=True)
    if sc is not None:
        cb = fig.colorbar(sc, ax=list(axes), shrink=0.6, pad=0.02)
        cb.set_label("mean vehicles queueing for a plug (time average)")
        sizes = sorted({float(f"{k:.1g}") for k in (kmax / 10, kmax / 2, kmax) if k >= 1})
        handles = [Line2D([], [], marker="o", linestyle="", markerfacecolor="white",
                          markeredgecolor="black", markersize=np.sqrt(15 + 700 * k / kmax),
                          label=f"{k:,.0f} kWh") for k in sizes]
        if handles:  # nothing delivered (a short run): no size to key
            axes[0].legend(handles=handles, title="energy delivered", loc="lower left",
                           fontsize="small", title_fontsize="small", labelspacing=1.6,
                           handletextpad=1.6, borderpad=1.0, framealpha=0.9)
    fig.suptitle(title or "Charging stations: energy delivered and queueing", wrap=True)
    return _save(fig, path)


def energy_section(res, summary: pd.DataFrame, out: Path, maps: dict, run_ids: dict,
                   keys: list[str]) -> tuple[list[Path], list]:
    """(files written, report items) of the energy figures; nothing without energy.
    ``run_ids``: per scenario the run whose stations are drawn; ``maps``: per scenario its
    network (``xy``, ``edges``; None where it cannot be rebuilt)."""
    ids = list(summary["run_id"])
    soc = res.table("soc", run_id=ids)
    if soc is None or not len(soc):
        return [], []
    soc = soc.merge(summary[["run_id", *[k for k in keys if k not in soc.columns]]],
                    on="run_id") if any(k not in soc.columns for k in keys) else soc
    q = soc_quantiles(soc, keys)
    q.to_csv(out / "soc.csv", index=False)
    scen = ", ".join(sorted({str(s) for s in q["scenario"]})) if "scenario" in q else ""
    files = [soc_over_day(q, out / "soc.png",
                          title=f"{scen}: state of charge of the fleet over the day"),
             out / "soc.csv"]
    items = [("h2", "Electric fleet"),
             ("p", "State of charge of the fleet over the day (per series, seeds pooled; "
                   "soc.csv), vehicles driving to a charger / queueing / charging in the "
                   "fleet-state picture above, and the load of each station in one run of "
                   "each scenario."),
             ("img", "soc.png")]
    panels = []
    by_run = summary.set_index("run_id")
    for s, rid in run_ids.items():
        ch = res.table("chargers", run_id=rid)
        if ch is None or not len(ch):
            continue
        r = by_run.loc[rid]
        net = maps.get(s)
        panels.append(StationPanel(
            f"{s}: {r['allocator']}, N = {r['n_agents']}, seed {r['seed']}", ch,
            None if net is None else net.xy, None if net is None else net.edges))
    if panels:
        files.append(station_map(panels, out / "stations.png",
                                 title="Charging stations: disc area = energy delivered, "
                                       "colour = mean vehicles queueing"))
        items.append(("img", "stations.png"))
    return files, items
