"""``[acceptor]``: which acceptor answers offers, how often a declined request is offered again,
and the acceptor's parameters, as data (the contract: :mod:`dispatch.api.acceptor`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class AcceptorConfig:
    """``[acceptor]``: the acceptor, how many times a declined request is offered again, and
    the acceptor's parameters (``[acceptor.<name>]``)."""

    name: str = "always"  # an installed acceptor (`dispatch plugins`): always, threshold, logit
    retries: int = 0  # times a declined request is offered again at a later decision
    #: the ``[acceptor.<name>]`` table: keyword arguments of the acceptor's constructor
    params: tuple[tuple[str, Any], ...] = ()
