"""``logit``: a rider's seeded choice from a multinomial logit of the options' costs."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dispatch.api.mode_choice import ModeChoice, Option, Weights


class LogitChoice(ModeChoice):
    """Takes option ``i`` with probability ``exp(-scale * c_i) / sum_j exp(-scale * c_j)``,
    ``c`` the options' generalized costs in minutes, one draw of ``rng`` per choice.
    Parameter in ``[transit.logit]``: ``scale`` (per minute, > 0, default 0.1: an option
    ten minutes dearer is taken e (2.7) times less often)."""

    name = "logit"

    def __init__(self, scale: float = 0.1) -> None:
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) \
                or not math.isfinite(scale) or scale <= 0:
            raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
        self.scale = float(scale)

    def probabilities(self, options: Sequence[Option], weights: Weights) -> np.ndarray:
        """The closed form: each option's probability (shifted by the least cost, so no
        exponential overflows)."""
        u = -self.scale * np.array([weights.cost(o) for o in options]) / 60.0
        e = np.exp(u - u.max())
        return e / e.sum()

    def choose(self, options: Sequence[Option], weights: Weights,
               rng: np.random.Generator) -> int:
        p = self.probabilities(options, weights)
        return int(min(np.searchsorted(np.cumsum(p), rng.random(), side="right"), len(p) - 1))
