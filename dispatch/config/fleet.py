"""``[fleet]``: the vehicles of a run, their speeds, seats, start and shifts, as data (the
batteries of ``[fleet.energy]``: :mod:`dispatch.config.energy`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class FleetConfig:
    agents: int = 8  # vehicles in the fleet (N); a start file's rows win
    uav_fraction: float = 0.5  # share of the fleet that flies (rounded to whole vehicles)
    uav_speed: float = 5.0  # m/s of the flying vehicles (UAVs, voxel world)
    ugv_speed: float = 3.0  # m/s of the ground vehicles (UGVs, voxel world)
    uav_max_start_altitude: float = 10.0  # metres: UAVs start in a free cell at or below this
    #: where the fleet starts (``[fleet] start``): ``(vehicle_id, a, b, c)`` rows from a CSV file;
    #: ``a`` a road node id (b, c nan) or ``(a, b[, c])`` a position in metres; empty: random
    start: tuple[tuple, ...] = field(
        default=(), metadata={"toml": "string (a CSV file, relative to the scenario file)",
                              "default": "(unset: random places)"})
    start_file: Path | None = None
    #: roads, without a start file: "uniform" nodes, or "demand" (the empirical sample's
    #: pickup nodes, weighted by their trips)
    placement: str = "uniform"
    #: seats per vehicle (``[fleet] capacity``); a start file's ``capacity`` column per vehicle
    #: (row order; 0: the fleet's)
    capacity: int = 1
    capacities: tuple[int, ...] = ()
    #: ``[fleet.energy]`` (:class:`dispatch.config.energy.EnergyConfig`); None: no batteries
    energy: Any = None
    #: the start file's shift columns (:class:`dispatch.fleet.shifts.ShiftTable`); None: none
    shifts: Any = None
    #: seconds after its shift's end a vehicle may still complete its plan's last stop
    shift_grace: float = 0.0
    #: ``[fleet] sizing``: the fleet-sizing strategy (``dispatch.sizers``; unset: as ``fixed``,
    #: every vehicle on duty over its shift) and its ``[fleet.sizing_params]``
    sizing: str | None = None
    #: the ``[fleet.sizing_params]`` table: keyword arguments of the sizing strategy's
    #: constructor
    sizing_params: tuple[tuple[str, Any], ...] = ()
    #: ``[fleet.breaks]`` (:class:`dispatch.config.breaks.BreaksConfig`); None: no breaks
    breaks: Any = None

    @property
    def pooled(self) -> bool:
        """Some vehicle has more than one seat: busy vehicles take part in decisions."""
        return self.capacity > 1 or any(c > 1 for c in self.capacities)

    @property
    def n_uav(self) -> int:
        return int(round(self.agents * self.uav_fraction))
