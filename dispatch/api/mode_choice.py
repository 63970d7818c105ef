"""Mode choice: the options a rider has for one trip, their generalized cost, and the contract
of the plugins that choose among them (``dispatch.mode_choices`` entry points; subclass
:class:`ModeChoice`).

A rider's options (:class:`Option`): door to door by the fleet; the fleet to a station, then
train(s), then a walk; a walk, train(s), then the fleet; a walk and train(s) alone. Each is
summed up as the seconds it spends aboard, waiting, walking and changing trains, and its
changes; :meth:`Weights.cost` weighs them (the weights are ``[transit]``'s,
:class:`dispatch.config.transit.TransitConfig`). A plugin answers :meth:`ModeChoice.choose`
with the index of the option the rider takes.

Configuration::

    [transit]
    mode_choice = "logit"   # an installed mode choice (default "cheapest")
    [transit.logit]         # its parameters
    scale = 0.1
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

#: the kinds of option, by the modes of their legs in time order
KINDS = ("fleet", "fleet+train", "train+fleet", "train")


@dataclass(frozen=True, slots=True)
class Option:
    """One way to make a trip, in seconds: ``ivt`` aboard (the fleet's vehicle and trains),
    ``wait`` waiting (for the pickup, for the first train), ``walk`` walking between the
    rider's door or goal and a station, ``change`` walking and waiting between two trains,
    ``changes`` the number of changes; ``arrive`` when it reaches the goal (simulated
    seconds). ``kind`` is one of :data:`KINDS`."""

    kind: str
    arrive: float
    ivt: float
    wait: float
    walk: float
    change: float = 0.0
    changes: int = 0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"option kind {self.kind!r} is not one of {', '.join(KINDS)}")


@dataclass(frozen=True, slots=True)
class Weights:
    """The weights of a generalized cost (``[transit]``'s ``w_*`` and ``transfer_penalty``)."""

    ivt: float
    wait: float
    walk: float
    change: float
    per_change: float

    def cost(self, o: Option) -> float:
        """The option's generalized cost in seconds."""
        return (self.ivt * o.ivt + self.wait * o.wait + self.walk * o.walk
                + self.change * o.change + self.per_change * o.changes)


class ModeChoice(ABC):
    """Base class of mode choice plugins (entry-point group ``dispatch.mode_choices``).

    Subclasses set ``name`` and implement :meth:`choose`. Constructor keyword arguments come
    from the scenario's ``[transit.<name>]`` table; reject unknown or bad ones with
    ``TypeError`` or ``ValueError`` (the scenario's parser turns that into one line naming
    the file and the key)."""

    name: ClassVar[str] = ""

    @abstractmethod
    def choose(self, options: Sequence[Option], weights: Weights,
               rng: np.random.Generator) -> int:
        """The index in ``options`` (at least one) of the option the rider takes.
        Randomness only from ``rng`` (a stream of the run, derived from the seed)."""
