"""Repositioning in a run: calls a non-passive repositioner (the contract:
:mod:`dispatch.api.repositioner`) every ``[reposition] interval`` seconds and hands its moves to
the operator, which drives them as reposition stops."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from dispatch.api.legs import as_point
from dispatch.api.repositioner import Repositioner, RepositionView, _readonly
from dispatch.errors import PluginError

if TYPE_CHECKING:
    import simpy

    from dispatch.events import Event, EventBus
    from dispatch.plan.operator import Operator
    from dispatch.plan.vehicles import Fleet, Vehicle
    from dispatch.space.roads import RoadNetwork

log = logging.getLogger(__name__)


class Repositioning:
    """Calls a non-passive repositioner every ``interval`` seconds and hands its moves to the
    operator (:meth:`dispatch.plan.operator.Operator.reposition`), which drives them as reposition
    stops. ``moves`` counts the moves started; their metres are the operator's
    (:attr:`dispatch.plan.operator.Operator.reposition_distance`)."""

    def __init__(self, env: simpy.Environment, bus: EventBus, fleet: Fleet, operator: Operator,
                 space: RoadNetwork, repositioner: Repositioner, *, interval: float, horizon: float,
                 rng: np.random.Generator, run_id: str = "") -> None:
        self.env, self.bus, self.fleet, self.operator = env, bus, fleet, operator
        self.space, self.repositioner, self.rng = space, repositioner, rng
        self.interval, self.horizon = interval, horizon
        self.run_id = run_id  # named in error messages
        self.moves = 0
        self._recent: deque[tuple[float, int]] = deque()
        bus.subscribe(self._released, ["release"])
        self.process = env.process(self._loop())

    def _released(self, e: Event) -> None:
        self._recent.append((e.t, int(e.loc)))

    def _loop(self):
        while True:
            yield self.env.timeout(self.interval)
            self.step()

    # ------------------------------------------------------------------ one call
    def view(self) -> RepositionView:
        """The read-only view of now (see :class:`RepositionView`)."""
        now, recent = self.env.now, self._recent
        while recent and recent[0][0] <= now - self.horizon:
            recent.popleft()
        idle = self.fleet.idle()
        locs = [v.location(now) for v in idle]
        points = [as_point(p) for p in locs]
        nodes = [p.node for p in points]
        rem = [max(p.remaining, 0.0) for p in points]
        going = [self.operator.repositioning(v) for v in idle]
        targets = [-1 if node is None else node for node in going]
        rnodes = _readonly([n for _, n in recent], np.int64)
        return RepositionView(
            time=float(now), horizon=self.horizon,
            vehicle_ids=_readonly([v.id for v in idle], np.int64),
            nodes=_readonly(nodes, np.int64), remaining=_readonly(rem, np.float64),
            targets=_readonly(targets, np.int64),
            vehicle_pos=_readonly(self.space.positions(locs), np.float64),
            request_times=_readonly([t for t, _ in recent], np.float64), request_nodes=rnodes,
            request_pos=_readonly(self.space.positions(rnodes), np.float64),
            space=self.space, rng=self.rng)

    def _fail(self, why: str) -> PluginError:
        name = self.repositioner.name or type(self.repositioner).__name__
        run = f", run {self.run_id}" if self.run_id else ""
        return PluginError(f"repositioner {name!r}{run}, t = {self.env.now:.6g} s: {why}")

    def step(self) -> None:
        """Ask the repositioner for moves now, check them, and start them (in vehicle id
        order; a move to where the vehicle already is or is already heading is ignored)."""
        view = self.view()
        try:
            moves = self.repositioner.reposition(view)
        except PluginError:
            raise
        except Exception as e:  # noqa: BLE001 - a plugin may raise anything
            raise self._fail(f"reposition() raised {type(e).__name__}: "
                             f"{' '.join(str(e).split())[:300]}") from e
        if not isinstance(moves, Mapping):
            raise self._fail(f"reposition() must return a mapping of vehicle id to node, got "
                             f"{type(moves).__name__}")
        idle = {int(i): k for k, i in enumerate(view.vehicle_ids)}
        checked = []
        for vid, node in moves.items():
            if isinstance(vid, bool) or not isinstance(vid, (int, np.integer)) \
                    or int(vid) not in idle:
                raise self._fail(f"move for vehicle {vid!r}, which is not an idle vehicle of "
                                 f"the view")
            if isinstance(node, bool) or not isinstance(node, (int, np.integer)) \
                    or not 0 <= node < self.space.n:
                raise self._fail(f"vehicle {vid} sent to {node!r}, not a node index of the "
                                 f"network (0 .. {self.space.n - 1})")
            checked.append((int(vid), int(node)))
        for vid, node in sorted(checked):
            k = idle[vid]
            here = int(view.nodes[k]) == node and view.remaining[k] <= 0.0
            if int(view.targets[k]) == node or (here and view.targets[k] < 0):
                continue
            self.start(self.fleet.by_id[vid], node)

    def start(self, v: Vehicle, node: int) -> None:
        """Send the idle vehicle ``v`` to ``node`` now (a move it is on ends where it is)."""
        self.moves += 1
        self.operator.reposition(v, node)


def summary_of(r: Repositioning | None) -> dict:
    """The summary columns of repositioning: moves started and their metres."""
    return {"repositions": 0 if r is None else r.moves,
            "reposition_distance": 0.0 if r is None else r.operator.reposition_distance}
