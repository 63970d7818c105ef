"""The charging-strategy checks (``dispatch check NAME`` of a charger), on small
:class:`~dispatch.api.charger.ChargingView` s of :func:`dispatch.checks.common.small_network`
(no idle vehicle, low and full batteries, busy stations): ``construct``, ``valid`` (a mapping
of idle vehicle ids of the view to a station id of the view and a target in (0, 1]),
``no-mutation`` (of the view), ``deterministic`` and ``rng``
(:func:`dispatch.checks.common.replay`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from dispatch.checks.common import (Report, constructed, describe_error, perturb_global_rng, replay,
                                    small_network)


def charging_views(space=None, seed: int = 0) -> list[tuple[str, Callable[[], Any]]]:
    """:class:`dispatch.api.charger.ChargingView` factories on ``space`` (default
    :func:`small_network`): empty, low batteries, full batteries, busy stations."""
    from dispatch.api.charger import ChargingView
    from dispatch.fleet.chargers import charge_seconds

    space = space if space is not None else small_network()

    def make(label: str, n: int, lo: float, hi: float, busy: bool):
        def build():
            g = np.random.default_rng(seed)
            nodes = g.integers(0, space.n, n)
            st = np.array([0, space.n - 1], dtype=np.int64)

            def ro(a, dtype):
                a = np.array(a, dtype=dtype)
                a.setflags(write=False)
                return a

            return ChargingView(
                time=3600.0 * 5, vehicle_ids=ro(np.arange(n) * 3 + 1, np.int64),
                nodes=ro(nodes, np.int64), remaining=ro(np.zeros(n), float),
                soc=ro(g.uniform(lo, hi, n), float), station_ids=("a", "b"),
                station_nodes=ro(st, np.int64), plugs=ro([1, 2], np.int64),
                in_use=ro([1, 2] if busy else [0, 0], np.int64),
                waiting=ro([2, 0] if busy else [0, 0], np.int64), kw=ro([50.0, 7.2], float),
                released_by_hour=ro([10, 20, 30, 40, 30, 5], np.int64), battery_kwh=50.0,
                reserve=0.1, space=space, rng=np.random.default_rng(seed),
                charge_seconds=lambda a, b, kw: charge_seconds(a, b, 50.0, kw, 0.8, 0.2))
        return label, build

    return [make("no idle vehicle", 0, 0.0, 1.0, False), make("low batteries", 12, 0.0, 0.3,
                                                                False),
            make("full batteries", 8, 0.95, 1.0, False), make("mixed, busy stations", 20, 0.0,
                                                               1.0, True)]


def check_charger(cls, space=None, *, seed: int = 0, **params: Any) -> Report:
    """Run every charging-strategy check on ``cls(**params)`` (a
    :class:`dispatch.api.charger.ChargingStrategy`): each answer a mapping of idle vehicle
    ids of the view to (station id of the view, target in (0, 1]); the view not mutated; same
    view and seed, same answer; no use of the global random state."""
    from collections.abc import Mapping

    report, _ = constructed("charger", cls, params)
    if not report.ok:
        return report
    invalid, mutated, differs, global_rng = [], [], [], []
    answers: dict[str, dict] = {}
    cases = charging_views(space, seed)

    def snap(view):
        return tuple(np.array(a).tobytes() for a in
                     (view.vehicle_ids, view.nodes, view.remaining, view.soc,
                      view.station_nodes, view.plugs, view.in_use, view.waiting, view.kw,
                      view.released_by_hour))

    called = 0  # views whose call returned (the no-mutation check's)
    for label, build in cases:
        view = build()
        before = snap(view)
        try:
            perturb_global_rng(1)
            moves = cls(**params).decide(view)
        except Exception as e:  # noqa: BLE001
            invalid.append(f"{label}: decide raised {describe_error(e)}")
            continue
        called += 1
        if before != snap(view):
            mutated.append(f"{label}: the view changed during decide")
        if not isinstance(moves, Mapping):
            invalid.append(f"{label}: returned {type(moves).__name__}, not a mapping")
            continue
        ids = set(view.vehicle_ids.tolist())
        bad = []
        for k, v in moves.items():
            ok = (not isinstance(k, bool) and isinstance(k, (int, np.integer)) and k in ids
                  and isinstance(v, tuple) and len(v) == 2 and v[0] in view.station_ids
                  and isinstance(v[1], (int, float)) and 0.0 < float(v[1]) <= 1.0)
            if not ok:
                bad.append((k, v))
        if bad:
            invalid.append(f"{label}: {bad[0][0]!r} -> {bad[0][1]!r} names no idle vehicle of "
                           f"the view, no station, or a target outside (0, 1]")
            continue
        answers[label] = {int(k): (v[0], float(v[1])) for k, v in moves.items()}
    for label, build in cases:
        if label in answers:
            replay(label, lambda b=build: {int(k): (v[0], float(v[1])) for k, v in
                                            cls(**params).decide(b()).items()},
                    answers[label], differs, global_rng, given="view and seed")
    report.add("valid", invalid, f"{len(cases)} views, every answer a mapping of idle vehicle "
                                 f"ids to (station id, target)")
    report.add("no-mutation", mutated, "no view changed",
               ran=called, of=len(cases), after="decide (it raised)")
    report.add("deterministic", differs, "same view and seed, same visits",
               ran=len(answers), of=len(cases), after="valid")
    report.add("rng", global_rng, "visits do not depend on the global random state",
               ran=len(answers), of=len(cases), after="valid")
    return report
