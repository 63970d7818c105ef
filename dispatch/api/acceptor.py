"""Offers riders may decline: the offer a rider is made, the acceptor contract, the fare.

When a decision hands a request to a vehicle, the rider is first made an :class:`Offer`: the
estimates of the plan the allocator chose (when the vehicle would pick the rider up and drop
them off, so the wait, the in-vehicle time and the detour over the direct ride) and, with a
``[pricing]`` section, a fare (:meth:`Pricing.fare`). An acceptor plugin
(``dispatch.acceptors`` entry points; subclass :class:`Acceptor`) answers
:meth:`Acceptor.accept`. A declined offer is undone before the vehicle moves: the request's
stops never enter the plan, and the request is closed ``declined`` unless it may be offered
again (``[acceptor] retries``) at a later decision. The step itself is
:class:`dispatch.decide.offer_step.Offering`.

Configuration (parsed once by :func:`dispatch.scenario.sections.parse_acceptor` and
:func:`dispatch.scenario.sections.parse_pricing`)::

    [acceptor]
    name = "logit"        # an installed acceptor (default "always")
    retries = 0           # times a declined request is offered again before it is declined
    [acceptor.logit]      # the acceptor's parameters
    b0 = 2.0

    [pricing]             # optional: fares (needs a road network)
    base = 2.5            # currency units per ride
    per_km = 1.5          # ... per km of the direct route
    per_minute = 0.3      # ... per minute of the direct drive (free flow)
    sharing_discount = 0.2  # share taken off the fare of a pooled ride

An acceptor that declares ``declines = False`` (``always``) never declines: without a
``[pricing]`` section the kernel then skips the offer step entirely (the run is the run
without offers, to the bit).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from dispatch.api.problem import TaskView


@dataclass(frozen=True, slots=True)
class Offer:
    """What a rider is offered: the request (its read-only view: pickup, drop-off, release,
    riders, limits), the vehicle's id, and the estimates of the plan the decision chose
    (simulated seconds).

    ``wait``: pickup estimate minus when the rider is ready at the pickup (``ready_at``: the
    release; a booked rider's departure; a walker's arrival at the meeting point, so that the
    walk is not counted as waiting; nan: the release); ``ivt``: in-vehicle seconds
    (drop-off estimate minus pickup estimate; 0 for a request without a drop-off);
    ``direct``: the free-flow direct drive (nan where unknown); ``detour``: ``ivt - direct``
    (0 where the direct drive is unknown); ``fare``: the price (nan without ``[pricing]``);
    ``pooled``: another rider is on board at some point of this ride in the plan; ``attempt``:
    1 for the first offer, 2 for the first re-offer, ..."""

    request: TaskView
    vehicle_id: int
    now: float
    released_at: float
    pickup_at: float
    dropoff_at: float
    direct: float
    fare: float
    pooled: bool
    attempt: int
    ready_at: float = math.nan

    @property
    def wait(self) -> float:
        ready = self.ready_at if self.ready_at == self.ready_at else self.released_at
        return self.pickup_at - ready

    @property
    def ivt(self) -> float:
        return self.dropoff_at - self.pickup_at

    @property
    def detour(self) -> float:
        return self.ivt - self.direct if self.direct == self.direct else 0.0


class Acceptor(ABC):
    """Base class of acceptor plugins (entry-point group ``dispatch.acceptors``).

    Subclasses set ``name`` and implement :meth:`accept`. Constructor keyword arguments come
    from the scenario's ``[acceptor.<name>]`` table; reject unknown or bad ones with
    ``TypeError`` or ``ValueError`` (the scenario's parser turns that into one line naming
    the file and the key)."""

    name: ClassVar[str] = ""
    #: False for an acceptor that accepts every offer (``always``): the kernel may skip the
    #: offer step (without fares to record).
    declines: ClassVar[bool] = True
    #: True for an acceptor whose answer depends on the fare (``[pricing]`` is then needed).
    uses_fare: ClassVar[bool] = False

    @abstractmethod
    def accept(self, offer: Offer, rng: np.random.Generator) -> bool:
        """Whether the rider accepts ``offer``. Randomness only from ``rng`` (the run's
        offers stream, derived from the seed)."""


@dataclass(frozen=True)
class Pricing:
    """``[pricing]``: a ride's fare is ``base + per_km * km + per_minute * minutes`` of the
    direct ride (the network's fastest route from pickup to drop-off and its free-flow
    minutes), times ``1 - sharing_discount`` for a pooled ride."""

    base: float = 0.0  # currency units per ride
    per_km: float = 0.0  # currency units per km of the direct route
    per_minute: float = 0.0  # currency units per minute of the direct (free-flow) drive
    sharing_discount: float = 0.0  # share taken off the fare of a pooled ride (0-1)

    def fare(self, metres: float, seconds: float, pooled: bool) -> float:
        """The fare of a ride of ``metres`` and ``seconds`` (direct), pooled or not."""
        price = self.base + self.per_km * metres / 1000.0 + self.per_minute * seconds / 60.0
        return price * (1.0 - self.sharing_discount) if pooled else price


def logistic(u: float) -> float:
    """``1 / (1 + exp(-u))``, without overflow for large ``|u|``."""
    if u >= 0:
        return 1.0 / (1.0 + math.exp(-u))
    e = math.exp(u)
    return e / (1.0 + e)
