"""``[reposition]``: what idle vehicles do, as data (the contract:
:mod:`dispatch.api.repositioner`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class RepositionConfig:
    """``[reposition]``: what idle vehicles do (see :mod:`dispatch.api.repositioner`).

    ``policy`` names an installed repositioner (``stay``: they wait where they are); a
    non-passive one is called every ``interval`` seconds and sees the requests released in the
    last ``horizon`` seconds. ``params`` holds each policy's ``[reposition.<name>]`` table
    (its constructor's keyword arguments). ``declared``: the file has a ``[reposition]`` table
    or a ``reposition`` sweep, so run ids and partitions name the repositioner (older layouts,
    and scenarios without it, keep theirs)."""

    policy: str = "stay"
    interval: float = 300.0  # seconds between two calls of the repositioner
    horizon: float = 1800.0  # seconds of released requests it sees
    params: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    declared: bool = False

    def params_of(self, name: str) -> tuple[tuple[str, Any], ...]:
        """The constructor arguments of repositioner ``name``."""
        return dict(self.params).get(name, ())
