"""The acceptor checks (``dispatch check NAME`` of an acceptor, :mod:`dispatch.api.acceptor`), on
a fixed set of offers (short and long waits, detours, pooled or not, with and without a fare,
first offers and re-offers): ``construct``, ``valid`` (each answer a bool), ``declines`` (an
acceptor declaring ``declines = False`` accepts every offer), ``deterministic`` and ``rng``
(:func:`dispatch.checks.common.replay`: the same offers and seed give the same answers, whatever
the global random state).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dispatch.api.acceptor import Offer
from dispatch.api.problem import TaskView
from dispatch.checks.common import Report, add_replayed, constructed, first_answer


def sample_offers(fares: bool) -> list[Offer]:
    """Offers of a 1-rider trip released at 100 s (direct drive 300 s): waits of 0 s to
    40 min, detours of 0 s to 20 min, pooled or not, first offers and re-offers; a fare of
    2.5 to 40 units where ``fares`` (an acceptor that uses fares), else nan."""
    out = []
    request = TaskView(7, "trip", 3, 100.0, dropoff=9)
    for k, (wait, detour) in enumerate([(0, 0), (60, 0), (300, 120), (900, 600),
                                        (2400, 1200), (120, 30)]):
        pickup = 100.0 + wait
        fare = 2.5 + 7.5 * k if fares else math.nan
        out.append(Offer(request, 4, 100.0, 100.0, pickup, pickup + 300.0 + detour, 300.0,
                         fare, k % 2 == 1, 1 + k % 3))
    return out


def check_acceptor(cls, *, seed: int = 0, **params: Any) -> Report:
    """Run every acceptor check (see the module docstring) on ``cls(**params)``."""
    report, caps = constructed("acceptor", cls, params)
    if not report.ok:
        return report
    offers = sample_offers(bool(cls.uses_fare))

    def answers():
        a = cls(**params)
        rng = np.random.default_rng(seed)
        return [a.accept(o, rng) for o in offers]

    ok, first = first_answer(report, answers, "accept")
    if not ok:
        return report
    bad = [f"offer {k + 1}: answered {a!r}, not a bool" for k, a in enumerate(first)
           if not isinstance(a, (bool, np.bool_))]
    report.add("valid", bad, f"{len(offers)} offers, each answered True or False")
    never = [] if caps.declines or all(first) else \
        [f"declares declines = False but declined offer {first.index(False) + 1}"]
    report.add("declines", never, "declines offers" if caps.declines else
               "accepts every offer, as it declares")
    add_replayed(report, lambda: [bool(a) for a in answers()], [bool(a) for a in first],
                 "offers and seed", "answers")
    return report
