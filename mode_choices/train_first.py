"""``train_first``: an operator that steers riders to the train: the cheapest option with a
train where it costs at most ``slack`` more than the cheapest option."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dispatch.api.mode_choice import ModeChoice, Option, Weights


class TrainFirstChoice(ModeChoice):
    """Takes the option of least :meth:`~dispatch.api.mode_choice.Weights.cost` among those
    with a train (``fleet+train``, ``train+fleet``, ``train``) where that cost is at most the
    least cost of all options plus ``slack`` seconds, else the cheapest option (of equal
    costs, the first; no draw of ``rng``). ``slack = 0`` chooses as ``cheapest`` does but
    for ties, which go to the train. Parameter in ``[transit.train_first]``: ``slack``
    (generalized seconds, >= 0, default 600)."""

    name = "train_first"

    def __init__(self, slack: float = 600.0) -> None:
        if isinstance(slack, bool) or not isinstance(slack, (int, float)) \
                or not math.isfinite(slack) or slack < 0:
            raise ValueError(f"slack must be a finite number >= 0, got {slack!r}")
        self.slack = float(slack)

    def choose(self, options: Sequence[Option], weights: Weights,
               rng: np.random.Generator) -> int:
        costs = [weights.cost(o) for o in options]
        least = min(costs)
        train = [(c, i) for i, (c, o) in enumerate(zip(costs, options)) if o.kind != "fleet"]
        if train and min(train)[0] <= least + self.slack:
            return min(train)[1]
        return costs.index(least)
