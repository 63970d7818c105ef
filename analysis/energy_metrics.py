"""The energy columns of the taxi metrics (``taxi.csv``, ``runs.csv``) of electric runs
(``[fleet.energy]``), from the ``vehicles`` table and the event stream (Parquet only):

``kwh_drawn_per_vehicle``, ``kwh_charged_per_vehicle``
    kWh drawn from the batteries (driving and auxiliary load) and charged into them, mean
    over the vehicles (of every run pooled);
``charges``
    charges started (``charge_start`` events: a vehicle plugged in), summed over the runs;
``strandings``
    vehicles whose battery ran empty on the road (``stranded`` events), summed over the runs;
``soc_min``
    the lowest state of charge (0-1) any vehicle reached;
``soc_end_mean``
    the vehicles' mean state of charge at the end of the run (0-1);
``queue_seconds_per_vehicle``
    seconds spent queueing at a station for a free plug, mean over the vehicles.

Runs without energy get NaN in every column.
"""

from __future__ import annotations

import math

import pandas as pd

ENERGY_COLUMNS = ["kwh_drawn_per_vehicle", "kwh_charged_per_vehicle", "charges", "strandings",
                  "soc_min", "soc_end_mean", "queue_seconds_per_vehicle"]


def energy_events(events: pd.DataFrame | None) -> pd.DataFrame:
    """Per run: ``charges`` and ``strandings`` counted from ``events`` (0 for a run with
    events but none of those; no row for a run without events)."""
    cols = ["run_id", "charges", "strandings"]
    if events is None or events.empty:
        return pd.DataFrame(columns=cols)
    kinds = events["event"].to_numpy()
    counts = pd.DataFrame({"run_id": events["run_id"].to_numpy(),
                           "charges": kinds == "charge_start",
                           "strandings": kinds == "stranded"})
    return counts.groupby("run_id", sort=False, observed=True)[["charges", "strandings"]] \
        .sum().astype(int).reset_index()


def electric(vehicles: pd.DataFrame) -> bool:
    """Whether ``vehicles`` holds rows of a run with energy (a kWh figure that is a number)."""
    return "kwh_drawn" in vehicles and bool(vehicles["kwh_drawn"].notna().any())


def energy_stats(vehicles: pd.DataFrame, counts: pd.DataFrame | None) -> dict:
    """The :data:`ENERGY_COLUMNS` of ``vehicles`` (rows of one or more runs) and ``counts``
    (their rows of :func:`energy_events`; None: no events read)."""
    if not electric(vehicles):
        return dict.fromkeys(ENERGY_COLUMNS, math.nan)
    v = vehicles.loc[vehicles["kwh_drawn"].notna()]
    have = counts is not None and len(counts)
    return {"kwh_drawn_per_vehicle": float(v["kwh_drawn"].mean()),
            "kwh_charged_per_vehicle": float(v["kwh_charged"].mean()),
            "charges": int(counts["charges"].sum()) if have else math.nan,
            "strandings": int(counts["strandings"].sum()) if have else math.nan,
            "soc_min": float(v["soc_min"].min()),
            "soc_end_mean": float(v["soc_end"].mean()),
            "queue_seconds_per_vehicle": float(v["queue_seconds"].mean())}
