"""The repositioner checks (``dispatch check NAME`` of a repositioner), on random views
(:func:`reposition_view`) of :func:`dispatch.checks.common.small_network` (no idle vehicles, no
recent requests, vehicles already repositioning, part-way along edges): ``construct``,
``valid`` (a mapping from idle vehicle ids of the view to node indices), ``no-mutation`` (of
the view), ``deterministic`` and ``rng`` (:func:`dispatch.checks.common.replay`). A passive
repositioner (never called by the kernel) must answer with no moves.

    report = check_repositioner(MyRepositioner, zone=500)  # on random views of a road grid
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dispatch.api.legs import RoadPoint, as_point
from dispatch.checks.common import (Report, constructed, describe_error, perturb_global_rng, replay,
                                    same_snapshot, small_network)


def reposition_view(space, vehicles, requests=(), *, time: float = 0.0, horizon: float = 1800.0,
                    targets=None, seed: int = 0):
    """A :class:`~dispatch.api.repositioner.RepositionView` built by hand: ``vehicles`` maps idle
    vehicle ids to where they are (a node or a :class:`~dispatch.api.legs.RoadPoint`),
    ``requests`` lists ``(release time, pickup node)`` (all inside the horizon), ``targets``
    maps vehicles already repositioning to their target node."""
    from dispatch.api.repositioner import RepositionView, _readonly

    ids = sorted(vehicles)
    locs = [vehicles[i] for i in ids]
    targets = targets or {}
    req = list(requests)
    points = [as_point(p) for p in locs]
    rnodes = _readonly([int(n) for _, n in req], np.int64)
    return RepositionView(
        time=float(time), horizon=float(horizon), vehicle_ids=_readonly(ids, np.int64),
        nodes=_readonly([p.node for p in points], np.int64),
        remaining=_readonly([max(p.remaining, 0.0) for p in points], np.float64),
        targets=_readonly([targets.get(i, -1) for i in ids], np.int64),
        vehicle_pos=_readonly(space.positions(locs) if locs else np.zeros((0, 3)), np.float64),
        request_times=_readonly([float(t) for t, _ in req], np.float64), request_nodes=rnodes,
        request_pos=_readonly(space.positions(rnodes), np.float64), space=space,
        rng=np.random.default_rng(seed))


def _reposition_views(space, seed: int):
    """Labelled view factories (each call builds the same view with a fresh rng)."""
    g = np.random.default_rng(seed)
    n = space.n

    def views(label, n_vehicles, n_requests, moving=0, on_edge=0):
        nodes = g.integers(0, n, n_vehicles).tolist()
        ids = (g.permutation(1000)[:n_vehicles] + 1000).tolist()
        vehicles = dict(zip(ids, nodes))
        for vid in ids[:on_edge]:  # part-way along an edge into its node
            node = vehicles[vid]
            prev = int(space._time_t.indices[space._time_t.indptr[node]])
            secs, metres = space.edge(prev, node)
            vehicles[vid] = RoadPoint(node, prev, secs / 2, metres / 2)
        targets = {vid: int(g.integers(0, n)) for vid in ids[on_edge:on_edge + moving]}
        req = [(float(t), int(v)) for t, v in zip(np.sort(g.uniform(0, 1800, n_requests)),
                                                  g.integers(0, n, n_requests))]
        return label, lambda: reposition_view(space, vehicles, req, time=1800.0,
                                              targets=targets, seed=seed)

    return [views("no idle vehicles", 0, 10), views("no requests", 5, 0),
            views("one vehicle, one request", 1, 1), views("8 vehicles, 40 requests", 8, 40),
            views("some repositioning, some on edges", 10, 30, moving=3, on_edge=3),
            views("many vehicles, few requests", 25, 3)]


def _view_snapshot(v) -> tuple:
    arrays = (v.vehicle_ids, v.nodes, v.remaining, v.targets, v.vehicle_pos, v.request_times,
              v.request_nodes, v.request_pos)
    return (v.time, v.horizon, *(a.copy() for a in arrays),
            *(a.flags.writeable for a in arrays))


def check_repositioner(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every repositioner check (see the module docstring) on ``cls(**params)`` with views
    of ``space`` (default :func:`small_network`)."""
    from collections.abc import Mapping

    report, caps = constructed("repositioner", cls, params)
    if not report.ok:
        return report
    space = space if space is not None else small_network()
    passive = caps.passive
    invalid, mutated, differs, global_rng = [], [], [], []
    answers: dict[str, dict] = {}
    cases = _reposition_views(space, seed)
    called = 0  # views whose call returned (the no-mutation check's)
    for label, build in cases:
        view = build()
        before = _view_snapshot(view)
        try:
            perturb_global_rng(1)
            moves = cls(**params).reposition(view)
        except Exception as e:  # noqa: BLE001
            invalid.append(f"{label}: reposition raised {describe_error(e)}")
            continue
        called += 1
        if not same_snapshot(before, _view_snapshot(view)):
            mutated.append(f"{label}: the view changed during reposition")
        if not isinstance(moves, Mapping):
            invalid.append(f"{label}: returned {type(moves).__name__}, not a mapping")
            continue
        ids = set(view.vehicle_ids.tolist())
        bad = [(k, v) for k, v in moves.items()
               if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k not in ids
               or isinstance(v, bool) or not isinstance(v, (int, np.integer))
               or not 0 <= v < space.n]
        if bad:
            invalid.append(f"{label}: move {bad[0][0]!r} -> {bad[0][1]!r} names no idle vehicle "
                           f"of the view or no node of the network")
            continue
        if passive and moves:
            invalid.append(f"{label}: a passive repositioner returned {len(moves)} move(s)")
            continue
        answers[label] = dict(moves)
    for label, build in cases:
        if label in answers:
            replay(label, lambda b=build: dict(cls(**params).reposition(b())), answers[label],
                    differs, global_rng, given="view and seed")
    report.add("valid", invalid, f"{len(cases)} views, every answer a mapping of idle vehicle "
                                 f"ids to nodes")
    report.add("no-mutation", mutated, "no view changed",
               ran=called, of=len(cases), after="reposition (it raised)")
    report.add("deterministic", differs, "same view and seed, same moves",
               ran=len(answers), of=len(cases), after="valid")
    report.add("rng", global_rng, "moves do not depend on the global random state",
               ran=len(answers), of=len(cases), after="valid")
    return report
