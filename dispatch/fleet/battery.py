"""Batteries of an electric fleet (``[fleet.energy]``) and the dispatcher's reserve rule.

Everything here is off unless the scenario has ``[fleet.energy]``; a run without it builds none
of it and its tables are today's.

Energy
    Each vehicle carries a :class:`Battery`. A leg draws ``wh_per_km`` at the leg's mean speed
    (a constant, or a table of ``[km/h, Wh/km]`` points interpolated linearly, like HIVE's
    tabular powertrain) times its length, when it is counted (:meth:`dispatch.plan.vehicles.Vehicle.
    drove`: a leg cut part-way by a decision, a breakdown or the horizon draws what was driven,
    at the cut part's mean speed). ``idle_kwh_per_hour`` is drawn over every second the
    vehicle is not plugged in (auxiliary load). The battery never goes below 0 kWh: a vehicle
    whose next leg would empty it drives until it is empty and is *stranded*. Energy is
    conserved: ``kwh0 + kwh_charged - kwh_drawn = kwh`` at every instant.

Reserve
    A vehicle whose plan, with a new request, would leave it below ``reserve`` of its battery
    is not a candidate for the request (``inf`` cost): the dispatcher estimates the energy of
    the plan's remaining drive seconds plus the drive to the pickup and the trip's direct time
    at the fleet's reference consumption (:attr:`Energy.kwh_per_second`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import simpy

from dispatch.config.energy import EnergyConfig

if TYPE_CHECKING:
    from dispatch.plan.vehicles import Fleet


class Battery:
    """One vehicle's battery (kWh). ``now`` gives the simulated time (auxiliary draw is
    settled lazily: :meth:`settle`)."""

    __slots__ = ("cfg", "capacity", "kwh", "kwh0", "drawn", "aux", "charged", "charge_seconds",
                 "queue_seconds", "kwh_min", "t", "plugged", "now", "arr", "slot")

    def __init__(self, cfg: EnergyConfig, soc: float, now: Callable[[], float],
                 arr: np.ndarray, slot: int) -> None:
        self.cfg, self.capacity = cfg, cfg.battery_kwh
        self.kwh = self.kwh0 = self.kwh_min = soc * cfg.battery_kwh
        self.drawn = self.charged = self.charge_seconds = self.queue_seconds = 0.0
        self.aux = 0.0  # the part of drawn the auxiliary load took (the rest: driving)
        self.t, self.plugged, self.now = 0.0, False, now
        self.arr, self.slot = arr, slot
        arr[slot] = self.kwh

    @property
    def soc(self) -> float:
        return self.kwh / self.capacity

    def _take(self, e: float) -> float:
        take = min(max(e, 0.0), self.kwh)
        self.kwh -= take
        self.drawn += take
        if self.kwh < self.kwh_min:
            self.kwh_min = self.kwh
        self.arr[self.slot] = self.kwh
        return take

    def settle(self) -> None:
        """Draw the auxiliary load up to now (nothing while plugged in)."""
        now = self.now()
        if now > self.t:
            if not self.plugged and self.cfg.idle_kwh_per_hour:
                self.aux += self._take(self.cfg.idle_kwh_per_hour * (now - self.t) / 3600.0)
            self.t = now

    def leg_kwh(self, metres: float, seconds: float) -> float:
        """kWh a drive of ``metres`` in ``seconds`` draws (without the auxiliary load)."""
        speed = metres / seconds if seconds > 0 else 0.0
        return metres * self.cfg.wh_per_metre(speed) / 1000.0

    def drive(self, metres: float, seconds: float) -> None:
        self.settle()
        self._take(self.leg_kwh(metres, seconds))

    def runs_out(self, metres: float, seconds: float) -> float | None:
        """Seconds into a leg of ``metres`` in ``seconds`` at which the battery is empty, or
        None if it lasts the leg."""
        self.settle()
        aux = self.cfg.idle_kwh_per_hour * seconds / 3600.0
        need = self.leg_kwh(metres, seconds) + aux
        if need <= self.kwh + 1e-12:
            return None
        return seconds * self.kwh / need if need > 0 else 0.0

    def add(self, e: float) -> None:
        e = min(max(e, 0.0), self.capacity - self.kwh)
        self.kwh += e
        self.charged += e
        self.arr[self.slot] = self.kwh


class Energy:
    """The run's batteries and the dispatcher's reserve rule."""

    def __init__(self, cfg: EnergyConfig, fleet: Fleet, env: simpy.Environment,
                 ref_speed: float) -> None:
        self.cfg, self.fleet, self.env = cfg, fleet, env
        n = len(fleet)
        self.kwh = np.zeros(n)
        now = lambda: env.now  # noqa: E731
        for i, v in enumerate(fleet.vehicles):
            soc = cfg.socs[i] if i < len(cfg.socs) and cfg.socs[i] == cfg.socs[i] else cfg.soc0
            v.battery = Battery(cfg, soc, now, self.kwh, v._slot)
        #: kWh per second of driving at the reference speed (the network's mean free speed)
        self.kwh_per_second = cfg.wh_per_metre(ref_speed) * ref_speed / 1000.0
        self.reserve_kwh = cfg.reserve * cfg.battery_kwh

    def filter(self, cost: np.ndarray, drive: np.ndarray, slots: np.ndarray, tasks,
               holders: frozenset = frozenset()) -> np.ndarray:
        """``cost`` with ``inf`` where vehicle ``slots[i]`` would end below the reserve after
        the plan and request ``j`` (``drive``: seconds from each vehicle to each pickup).
        ``holders``: ids of vehicles driving to a pickup they may give up (``[dispatch]
        reassign``), whose plans count as empty, as the decision's costs take them (counting
        the held trip too ruled each holder out of its own task in turn: two vehicles handed
        one task back and forth at one instant forever)."""
        vs = self.fleet.vehicles
        plan_s = np.array([0.0 if vs[k].id in holders else sum(s.leg for s in vs[k].plan)
                           for k in slots.tolist()]) if slots.size else np.zeros(0)
        direct = np.array([0.0 if t.dropoff is None or t.direct_time != t.direct_time
                           else t.direct_time for t in tasks])
        need = (plan_s[:, None] + drive + direct[None, :]) * self.kwh_per_second
        ok = self.kwh[slots][:, None] - need >= self.reserve_kwh
        return np.where(ok, cost, np.inf)

    def sampler(self, append: Callable[[tuple], None]):
        """Process: every ``sample`` seconds from 0, one ``soc`` row per vehicle."""
        ids = [v.id for v in self.fleet.vehicles]
        while True:
            self.settle_all()
            t = float(self.env.now)
            cap = self.cfg.battery_kwh
            for vid, k in zip(ids, (self.kwh / cap).tolist()):
                append((t, vid, k))
            yield self.env.timeout(self.cfg.sample)

    def settle_all(self) -> None:
        for v in self.fleet.vehicles:
            v.battery.settle()
