"""The mode choice checks (``dispatch check NAME --kind mode_choice``,
:mod:`dispatch.api.mode_choice`), on a fixed set of choices (one option alone, options of
every kind with costs near and far apart, equal costs, one dominating option): ``construct``,
``valid`` (each answer an index of the options, never a bool), ``deterministic`` and ``rng`` (:func:`dispatch.checks.common.replay`: the same choices and seed
give the same answers, whatever the global random state).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dispatch.api.mode_choice import Option, Weights
from dispatch.checks.common import Report, add_replayed, constructed, first_answer

#: the weights of the sample choices (transit appraisal's usual ones)
WEIGHTS = Weights(ivt=1.0, wait=2.0, walk=2.0, change=2.0, per_change=300.0)


def sample_choices() -> list[list[Option]]:
    """Choices of one to four options: door to door against feeders and walks to trains."""
    fleet = Option("fleet", 1800.0, ivt=1200.0, wait=240.0, walk=0.0)
    feeder = Option("fleet+train", 1700.0, ivt=900.0, wait=300.0, walk=120.0, change=0.0)
    after = Option("train+fleet", 1900.0, ivt=1000.0, wait=180.0, walk=200.0, change=240.0,
                   changes=1)
    train = Option("train", 2100.0, ivt=1100.0, wait=120.0, walk=700.0, change=420.0,
                   changes=2)
    far = Option("fleet", 9000.0, ivt=8000.0, wait=900.0, walk=0.0)
    return [[fleet], [fleet, feeder, after, train], [train, after, feeder, fleet],
            [fleet, fleet], [feeder, far], [far, train, far]]


def check_mode_choice(cls, *, seed: int = 0, **params: Any) -> Report:
    """Run every mode choice check (see the module docstring) on ``cls(**params)``."""
    report, _ = constructed("mode_choice", cls, params)
    if not report.ok:
        return report
    choices = sample_choices()

    def answers():
        m = cls(**params)
        rng = np.random.default_rng(seed)
        return [m.choose(options, WEIGHTS, rng) for options in choices]

    ok, first = first_answer(report, answers, "choose")
    if not ok:
        return report
    bad = [f"choice {k + 1} of {len(o)} options: answered {a!r}, not an index of them"
           for k, (o, a) in enumerate(zip(choices, first))
           if isinstance(a, bool) or not isinstance(a, (int, np.integer)) or not 0 <= a < len(o)]
    report.add("valid", bad, f"{len(choices)} choices, each answered with an index")
    add_replayed(report, lambda: [int(a) for a in answers()], [int(a) for a in first],
                 "choices and seed", "answers")
    return report
