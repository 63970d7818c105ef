"""``[comms]``: who can talk at a decision and what a message costs, as data (the model:
:mod:`dispatch.api.comms`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CommsConfig:
    """Who can talk at a decision, and what a message costs (see :mod:`dispatch.api.comms`)."""

    range: float | None = None  # metres a message carries (unset: unlimited)
    latency: float = 0.0  # simulated seconds per message hop
    loss: float = 0.0  # probability that one reception of a message is lost, in [0, 1)

    @property
    def unlimited(self) -> bool:
        return self.range is None
