"""``always``: every rider accepts every offer (the default; the run is the run without
offers)."""

from __future__ import annotations

import numpy as np

from dispatch.api.acceptor import Acceptor, Offer


class AlwaysAcceptor(Acceptor):
    """Every rider accepts every offer (the default): the kernel skips the offer step unless
    a ``[pricing]`` section asks for fares."""

    name = "always"
    declines = False

    def accept(self, offer: Offer, rng: np.random.Generator) -> bool:
        return True
