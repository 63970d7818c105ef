"""``logit``: a rider's seeded choice from a binary logit model of the offer."""

from __future__ import annotations

import math

import numpy as np

from dispatch.api.acceptor import Acceptor, Offer, logistic


def _coefficient(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, got {value!r}")
    return float(value)


class LogitAcceptor(Acceptor):
    """Accepts with probability ``1 / (1 + exp(-(b0 + b_wait * wait + b_ivt * ivt + b_fare *
    fare)))`` (wait and in-vehicle time in minutes, the fare in the pricing's currency), one
    draw of the run's offers stream per offer. Parameters in ``[acceptor.logit]``: ``b0``
    (default 3), ``b_wait`` (per minute, default -0.2), ``b_ivt`` (per minute, default -0.05),
    ``b_fare`` (per currency unit, default 0: a fare needs ``[pricing]``)."""

    name = "logit"

    def __init__(self, b0: float = 3.0, b_wait: float = -0.2, b_ivt: float = -0.05,
                 b_fare: float = 0.0) -> None:
        self.b0 = _coefficient("b0", b0)
        self.b_wait = _coefficient("b_wait", b_wait)
        self.b_ivt = _coefficient("b_ivt", b_ivt)
        self.b_fare = _coefficient("b_fare", b_fare)
        # the fare weighs only where it has a coefficient (the parser then needs [pricing])
        self.uses_fare = self.b_fare != 0.0

    def probability(self, offer: Offer) -> float:
        """The probability that the rider accepts ``offer`` (the closed form)."""
        u = self.b0 + self.b_wait * offer.wait / 60.0 + self.b_ivt * offer.ivt / 60.0
        if self.b_fare:
            u += self.b_fare * offer.fare
        return logistic(u)

    def accept(self, offer: Offer, rng: np.random.Generator) -> bool:
        return bool(rng.random() < self.probability(offer))
