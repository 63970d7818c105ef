"""A TOML table of a scenario file being read: typed getters that raise one
:class:`~dispatch.errors.ScenarioError` naming the file, the dotted key and the reason, and the
check that no key is left unread (an unknown key).

A table is read into its section's dataclasses (``of``): a key the file leaves out takes the
default of the field of the same name, written once, in the dataclass (:func:`default_of`);
a getter is given a default of its own only where the default is not a field's (it depends on
another setting, or it marks a key the file left out).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from pathlib import Path
from typing import Any

from dispatch.config.scenario import _short
from dispatch.config.world import Vec3
from dispatch.errors import ScenarioError

#: a getter's default when it is not given: the default of the section's field of the key's name
FIELD: Any = object()


def default_of(classes: tuple[type, ...], name: str) -> Any:
    """The default of field ``name`` of the first of the dataclasses ``classes`` that has one
    (a ``default_factory`` called); LookupError where none has a field ``name`` with a
    default (a parser that asks for it has a bug)."""
    for cls in classes:
        for f in dataclasses.fields(cls):
            if f.name != name:
                continue
            if f.default is not dataclasses.MISSING:
                return f.default
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
            raise LookupError(f"{cls.__name__}.{name} has no default")
    raise LookupError(f"no field {name!r} in {', '.join(c.__name__ for c in classes)}")


def did_you_mean(word: str, known) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``known`` to ``word``; "" where none is close."""
    close = difflib.get_close_matches(str(word), [str(k) for k in known], n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


class Table:
    """A TOML table being read into the dataclasses ``of``: typed getters that raise
    ScenarioError and take a left-out key's default from its field, unknown-key check."""

    def __init__(self, file: Path, prefix: str, data: Any, of: tuple[type, ...] = ()) -> None:
        self.file, self.prefix, self.of = file, prefix, of
        if not isinstance(data, dict):
            raise ScenarioError(file, prefix.rstrip(".") or "<root>", "must be a table")
        self.data, self.used = data, set()
        self.known: set[str] = set()  # keys declared by expect(), read or not

    def key(self, k: str) -> str:
        return f"{self.prefix}{k}"

    def fail(self, k: str, reason: str) -> ScenarioError:
        return ScenarioError(self.file, self.key(k), reason)

    def default(self, name: str) -> Any:
        """The default of this table's field ``name`` (see :func:`default_of`)."""
        return default_of(self.of, name)

    def get(self, k: str, default: Any = FIELD) -> Any:
        """The file's value of ``k`` as it is; left out: ``default`` (not given: the field's)."""
        if self.known and k not in self.known:  # a parser bug: expect() would refuse the key
            raise LookupError(f"{self.key(k)} is read but not declared in expect()")
        self.used.add(k)
        if k in self.data:
            return self.data[k]
        return self.default(k) if default is FIELD else default

    def given(self, k: str) -> Any:
        """The file's value of ``k`` as it is; None where the file leaves it out."""
        return self.get(k, None)

    def table(self, k: str, *of: type) -> Table:
        """The sub-table ``k`` (empty where left out), read into the dataclasses ``of``."""
        return Table(self.file, self.key(k) + ".", self.get(k, {}), of)

    def number(self, k, default=FIELD, *, lo=None, gt=None, hi=None, integer=False):
        """The number ``k``, checked (finite; ``>= lo``, ``> gt``, ``<= hi``; an integer);
        left out: ``default`` as it is (not given: the field's, which may be None or inf)."""
        v = self.get(k, default)
        if k not in self.data:
            return v
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

    def string(self, k, default=FIELD, choices=None) -> str:
        """The non-empty string ``k``, one of ``choices`` where given; left out: ``default``
        (not given: the field's)."""
        v = self.get(k, default)
        if k not in self.data:
            return v
        if not isinstance(v, str) or not v:
            raise self.fail(k, f"must be a non-empty string, got {_short(v)}")
        if choices and v not in choices:
            raise self.fail(k, f"must be one of {', '.join(choices)}; got {_short(v)}"
                               f"{did_you_mean(v, choices)}")
        return v

    def flag(self, k, default=FIELD) -> bool:
        """``k``, true or false; left out: ``default`` (not given: the field's)."""
        v = self.get(k, default)
        if k not in self.data:
            return v
        if not isinstance(v, bool):
            raise self.fail(k, f"must be true or false, got {_short(v)}")
        return v

    def vec3(self, k, default=FIELD, *, gt=0.0) -> Vec3:
        """Three finite numbers > ``gt``; left out: ``default`` (not given: the field's)."""
        v = self.get(k, default)
        if k not in self.data:
            return v
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
        """A list of names; left out: the field's default."""
        v = self.get(k)
        if k not in self.data:
            return v
        if not isinstance(v, list) or any(not isinstance(x, str) or not x for x in v):
            raise self.fail(k, f"must be a list of names, got {_short(v)}")
        return tuple(v)

    def int_list(self, k, lo=None, hi=None) -> tuple[int, ...]:
        """A list of integers in ``[lo, hi]``; left out: the field's default."""
        v = self.get(k)
        if k not in self.data:
            return v
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

    def expect(self, known) -> None:
        """Refuse a key not in ``known`` now, before any value is read (a value may name a file
        that takes long to read or fails); ``known`` joins the keys :meth:`done` lists."""
        self.known.update(known)
        self._refuse_unknown(self.known)

    def done(self) -> None:
        """Refuse a key that was neither read nor declared (:meth:`expect`), naming the closest
        known key."""
        self._refuse_unknown(self.used | self.known)

    def _refuse_unknown(self, known: set[str]) -> None:
        unknown = sorted(set(self.data) - known)
        if unknown:
            hint = did_you_mean(unknown[0], known)
            raise self.fail(unknown[0], f"unknown key{hint} (known keys here: "
                                        f"{', '.join(sorted(known))})")

    def reading(self, k: str, file: Path):
        """A context in which ``file``, named by key ``k``, is read: its ScenarioError is raised
        again naming this scenario file and ``k`` (the file's own name and row in the reason)."""
        return _Reading(self, k, file)


class _Reading:
    """See :meth:`Table.reading`."""

    def __init__(self, table: Table, k: str, file: Path) -> None:
        self.table, self.k, self.file = table, k, file

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, err, tb) -> bool:
        if not isinstance(err, ScenarioError) or err.file == str(self.table.file):
            return False
        name = Path(err.file).name
        where = f"{name}" if err.key == "<file>" else f"{name}: {err.key}:"
        raise self.table.fail(self.k, f"{where} {err.reason}") from None
