"""The named random streams of a run's seed.

Every random draw of a run comes from a ``numpy.random.Generator`` seeded from the run's seed
and a fixed stream number, so the world (obstacles) depends on the seed only, and the same
seed gives the same fleet and the same tasks whichever allocator runs: instances are paired
across allocators.
"""

from __future__ import annotations

import numpy as np

(STREAM_WORLD, STREAM_FLEET, STREAM_TASKS, STREAM_ALLOCATOR, STREAM_SOURCE, STREAM_FAULTS,
 STREAM_REPOSITION, STREAM_CHARGING) = range(8)
#: which requests are booked ahead ([tasks] prebook_share; dispatch.decide.prebook)
STREAM_PREBOOK = 8
#: the riders' answers to offers (dispatch.api.acceptor); a number of its own, clear of the others
STREAM_OFFERS = 31
#: fleet sizing (dispatch.fleet.shifts); numbered apart from the streams above
STREAM_SIZING = 12
#: riders' mode choices ([transit]; dispatch.decide.riders)
STREAM_MODE_CHOICE = 13


def rng_for(seed: int, stream: int) -> np.random.Generator:
    """The generator of one named stream of a run's seed."""
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(stream,)))
