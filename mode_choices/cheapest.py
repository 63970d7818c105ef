"""``cheapest``: the option of least generalized cost."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dispatch.api.mode_choice import ModeChoice, Option, Weights


class CheapestChoice(ModeChoice):
    """Takes the option of least :meth:`~dispatch.api.mode_choice.Weights.cost`; of equal
    costs, the first (no draw of ``rng``)."""

    name = "cheapest"

    def choose(self, options: Sequence[Option], weights: Weights,
               rng: np.random.Generator) -> int:
        costs = [weights.cost(o) for o in options]
        return costs.index(min(costs))
