"""A learned value of a vehicle's post-decision state: zone x time of day (x free seats, for
shared rides), by temporal-difference learning on simulated days, used in the assignment as
DiDi (Tang et al., KDD 2019) and NeurADP (Shah et al., AAAI 2020) do.

The value ``V(z, t, s)`` is the discounted number of requests a vehicle whose plan ends in zone
``z`` at time ``t`` with ``s`` free seats will still serve (discount per second ``gamma``, from
a half-life); a single-seat value has one seat class. It is learned by
:mod:`learning.value_train` (``dispatch train value``) and answers the plugin-facing
:class:`dispatch.api.value.ValueFunction`: every allocator that takes a ``value`` file uses it
through :func:`dispatch.api.value.value_costs` (``hungarian``, ``local_hungarian``,
``magnnet``; with plans, the pooled insertion's post-decision ends), ``rtv`` on its routes'
ends, and the ``demand`` repositioner. A pair's cost becomes

    dt = seconds until the pair's plan ends (cost + expected trip, or the insertion's end)
    cost[i, j] - weight * (gamma^dt * V(zone(end_ij), now + dt, seats_ij)
                           - gamma^dt_i * V(zone(end_i), now + dt_i, seats_i))

where ``end_i``, ``dt_i`` and ``seats_i`` are vehicle ``i``'s own plan's end (an idle vehicle:
where it is, now, all seats free): what taking request ``j`` adds to the vehicle's future. The
expected trip is a fit of the simulated trips' durations on the straight-line distance
from pickup to drop-off, per hour of the day, and ``weight`` seconds per served request (the
exchange rate between waiting and the future). A file records the network it was learned on
(its node positions and their fingerprint, :func:`dispatch.api.value.network_key`); on
another network the allocator stops the run with one line
(:class:`dispatch.api.value.NetworkMismatch`).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dispatch.api.value import NetworkMismatch, network_key, value_costs
from learning.zones import Zones

ROOT = Path(__file__).resolve().parents[1]
log = logging.getLogger(__name__)


@dataclass
class ZoneValue:
    """The learned table and what using it needs (load with :meth:`load`); a
    :class:`dispatch.api.value.ValueFunction`."""

    zones: Zones
    node_xy: np.ndarray  # (n_nodes, 2) metres: the network the value was learned on
    bin_s: float  # seconds per time bin
    table: np.ndarray  # (n_zones * seats, n_bins); 0 outside a zone and after the last bin
    gamma: float  # discount per second
    weight: float  # seconds of cost per unit of value
    trip_fit: np.ndarray  # (24, 2): per hour, trip seconds = a + b * straight-line metres
    meta: dict
    seats: int = 1  # seat classes: row zone * seats + min(free seats, seats - 1)
    _checked: bool = False

    @property
    def network(self) -> str:
        """The fingerprint of the network the value was learned on."""
        return network_key(self.node_xy)

    # ------------------------------------------------------------------ using it
    def of_zone(self, zone: np.ndarray, t: np.ndarray, seats=None) -> np.ndarray:
        """``V(zone, t, seats)`` element-wise (broadcast); 0 for zone -1 or beyond the last
        bin; seats None: the most free seats."""
        zone, t = np.broadcast_arrays(np.asarray(zone, np.int64), np.asarray(t, float))
        if self.seats > 1:
            s = self.seats - 1 if seats is None else np.clip(
                np.broadcast_to(np.asarray(seats, np.int64), zone.shape), 0, self.seats - 1)
            zone = np.where(zone >= 0, zone * self.seats + s, -1)
        b = np.floor(t / self.bin_s).astype(np.int64)
        ok = (zone >= 0) & (b >= 0) & (b < self.table.shape[1])
        out = np.zeros(zone.shape)
        out[ok] = self.table[zone[ok], b[ok]]
        return out

    def value(self, place, time, seats_left=None) -> np.ndarray:
        """``V`` of a vehicle at node ``place`` at ``time`` with ``seats_left`` free seats
        (:class:`dispatch.api.value.ValueFunction`); a node beyond the network's raises
        :class:`~dispatch.api.value.NetworkMismatch`."""
        place = np.asarray(place, np.int64)
        if place.size and int(place.max()) >= len(self.node_xy):
            raise NetworkMismatch(
                f"the value was learned on another road network (node {int(place.max())} is "
                f"beyond its {len(self.node_xy)} nodes): train one for this network")
        return self.of_zone(self.zones.of_node[place], time, seats_left)

    def trip_seconds(self, pickup, dropoff, t: float) -> np.ndarray:
        """Expected drive from pickup to drop-off node (the fit of the hour of ``t``)."""
        d = np.hypot(*(self.node_xy[dropoff] - self.node_xy[pickup]).T)
        a, b = self.trip_fit[int(t // 3600) % 24]
        return np.maximum(a + b * d, 0.0)

    def check(self, problem) -> None:
        """Refuse (one line, :class:`~dispatch.api.value.NetworkMismatch`) a problem whose
        pickups do not lie on this value's network (the node ids past its nodes, or their
        positions more than a metre off); checked on the first problem with tasks only."""
        if self._checked or not problem.tasks:
            return
        from dispatch.api.value import nodes_of

        got = nodes_of(problem)
        if got is None:
            return
        picks = got[1]
        bad = int(picks.max()) >= len(self.node_xy)
        if not bad:
            off = np.hypot(*(self.node_xy[picks] - np.asarray(problem.task_pos)[:, :2]).T)
            bad = bool((off > 1.0).any())
        if bad:
            raise NetworkMismatch(
                f"the value {self.meta.get('file', '')} was learned on another road network "
                f"(fingerprint {self.network}, scenario {self.meta.get('scenario', '?')}): "
                "train one for this network")
        self._checked = True

    def adjusted(self, problem, weight: float | None = None) -> np.ndarray:
        """The problem's cost with the value of each pair
        (:func:`dispatch.api.value.value_costs`)."""
        self.check(problem)
        return value_costs(problem, self, self.weight if weight is None else weight)

    # ------------------------------------------------------------------ files
    def to_bytes(self) -> bytes:
        """The value's file (npz): the same value gives the same bytes (fixed arrays in a fixed
        order; the zip entries carry a fixed date, not the clock)."""
        import io
        import zipfile

        buf = io.BytesIO()
        np.savez_compressed(
            buf, zone_size=self.zones.size, zone_origin=self.zones.origin,
            zone_keys=self.zones.keys, node_xy=self.node_xy, bin_s=self.bin_s,
            table=self.table, gamma=self.gamma, weight=self.weight, trip_fit=self.trip_fit,
            seats=self.seats, network=self.network, meta=json.dumps(self.meta, sort_keys=True))
        buf.seek(0)
        out = io.BytesIO()
        with zipfile.ZipFile(buf) as src, zipfile.ZipFile(out, "w") as dst:
            for name in sorted(src.namelist()):
                info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                dst.writestr(info, src.read(name))
        return out.getvalue()

    def save(self, path: str | Path) -> None:
        """Write the value to ``path`` (:meth:`to_bytes`), whole (a temporary name, then a
        rename)."""
        import os

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_bytes(self.to_bytes())
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: str | Path) -> ZoneValue:
        with np.load(Path(path), allow_pickle=False) as f:
            node_xy = f["node_xy"]
            zones = Zones(node_xy, float(f["zone_size"]), f["zone_origin"], f["zone_keys"])
            seats = int(f["seats"]) if "seats" in f.files else 1
            meta = json.loads(str(f["meta"]))
            out = cls(zones, node_xy, float(f["bin_s"]), f["table"], float(f["gamma"]),
                      float(f["weight"]), f["trip_fit"], meta, seats)
            if "network" in f.files and str(f["network"]) != out.network:
                raise NetworkMismatch(f"{path}: its network fingerprint does not match its "
                                      "node positions (a damaged file)")
        out.meta.setdefault("file", Path(path).name)
        return out


# ---------------------------------------------------------------------------- an option
class ValueOption:
    """The ``value`` / ``value_weight`` / ``value_reward`` option of an allocator or
    repositioner: the learned value of ``path``, the weight to use it with (None: the file's)
    and, where given, the seconds of cost one served request is worth (``reward``).

    Without a reward an allocator still serves as many requests as it can and the value only
    chooses among the ways to do so. With one, a pair is worth ``reward`` less its adjusted
    cost, in the units of the value's own target (one served request = ``reward`` seconds,
    the NeurADP score ``1 + gamma^dt V(after) - V(now)`` less the cost over the reward): the
    assignment maximises the total worth and leaves a vehicle free, and a request for a later
    batch, where no pair is worth anything (:func:`allocators.hungarian.gated_pairs`).

    Every adjustment is per agent: row ``i`` of :meth:`costs` depends only on agent ``i``'s
    state, the tasks and the time, so a decentralized agent adjusts its own costs and gets the
    same numbers as a central one."""

    def __init__(self, path: str | Path, weight: float | None = None,
                 reward: float | None = None) -> None:
        self.path = str(path)
        self.value = ZoneValue.load(path)
        self.weight = self.value.weight if weight is None else float(weight)
        if reward is not None and (isinstance(reward, bool) or not isinstance(reward, (int, float))
                                   or not reward > 0):
            raise TypeError(f"value_reward must be a number of seconds > 0, got {reward!r}")
        self.reward = None if reward is None else float(reward)

    @classmethod
    def of(cls, path, weight=None, reward=None) -> ValueOption | None:
        """The option of an allocator's parameters (None without a ``value`` file; a
        ``value_reward`` without one is refused)."""
        if path is None:
            if reward is not None:
                raise TypeError("value_reward needs a value file ('value')")
            return None
        return cls(path, weight, reward)

    def costs(self, problem) -> np.ndarray:
        """The problem's costs less the discounted value after each pair plus the value now
        (:func:`dispatch.api.value.value_costs`); ``inf`` where the cost is."""
        return self.value.adjusted(problem, self.weight)

    @property
    def offset(self) -> float:
        """A bound of how far below its travel time an adjusted cost can go (the weight times
        the largest value of the file): :meth:`costs` plus it is never negative. A constant of
        the file, so every agent knows it without hearing the others."""
        return self.weight * max(float(self.value.table.max(initial=0.0)), 0.0)

    def problem(self, problem, shift: bool = False):
        """``problem`` with :meth:`costs` as its cost matrix (plus :attr:`offset` with ``shift``,
        for allocators whose models read costs as non-negative travel times; a constant added
        to every pair changes no comparison between pairs)."""
        from dataclasses import replace as _replace

        cost = self.costs(problem)
        if shift:
            cost = cost + self.offset
        return _replace(problem, cost=np.ascontiguousarray(cost))


def travel_costs(allocation, problem):
    """``allocation`` (decided on an adjusted copy of ``problem``) with each request's cost
    read back from ``problem.cost``: what the run records stays the travel time."""
    from dataclasses import replace as _replace

    if not allocation.requests:
        return allocation
    row = {int(a): i for i, a in enumerate(problem.agent_ids.tolist())}
    col = {int(t): j for j, t in enumerate(problem.task_ids.tolist())}
    reqs = tuple(_replace(r, cost=float(problem.cost[row[r.agent_id], col[r.task_id]]))
                 for r in allocation.requests)
    return _replace(allocation, requests=reqs)
