"""The figures of an electric fleet (``[fleet.energy]``), from the ``soc`` and ``chargers``
tables (Parquet only):

* :func:`soc_over_day`: the fleet's state of charge over the day, median and 10-90 % band,
  one line per series;
* :func:`station_map`: the stations on the streets, a disc per station with its area
  proportional to the energy delivered and its colour the mean number of vehicles queueing.

:func:`energy_section` draws both into a report folder and returns the report items; it gives
nothing for runs without energy (empty tables).
"""

from __future__ import annotations

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


def soc_over_day(q: pd.DataFrame, keys: list[str], path: Path, title: str = "") -> Path:
    fig = _figure(8.5, 4.4)
    ax = fig.add_subplot()
    labels = [" ".join(str(x) for x in k) if isinstance(k, tuple) else str(k)
              for k, _ in q.groupby(keys, sort=False)]
    colours = _colours(labels)
    for (k, g), label in zip(q.groupby(keys, sort=False), labels):
        h = g["t"].to_numpy(dtype=float) / 3600
        ax.fill_between(h, 100 * g["p10"], 100 * g["p90"], color=colours[label], alpha=0.18,
                        linewidth=0)
        ax.plot(h, 100 * g["median"], color=colours[label], label=f"{label}: median")
    ax.set_xlabel("time (h)")
    ax.set_ylabel("state of charge (%)")
    ax.set_ylim(0, 100)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small", loc="lower left")
    ax.set_title(title or "State of charge of the fleet: median, 10-90 % band", wrap=True)
    return _save(fig, path)


def station_map(ch: pd.DataFrame, path: Path, *, xy=None, edges=None, title: str = "") -> Path:
    """One run's ``chargers`` rows on the streets."""
    from matplotlib.collections import LineCollection

    fig = _figure(7.5, 8.0)
    ax = fig.add_subplot()
    if xy is not None and edges is not None and len(edges):
        segs = np.stack([xy[edges[:, 0], :2], xy[edges[:, 1], :2]], axis=1)
        ax.add_collection(LineCollection(segs, colors="0.7", linewidths=0.3, zorder=1))
    kwh = ch["kwh_delivered"].to_numpy(dtype=float)
    size = 20 + 900 * kwh / max(float(kwh.max()), 1e-9)
    sc = ax.scatter(ch["x"], ch["y"], s=size, c=ch["mean_queue"], cmap="viridis_r",
                    edgecolor="black", linewidth=0.5, zorder=3, vmin=0)
    for r in ch.itertuples():
        ax.annotate(f"{r.station_id}\n{r.kwh_delivered:,.0f} kWh", (r.x, r.y), fontsize=6,
                    xytext=(6, 6), textcoords="offset points", zorder=4)
    cb = fig.colorbar(sc, ax=ax, shrink=0.7)
    cb.set_label("mean vehicles queueing")
    if xy is not None:
        lo, hi = xy[:, :2].min(axis=0), xy[:, :2].max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title or "Station load (disc area: energy delivered)", wrap=True)
    return _save(fig, path)


def energy_section(res, summary: pd.DataFrame, out: Path, net, run_id: str, keys: list[str],
                   scen: str) -> tuple[list[Path], list]:
    """(files written, report items) of the energy figures; nothing without energy."""
    ids = list(summary["run_id"])
    soc = res.table("soc", run_id=ids)
    if soc is None or not len(soc):
        return [], []
    soc = soc.merge(summary[["run_id", *[k for k in keys if k not in soc.columns]]],
                    on="run_id") if any(k not in soc.columns for k in keys) else soc
    q = soc_quantiles(soc, keys)
    q.to_csv(out / "soc.csv", index=False)
    files = [soc_over_day(q, keys, out / "soc.png",
                          title=f"{scen}: state of charge of the fleet (median, 10-90 %)"),
             out / "soc.csv"]
    items = [("h2", "Electric fleet"),
             ("p", "State of charge of the fleet over the day (per series, seeds pooled; "
                   "soc.csv), vehicles driving to a charger / queueing / charging in the "
                   "fleet-state picture above, and the load of each station in one run."),
             ("img", "soc.png")]
    ch = res.table("chargers", run_id=run_id)
    if ch is not None and len(ch):
        files.append(station_map(ch, out / "stations.png",
                                 xy=None if net is None else net.xy,
                                 edges=None if net is None else net.edges,
                                 title=f"{run_id}: station load (disc area: energy "
                                       f"delivered; colour: mean queue)"))
        items.append(("img", "stations.png"))
    return files, items
