"""``threshold``: a rider declines an offer whose wait or detour is past the scenario's
limits."""

from __future__ import annotations

import math

import numpy as np

from dispatch.api.acceptor import Acceptor, Offer


def _limit(key: str, value) -> float:
    """A limit in seconds: a number >= 0 (``inf``: none)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value) \
            or value < 0:
        raise ValueError(f"{key} must be a number of seconds >= 0, got {value!r}")
    return float(value)


class ThresholdAcceptor(Acceptor):
    """Declines an offer whose estimated wait (pickup minus request, s) exceeds ``max_wait``
    or whose detour (in-vehicle time minus the direct drive, s) exceeds ``max_detour``;
    accepts the others (a limit equal to the estimate is kept). Parameters in
    ``[acceptor.threshold]``; both default to ``inf`` (no limit)."""

    name = "threshold"

    def __init__(self, max_wait: float = math.inf, max_detour: float = math.inf) -> None:
        self.max_wait = _limit("max_wait", max_wait)
        self.max_detour = _limit("max_detour", max_detour)

    def accept(self, offer: Offer, rng: np.random.Generator) -> bool:
        return offer.wait <= self.max_wait and offer.detour <= self.max_detour
