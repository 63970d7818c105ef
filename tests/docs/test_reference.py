"""The generated scenario-key reference (``docs/_ext/dispatch_reference.py``): every key a
scenario file accepts has a row, and every row says what the key means and its type as the
file writes it (TOML), not as Python stores it. Read without Sphinx (the module imports it
only when the site is built)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from dispatch.files.roads import SHIPPED
from dispatch.scenario.keys import KEYS

EXT = Path(__file__).resolve().parents[2] / "docs" / "_ext" / "dispatch_reference.py"

#: a TOML type starts with one of TOML's own words
TOML_WORDS = re.compile(r"^(string|integer|float|boolean|date|array|table)\b")
#: what a Python annotation leaves in a type's text
PYTHON_WORDS = re.compile(r"tuple\[|\bAny\b|\bNone\b|\bstr\b|\bint\b|\bbool\b|\bPath\b|"
                          r"\bdatetime\b|\bVec3\b|\|")


@pytest.fixture(scope="module")
def reference():
    spec = importlib.util.spec_from_file_location("dispatch_reference", EXT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def rows(reference):
    return reference.scenario_rows()


def test_every_key_has_a_meaning_and_a_toml_type(rows):
    assert len(rows) > 80  # every section is read (a lost section would shrink this)
    for title, row in rows:
        where = f"{title} {row['key']}"
        meaning = row["meaning"].strip()
        assert meaning and meaning not in ("—", "-"), f"{where}: no meaning"
        assert not re.search(r"\b(None|True|False)\b", meaning), f"{where}: Python in {meaning!r}"
        assert TOML_WORDS.match(row["type"]), f"{where}: {row['type']!r} is not a TOML type"
        assert not PYTHON_WORDS.search(row["type"]), f"{where}: {row['type']!r} is Python"
        assert row["default"].strip(), f"{where}: no default"


def test_every_declared_key_of_the_file_is_in_the_reference(rows):
    """The keys the parser checks before reading anything (``dispatch.scenario.keys``),
    tables aside (their own sections), each have a row in their section."""
    titles = {"": "top level", "fleet": "[fleet]", "tasks": "[tasks]",
              "dispatch": "[dispatch]", "comms": "[comms]", "sweep": "[sweep]"}
    tables = {"world", "fleet", "tasks", "dispatch", "comms", "faults", "sweep", "reposition",
              "chargers", "charging", "pricing", "acceptor", "energy", "breaks",
              "transit"}
    have = {(title, row["key"]) for title, row in rows}
    missing = [f"{section or 'top level'}.{key}" for section, keys in KEYS.items()
               for key in keys if key not in tables and (titles[section], key) not in have]
    assert not missing


def test_network_lists_every_accepted_value(rows):
    (network,) = [row for title, row in rows if row["key"] == "network"]
    for name in ("manhattan", *SHIPPED):
        assert f'`"{name}"`' in network["meaning"]
    assert "manhattan_osm" in SHIPPED  # the NYC scenarios' network, named in the reference


def test_types_follow_the_annotation_and_the_unit(reference):
    """A few fixed answers: the TOML type of a field is its annotation's TOML form, with the
    unit its comment starts with; an annotation with no TOML form is refused by name."""
    import dataclasses

    @dataclasses.dataclass
    class Example:
        wait: float | None = None  # seconds a rider waits
        names: tuple[str, ...] = ()
        params: tuple[tuple[str, object], ...] = ()

    fields = {f.name: f for f in dataclasses.fields(Example)}
    unit = reference.split_unit("seconds a rider waits")[0]
    assert reference.toml_type(fields["wait"], unit) == "float (seconds)"
    assert reference.toml_type(fields["names"]) == "array of strings"
    with pytest.raises(LookupError, match="params"):
        reference.toml_type(fields["params"])
    assert reference.toml_value((1.0, True, "a", float("inf"))) == '[1.0, true, "a", inf]'
    assert reference.toml_words("cap (None: no cap; True: on)") == "cap (unset: no cap; true: on)"
