"""The summary's energy columns of an electric run (``[fleet.energy]``).

:class:`EnergyTally` counts, from the event stream, the charges (a vehicle plugged in:
``charge_start``) and the strandings (a battery run empty: ``stranded``);
:func:`energy_columns` adds the fleet's batteries at the end of the run (settled, the charges
the end cut counted): kWh drawn (and the part of it the auxiliary load drew, idle or
driving) and charged, the lowest state of charge any vehicle reached,
the fleet's mean state of charge at the end and the seconds vehicles queued at stations.
A run without energy gets NaN for the figures and 0 for the counts (nothing charged, nobody
stranded).
"""

from __future__ import annotations

import math

#: the summary's energy columns, in schema order (see :data:`dispatch.output.parquet.SCHEMAS`)
ENERGY_COLUMNS = ("kwh_drawn", "kwh_charged", "charges", "strandings", "soc_min",
                  "soc_end_mean", "queue_seconds", "kwh_auxiliary")


class EnergyTally:
    """Charges started and vehicles stranded, counted as their events are emitted on
    ``bus``."""

    def __init__(self, bus) -> None:
        self.charges = 0
        self.strandings = 0
        bus.subscribe(self._charge, ["charge_start"])
        bus.subscribe(self._stranded, ["stranded"])

    def _charge(self, _event) -> None:
        self.charges += 1

    def _stranded(self, _event) -> None:
        self.strandings += 1


def energy_columns(tally: EnergyTally | None, vehicles) -> dict:
    """The :data:`ENERGY_COLUMNS` of a run whose ``vehicles`` have settled batteries (``tally``
    None: a run without energy)."""
    if tally is None:
        return {"kwh_drawn": math.nan, "kwh_charged": math.nan, "charges": 0, "strandings": 0,
                "soc_min": math.nan, "soc_end_mean": math.nan, "queue_seconds": math.nan,
                "kwh_auxiliary": math.nan}
    bats = [v.battery for v in vehicles]
    return {"kwh_drawn": float(sum(b.drawn for b in bats)),
            "kwh_charged": float(sum(b.charged for b in bats)),
            "charges": tally.charges, "strandings": tally.strandings,
            "soc_min": min((b.kwh_min / b.capacity for b in bats), default=math.nan),
            "soc_end_mean": (sum(b.soc for b in bats) / len(bats)) if bats else math.nan,
            "queue_seconds": float(sum(b.queue_seconds for b in bats)),
            "kwh_auxiliary": float(sum(b.aux for b in bats))}


def electric(s: dict) -> bool:
    """Whether the summary row ``s`` is of a run with energy (its kWh drawn is a number)."""
    v = s.get("kwh_drawn")
    return v is not None and v == v


def energy_line(s: dict) -> str:
    """One run's energy, in words, for the CLI's summary: kWh drawn (fleet and per vehicle;
    driving and the auxiliary load apart, so that kWh per km is the driving part over the km)
    and charged, charges, queueing, the lowest and the mean end state of charge, strandings."""
    n = max(int(s.get("n_agents", 0)), 1)
    stranded = s.get("strandings", 0)
    aux = s.get("kwh_auxiliary", math.nan)  # (a summary written before it was a column: nan)
    split = "" if aux != aux else (f"; {s['kwh_drawn'] - aux:,.1f} kWh driving, {aux:,.1f} kWh "
                                   "the auxiliary load")
    return (f"{s['kwh_drawn']:,.1f} kWh drawn ({s['kwh_drawn'] / n:.2f} kWh per vehicle{split}), "
            f"{s['kwh_charged']:,.1f} kWh charged in {s.get('charges', 0):,} charges, "
            f"{s['queue_seconds'] / 3600:,.1f} h queued; state of charge lowest "
            f"{100 * s['soc_min']:.1f}%, mean at the end {100 * s['soc_end_mean']:.1f}%; "
            f"{stranded:,} {'vehicle' if stranded == 1 else 'vehicles'} stranded")


#: The energy table's figures: (column, digits, scale, value of one run's summary row).
ENERGY_FIGURES = (
    ("kWh/veh", 2, 1.0, lambda r: r["kwh_drawn"] / r["n_agents"]),
    ("charged", 2, 1.0, lambda r: r["kwh_charged"] / r["n_agents"]),
    ("charges", 0, 1.0, lambda r: r["charges"]),
    ("queue h", 1, 1 / 3600, lambda r: r["queue_seconds"]),
    ("low %", 1, 100, lambda r: r["soc_min"]),
    ("end %", 1, 100, lambda r: r["soc_end_mean"]),
    ("strand.", 0, 1.0, lambda r: r["strandings"]),
)
