"""``[faults]``: vehicle breakdowns (a rate, a file of rows) and radio blackouts, as data."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class FaultConfig:
    rate: float = 0.0  # breakdowns per vehicle-hour of service
    repair: float = 600.0  # seconds a random breakdown lasts; inf: for good
    events: tuple[tuple[float, int, float], ...] = ()  # (t, vehicle_id, duration) from a file
    on_board: str = "transfer"  # "transfer" | "fail"
    tow: float = 3600.0  # seconds until a stranded vehicle ([fleet.energy]) is towed
    #: windows [t0, t1) in which every communication link is down (or only links with an end
    #: in ``blackout_region``)
    blackout: tuple[tuple[float, float], ...] = field(
        default=(), metadata={"toml": "array of [t0, t1] (simulated seconds)"})
    region: tuple[float, float, float, float] | None = None

    @property
    def vehicles(self) -> bool:
        return self.rate > 0 or bool(self.events)
