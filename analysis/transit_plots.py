"""The figure of riders who may take the train (``[transit]``), from the summary's transit
columns and the ``legs`` table (Parquet only):

* :func:`mode_split`: per series (named in words: ``hungarian N=90``), the share of the riders
  by the option they chose (door to door by the fleet, fleet then train, train then fleet,
  train alone) as one stacked bar, and beside it the door-to-door time of the served riders by
  option (median and the 10th to 90th percentile) from the legs table.

:func:`transit_section` draws it into a report folder and returns the report items; it gives
nothing for runs without ``[transit]`` (no ``riders`` column).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from analysis.plots import _figure, _save

#: the summary's mode share columns and their names in words, in the order of the bars
MODES = (("fleet", "door to door"), ("fleet_train", "fleet, then train"),
         ("train_fleet", "train, then fleet"), ("train", "walk and train"))
COLOURS = ("#4c72b0", "#dd8452", "#55a868", "#8172b3")
TRANSIT_FIGURES = ("mode_split.png",)


def door_to_door(legs: pd.DataFrame, tasks: pd.DataFrame) -> pd.DataFrame:
    """Per run and served rider (no fleet request of theirs ended otherwise): the option they took (by their legs' modes in order) and
    their door-to-door seconds (request, the tasks' release for a fleet rider, else the first
    leg's start, to the last leg's end)."""
    failed = tasks.loc[tasks["state"] != "completed"].set_index(["run_id", "request_id"]).index
    legs = legs.sort_values(["run_id", "request_id", "leg"])
    legs = legs.loc[~legs.set_index(["run_id", "request_id"]).index.isin(failed)]
    g = legs.groupby(["run_id", "request_id"], sort=False)
    modes = g["mode"].agg(lambda m: "+".join(dict.fromkeys(x for x in m if x != "walk")))
    out = pd.DataFrame({"mode": modes, "start": g["start"].min(), "end": g["end"].max()})
    kind = {"fleet": "fleet", "fleet+train": "fleet_train", "train+fleet": "train_fleet",
            "train": "train"}
    out["mode"] = out["mode"].map(kind)
    released = tasks.groupby(["run_id", "request_id"])["released_at"].min()
    start = released.reindex(out.index)
    # a train+fleet rider's task is released at their arrival: the walk is the trip's start
    first = np.where(out["mode"].isin(["fleet", "fleet_train"]) & start.notna(), start,
                     out["start"])
    out["seconds"] = out["end"] - first
    return out.reset_index()


def mode_split(summary: pd.DataFrame, trips: pd.DataFrame, path: Path, title: str = "") -> Path:
    """The shares of ``summary``'s rows (one bar per run) and the door-to-door times of
    ``trips`` (:func:`door_to_door`) by option."""
    rows = summary.sort_values(["scenario", "allocator", "n_agents", "seed"])
    labels = [f"{r.allocator} N={r.n_agents} s{r.seed}" for r in rows.itertuples()]
    fig = _figure(10.0, 1.6 + 0.45 * max(len(rows), 3))
    ax, bx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.2, 1.0]})
    y = np.arange(len(rows))
    left = np.zeros(len(rows))
    for (key, name), c in zip(MODES, COLOURS):
        share = rows[f"mode_share_{key}"].fillna(0.0).to_numpy(dtype=float)
        ax.barh(y, share * 100, left=left, color=c, label=name)
        left += share * 100
    ax.set_yticks(y, labels)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the riders (%)")
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=2, fontsize="small",
              frameon=False)
    done = trips.loc[trips["run_id"].isin(set(rows["run_id"]))]
    right = 0.0
    for k, ((key, name), c) in enumerate(zip(MODES, COLOURS)):
        s = done.loc[done["mode"] == key, "seconds"].to_numpy(dtype=float) / 60
        if s.size:
            lo, mid, hi = np.percentile(s, [10, 50, 90])
            bx.errorbar([mid], [k], xerr=[[mid - lo], [hi - mid]], fmt="o", color=c,
                        capsize=4)
            bx.annotate(f"{s.size} riders", (hi, k), xytext=(4, 0),
                        textcoords="offset points", va="center", fontsize="small")
            right = max(right, hi)
    bx.set_yticks(range(len(MODES)), [n for _, n in MODES])
    bx.invert_yaxis()
    bx.set_xlim(0, max(right, 1.0) * 1.3)  # (room for the counts)
    bx.set_xlabel("door to door (min): median, p10 to p90")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def transit_section(res, summary: pd.DataFrame, out: Path) -> tuple[list[Path], list]:
    """The mode split figure of the runs with ``[transit]`` and its report items (none
    without)."""
    if "riders" not in summary or not summary["riders"].notna().any():
        return [], []
    runs = summary.loc[summary["riders"].notna()]
    ids = list(runs["run_id"])
    legs = res.table("legs", run_id=ids)
    tasks = res.table("tasks", columns=["request_id", "released_at", "state"], run_id=ids)
    trips = door_to_door(legs, tasks) if len(legs) else pd.DataFrame(
        columns=["run_id", "request_id", "mode", "seconds"])
    path = mode_split(runs, trips, out / "mode_split.png",
                      title="Riders by the option they chose, and their door-to-door time")
    table = runs[["run_id", "riders", "riders_served", "vehicle_km_per_rider",
                  "door_to_door_median", "door_to_door_p90", "missed_connections"]]
    return [path], [
        ("h2", "Riders and the train"),
        ("p", "Runs with [transit]: riders, those served (every leg made), vehicle-km per "
              "served rider, door-to-door seconds of the served riders (median, 90th "
              "percentile) and feeders that missed their train (summary columns; every leg in "
              "the legs table)."),
        ("table", table),
        ("img", "mode_split.png"),
    ]
