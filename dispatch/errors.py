"""Errors the kernel raises. Each names what is wrong so a user can fix it without a traceback."""

from __future__ import annotations


class DispatchError(Exception):
    """Base class of every error this package raises on purpose."""


class ScenarioError(DispatchError):
    """A scenario file (or a file it names) is invalid.

    The message always names the file, the key (or row) and the reason.
    """

    def __init__(self, file: str, key: str, reason: str) -> None:
        self.file, self.key, self.reason = str(file), key, reason
        super().__init__(f"{self.file}: {key}: {reason}")


class PluginError(DispatchError):
    """An allocator or planner name is unknown or its plugin cannot be loaded."""


class AllocationError(DispatchError):
    """An allocator returned an answer the dispatcher cannot accept."""


class WorldError(DispatchError):
    """A world cannot be built from its configuration (e.g. obstacles do not fit)."""


#: what a refusal for size or work says a user can do about it
LIMITS_HINT = "use --ignore-limits to run anyway"
