"""A TOML table of a scenario file being read: typed getters that raise one
:class:`~dispatch.errors.ScenarioError` naming the file, the dotted key and the reason, and the
check that no key is left unread (an unknown key)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from dispatch.config.scenario import Vec3, _short
from dispatch.errors import ScenarioError


class Table:
    """A TOML table being read: typed getters that raise ScenarioError, unknown-key check."""

    def __init__(self, file: Path, prefix: str, data: Any) -> None:
        self.file, self.prefix = file, prefix
        if not isinstance(data, dict):
            raise ScenarioError(file, prefix.rstrip(".") or "<root>", "must be a table")
        self.data, self.used = data, set()

    def key(self, k: str) -> str:
        return f"{self.prefix}{k}"

    def fail(self, k: str, reason: str) -> ScenarioError:
        return ScenarioError(self.file, self.key(k), reason)

    def get(self, k: str, default: Any) -> Any:
        self.used.add(k)
        return self.data.get(k, default)

    def table(self, k: str) -> Table:
        return Table(self.file, self.key(k) + ".", self.get(k, {}))

    def number(self, k, default, *, lo=None, gt=None, hi=None, integer=False, optional=False):
        v = self.get(k, default)
        if v is None and optional:
            return None
        kind = "an integer" if integer else "a number"
        if isinstance(v, bool) or not isinstance(v, (int, float) if not integer else int):
            raise self.fail(k, f"must be {kind}, got {_short(v)}")
        if not integer and not math.isfinite(v):
            raise self.fail(k, f"must be finite, got {_short(v)}")
        if lo is not None and v < lo:
            raise self.fail(k, f"must be >= {lo}, got {_short(v)}")
        if gt is not None and v <= gt:
            raise self.fail(k, f"must be > {gt}, got {_short(v)}")
        if hi is not None and v > hi:
            raise self.fail(k, f"must be <= {hi}, got {_short(v)}")
        return int(v) if integer else float(v)

    def string(self, k, default, choices=None) -> str:
        v = self.get(k, default)
        if not isinstance(v, str) or not v:
            raise self.fail(k, f"must be a non-empty string, got {_short(v)}")
        if choices and v not in choices:
            raise self.fail(k, f"must be one of {', '.join(choices)}; got {_short(v)}")
        return v

    def vec3(self, k, default, *, gt=0.0) -> Vec3:
        v = self.get(k, default)
        if (
            not isinstance(v, (list, tuple))
            or len(v) != 3
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)
        ):
            raise self.fail(k, f"must be a list of 3 numbers, got {_short(v)}")
        if any(not math.isfinite(x) or x <= gt for x in v):
            raise self.fail(k, f"every entry must be finite and > {gt}, got {_short(v)}")
        return tuple(float(x) for x in v)  # type: ignore[return-value]

    def str_list(self, k) -> tuple[str, ...]:
        v = self.get(k, [])
        if not isinstance(v, list) or any(not isinstance(x, str) or not x for x in v):
            raise self.fail(k, f"must be a list of names, got {_short(v)}")
        return tuple(v)

    def int_list(self, k, lo=None, hi=None) -> tuple[int, ...]:
        v = self.get(k, [])
        if not isinstance(v, list) or any(isinstance(x, bool) or not isinstance(x, int) for x in v):
            raise self.fail(k, f"must be a list of integers, got {_short(v)}")
        if lo is not None and any(x < lo for x in v):
            raise self.fail(k, f"every entry must be >= {lo}, got {_short(v)}")
        if hi is not None and any(x > hi for x in v):
            raise self.fail(k, f"every entry must be <= {hi}, got {_short(v)}")
        return tuple(v)

    def params(self, k) -> tuple[tuple[str, Any], ...]:
        v = self.get(k, {})
        if not isinstance(v, dict):
            raise self.fail(k, "must be a table of parameters")
        return tuple(sorted(v.items()))

    def params_all(self) -> tuple[tuple[str, Any], ...]:
        """This whole table as sorted parameters."""
        self.used.update(self.data)
        return tuple(sorted(self.data.items()))

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used))
            raise self.fail(unknown[0], f"unknown key (known keys here: {known})")
