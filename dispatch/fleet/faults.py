"""Faults: vehicles that break down, radios that go quiet.

Vehicle breakdowns (``[faults]``) come from two sources, both SimPy processes:

* a **rate** per vehicle-hour: each vehicle's time to its next breakdown is exponential
  (drawn from the run's fault stream), counted while it is in service; a random breakdown lasts
  ``repair`` seconds (``inf``: for good);
* a **file** of breakdowns: rows ``t, vehicle_id, duration`` (``inf``: for good).

What a breakdown does to the vehicle and its trip is
:meth:`dispatch.plan.breakdowns.Breakdowns.breakdown`:
it stops where it is; a trip not yet picked up goes back to open and is re-assigned; a
passenger on board is either transferred (``on_board = "transfer"``: another vehicle picks them
up where the failed one stopped) or the trip ends ``failed`` (``on_board = "fail"``).

A communication **blackout** (``blackout = [[t0, t1], ...]``, optionally only inside
``blackout_region = [x0, y0, x1, y1]``) cuts every link (or every link with an end in the
region) of decisions taken in ``[t0, t1)``: decentralized allocators then hear only themselves
(and whoever is still linked); the kernel's conflict rule still settles every task.
"""

from __future__ import annotations

import math

import numpy as np
import simpy

from dispatch.config.faults import FaultConfig


class FaultInjector:
    """Starts the breakdown processes of a run (see the module docstring)."""

    def __init__(self, env: simpy.Environment, cfg: FaultConfig, fleet, operator,
                 rng: np.random.Generator) -> None:
        self.env, self.cfg, self.fleet, self.operator, self.rng = env, cfg, fleet, operator, rng
        self.injected = 0
        if cfg.rate > 0:
            for v in fleet.vehicles:
                env.process(self._random(v))
        if cfg.events:
            env.process(self._scheduled())

    def _break(self, v, duration: float) -> None:
        if self.operator.breakdown(v, duration, self.cfg.on_board == "transfer"):
            self.injected += 1

    def _random(self, v):
        mean = 3600.0 / self.cfg.rate
        while True:
            yield self.env.timeout(float(self.rng.exponential(mean)))
            if v.failed:  # failed by the file meanwhile: wait for its repair
                continue
            self._break(v, self.cfg.repair)
            if math.isinf(self.cfg.repair):
                return
            yield self.env.timeout(self.cfg.repair)

    def _scheduled(self):
        for t, vid, duration in self.cfg.events:
            if t > self.env.now:
                yield self.env.timeout(t - self.env.now)
            v = self.fleet.by_id.get(vid)
            if v is not None:
                self._break(v, duration)


def blackout_filter(cfg: FaultConfig):
    """``f(comm, positions, now) -> comm`` cutting the links of a blackout, or None."""
    if not cfg.blackout:
        return None

    def cut(comm: np.ndarray, pos: np.ndarray, now: float) -> np.ndarray:
        if not any(t0 <= now < t1 for t0, t1 in cfg.blackout):
            return comm
        if cfg.region is None:
            inside = np.ones(len(pos), dtype=bool)
        else:
            x0, y0, x1, y1 = cfg.region
            inside = ((pos[:, 0] >= x0) & (pos[:, 0] <= x1)
                      & (pos[:, 1] >= y0) & (pos[:, 1] <= y1))
        out = comm & ~(inside[:, None] | inside[None, :])
        np.fill_diagonal(out, True)
        return out

    return cut
