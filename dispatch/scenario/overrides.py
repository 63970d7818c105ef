"""Command-line overrides of scenario keys (``--set section.key=value``, ``--capacity``,
``--batch-window``, ``--duration``): each is written into the scenario's text, which is then
parsed once like any file, so that a bad key or value raises the same
:class:`~dispatch.errors.ScenarioError` as in the file (naming the key), and the text stored
with the results says what ran (every changed line ends ``# dispatch OPTION``, e.g.
``# dispatch --set``)."""

from __future__ import annotations

import copy
import json
import re
import tomllib
from pathlib import Path

from dispatch.errors import DispatchError, ScenarioError


def parse_set(item: str, path: Path) -> tuple[str, str]:
    """``"section.key=value"`` -> ``("section.key", value as TOML)``: the value as written when
    it reads as a TOML value (``4``, ``30.0``, ``true``, ``"rtv"``, ``[1, 2]``), else quoted as
    a string (``rtv``); raise ScenarioError for an item without ``=`` or key."""
    key, sep, raw = item.partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key or not raw:
        raise ScenarioError(path, "--set", f"must be SECTION.KEY=VALUE (e.g. fleet.capacity=4), "
                                           f"got {item!r}")
    parts = key.split(".")
    if any(not re.fullmatch(r"[A-Za-z0-9_-]+", p) for p in parts):
        raise ScenarioError(path, "--set", f"{key!r} is not a dotted key of bare names "
                                           "(e.g. dispatch.batch_window)")
    try:
        tomllib.loads(f"v = {raw}")
    except tomllib.TOMLDecodeError:
        raw = json.dumps(raw)  # a bare word: a string (JSON's escapes are TOML's)
    return key, raw


def apply_overrides(text: str, doc: dict, overrides: list[tuple[str, str, str]],
                    path: Path) -> tuple[str, dict]:
    """``text`` and its document ``doc`` with each ``(dotted key, TOML value, option)`` of
    ``overrides`` set, in order (the line ends with ``# dispatch OPTION``): the key's line replaced
    (a value over several lines with
    all of them), or added under its table's header (the table added at the end when the file
    has none). Raise ScenarioError naming the key when the file writes it in a way this cannot
    replace (an inline table, a dotted key): the result is checked against the document."""
    for key, raw, option in overrides:
        *tables, name = key.split(".")
        value = tomllib.loads(f"v = {raw}")["v"]
        want = copy.deepcopy(doc)
        node = want
        for i, t in enumerate(tables):
            node = node.setdefault(t, {})
            if not isinstance(node, dict):
                raise ScenarioError(path, ".".join(tables[:i + 1]), "is not a table; cannot set "
                                                                    f"{key} in it")
        node[name] = value
        text = _set_line(text, tables, name, f"{name} = {raw}  # dispatch {option}")
        try:
            got = tomllib.loads(text)
        except tomllib.TOMLDecodeError:
            got = None
        if got != want:
            raise ScenarioError(path, key, "cannot be set from the command line as the file "
                                           "writes it (an inline table or dotted key); edit "
                                           "the file")
        doc = got
    return text, doc


def _set_line(text: str, tables: list[str], name: str, line: str) -> str:
    lines = text.splitlines()
    header = re.compile(r"^\s*\[\s*" + r"\s*\.\s*".join(map(re.escape, tables))
                        + r"\s*\]\s*(#.*)?$") if tables else None
    any_header = re.compile(r"^\s*\[")
    if header is None:
        start = 0
    else:
        found = [i for i, s in enumerate(lines) if header.match(s)]
        if not found:
            return "\n".join(lines + ["", f"[{'.'.join(tables)}]", line]) + "\n"
        start = found[0] + 1
    end = next((i for i in range(start, len(lines)) if any_header.match(lines[i])), len(lines))
    assign = re.compile(r"^\s*" + re.escape(name) + r"\s*=")
    for i in range(start, end):
        if assign.match(lines[i]):
            last = i
            while last < end:  # the value's lines: up to the first that closes it
                try:
                    tomllib.loads("\n".join(lines[i:last + 1]))
                    break
                except tomllib.TOMLDecodeError:
                    last += 1
            return "\n".join(lines[:i] + [line] + lines[min(last, end - 1) + 1:]) + "\n"
    return "\n".join(lines[:start] + [line] + lines[start:]) + "\n"


def key_values(items) -> dict:
    """``KEY=VALUE`` strings as ``--param`` takes them (``dispatch check``, ``dispatch bench``):
    each VALUE read as TOML, else kept as a string; DispatchError naming an item without a key
    or an ``=``."""
    params = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise DispatchError(f"--param must be KEY=VALUE, got {item!r}")
        try:
            params[key.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            params[key.strip()] = value
    return params
