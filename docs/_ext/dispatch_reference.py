"""Sphinx extension: writes the generated reference pages before the build reads its sources.

One source of truth each, read at build time, never copied by hand:

* scenario keys: the typed configuration's frozen dataclasses (one per section, in the modules of
  ``dispatch.config``, and ``[pricing]``'s wherever it lives), their defaults from
  :func:`dataclasses.fields`, their meaning from the comment on or above each field in the
  source (a leading unit word becomes part of the type), their type as the file writes it
  (TOML: ``string``, ``float (seconds)``, ``array of [x, y, z]``), derived from the field's
  annotation or given by its ``metadata["toml"]`` where the file's form differs from the
  stored one (a file name read into rows); ``metadata["default"]`` words a default that is no
  value (``name``: the file's stem);
* the command line: the argument parser of ``dispatch.run.parser`` (the plugin commands included);
* the Parquet tables: ``dispatch.output.parquet.SCHEMAS`` (column names and Arrow types), each
  column's meaning from the table of the results page (``explanation/output.md``) where it
  has one, else from the comment above it in the recorder;

The pages land in ``reference/generated/`` (git-ignored); ``reference/*.md`` include them.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib
import inspect
import io
import math
import re
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).resolve().parents[1] / "reference" / "generated"

#: comment words that name a unit when a field's comment starts with them
UNITS = ("metres", "m/s", "seconds", "simulated seconds", "km/h", "Wh/km", "kWh", "kW",
         "probability", "share", "breakdowns per vehicle-hour")


# ----------------------------------------------------------------------------- field comments


def field_comments(cls: type) -> dict[str, str]:
    """``{field: comment}``: the trailing ``# ...`` on a field's line, or the ``#:`` lines
    right above it (Sphinx's convention), joined."""
    src = inspect.getsource(cls)
    tree = ast.parse(src)
    body = tree.body[0].body  # type: ignore[attr-defined]
    lines = src.splitlines()
    trailing: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.COMMENT:
            trailing[tok.start[0]] = tok.string
    out = {}
    for node in body:
        if not isinstance(node, ast.AnnAssign) or not isinstance(node.target, ast.Name):
            continue
        parts = []
        i = node.lineno - 2  # lines above (0-based index of the line above)
        above = []
        while i >= 0 and lines[i].strip().startswith("#:"):
            above.insert(0, lines[i].strip()[2:].strip())
            i -= 1
        parts += above
        c = trailing.get(node.end_lineno or node.lineno)
        code_line = lines[(node.end_lineno or node.lineno) - 1]
        if c and not code_line.strip().startswith("#"):
            parts.append(c.lstrip("#").strip())
        out[node.target.id] = " ".join(parts)
    return out


def find_class(name: str, package: str = "dispatch"):
    """The dataclass ``name`` from whichever module of ``package`` defines it (modules move;
    the concept stays)."""
    pkg = ROOT / package
    for path in sorted(pkg.rglob("*.py")):
        if re.search(rf"^class {name}\b", path.read_text(encoding="utf-8"), re.M):
            mod = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            return getattr(importlib.import_module(mod), name)
    raise LookupError(f"no module of {package} defines {name}")


#: the TOML form of the annotations the configuration uses (``X | None``: X, left out)
TOML_TYPES = {
    "str": "string",
    "int": "integer",
    "float": "float",
    "bool": "boolean",
    "Path": "string (a file, relative to the scenario file)",
    "datetime": "string (a date-time, e.g. \"2014-12-21T00:00\")",
    "Vec3": "array of [x, y, z] (3 floats)",
    "dt.date": "date (a TOML local date, e.g. 2026-09-23)",
    "tuple[int, int]": "array of 2 integers",
    "tuple[float, ...]": "array of floats",
    "tuple[int, ...]": "array of integers",
    "tuple[str, ...]": "array of strings",
    "tuple[tuple[str, Any], ...]": "table (keys to values)",
}


def toml_type(f: dataclasses.Field, unit: str = "") -> str:
    """The type of key ``f`` as a scenario file writes it (``"float (seconds)"``); LookupError
    for an annotation with no TOML form here (give the field a ``metadata["toml"]``)."""
    if "toml" in f.metadata:
        return f.metadata["toml"]
    ann = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    ann = ann.replace("typing.", "").removesuffix(" | None")
    if ann not in TOML_TYPES:
        raise LookupError(f"{f.name}: annotation {ann!r} has no TOML type; give the field "
                          "metadata={'toml': ...}")
    base = TOML_TYPES[ann]
    return f"{base} ({unit})" if unit and "(" not in base else base


def toml_words(doc: str) -> str:
    """A field comment in the file's words: Python's ``None`` is a key left out (``unset``),
    ``True`` / ``False`` are TOML's ``true`` / ``false``."""
    doc = re.sub(r"\bNone\b", "unset", doc)
    return re.sub(r"\b(True|False)\b", lambda m: m.group(1).lower(), doc)


def toml_value(v) -> str:
    """``v`` written as in a TOML file."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return '"' + v + '"'
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)  # TOML's nan, inf, -inf
    return repr(v)


def default_text(f: dataclasses.Field) -> str:
    if "default" in f.metadata:
        return f.metadata["default"]
    if f.default is not dataclasses.MISSING:
        v = f.default
    elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        v = f.default_factory()  # type: ignore[misc]
        if dataclasses.is_dataclass(v):
            return "(table)"
    else:
        return "(required)"
    if v is None:
        return "(unset)"
    if isinstance(v, tuple) and not v and "tuple[tuple[str, Any]" in str(f.type):  # a table
        return "(empty)"
    return toml_value(v)


def accepted_values(cls: type, name: str) -> str:
    """The values a key accepts from a fixed set, said after its meaning ("" for most keys):
    read from where the set is defined, so that a new shipped network is listed here too."""
    if (cls.__name__, name) == ("RoadConfig", "network"):
        from dispatch.files.roads import SHIPPED

        shipped = {"chicago": "the Chicago Regional network",
                   "manhattan_osm": "Manhattan's OSMnx street network, the NYC scenarios'"}
        names = ", ".join(f'`"{k}"` ({shipped.get(k, "shipped with the package")})'
                          for k in SHIPPED)
        return ('accepted: `"manhattan"` (a generated grid of `blocks`, `block` and `speed`), '
                f"{names}, or a file: `.graphml`, node-link `.json` (either may be `.gz`) or "
                "`X_net.tntp` with its node file beside it.")
    return ""


def split_unit(doc: str) -> tuple[str, str]:
    """``(unit, meaning)``: a leading unit word of the comment becomes the unit."""
    for u in sorted(UNITS, key=len, reverse=True):
        if doc.startswith(u) and (len(doc) == len(u) or not doc[len(u)].isalnum()):
            rest = doc[len(u):].lstrip(" :;,")
            if u in ("probability", "share"):
                return "0-1", doc
            return u, rest or "—"
    return "", doc


def esc(s: str) -> str:
    """``s`` as one Markdown table cell (reST roles and literals as Markdown code)."""
    s = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", s)
    s = s.replace("``", "`")
    return s.replace("|", "\\|").replace("\n", " ")


def guide_comments() -> dict[tuple[str, str], str]:
    """``{(table, key): comment}`` from the first TOML block of the scenario file guide
    (``scenarios/README.md``): the meaning of a key whose field has no comment in the code."""
    text = (ROOT / "scenarios" / "README.md").read_text(encoding="utf-8")
    block = text.split("```toml", 1)[1].split("```", 1)[0]
    out, table, last = {}, "", None
    for line in block.splitlines():
        m = re.match(r"\[([\w.\":]+)\]\s*(?:#\s?(.*))?$", line)
        if m:
            table, last = m.group(1), None
            out[(table, "")] = (m.group(2) or "").strip()
            continue
        m = re.match(r"(\w+)\s*=\s*(.*?)\s*#\s?(.*)$", line)
        if m:
            last = (table, m.group(1))
            out[last] = m.group(3).strip()
            out[(table, "=" + m.group(1))] = m.group(2)
        elif last and re.match(r"\s+#", line):
            out[last] += " " + line.strip().lstrip("#").strip()
        else:
            last = None
    return out


def file_keys() -> set[str]:
    """Every string literal of the scenario parser and of the configuration: a field the
    parser never names is built from others (a file's rows, a derived flag) and is not a key
    of the file."""
    keys = set()
    paths = [ROOT / "dispatch" / "scenario" / f"{mod}.py" for mod in ("load", "sections",
                                                                         "transit")]
    for path in [*paths, *sorted((ROOT / "dispatch" / "config").glob("*.py"))]:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        keys |= {n.value for n in ast.walk(tree)
                 if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    return keys


def key_rows(table: str, cls: type, keys: set[str], skip=(), guide=None
             ) -> tuple[list[dict[str, str]], list[str]]:
    """``(rows, derived)``: one row per key of ``[table]`` that ``cls`` holds (``key``,
    ``type``, ``default``, ``meaning``), and the fields the parser builds from others."""
    docs = field_comments(cls)
    rows, derived = [], []
    names = {f.name for f in dataclasses.fields(cls)}
    for f in dataclasses.fields(cls):
        if f.name in skip or default_text(f) == "(table)":  # a nested table: its own section
            continue
        if f.name not in keys:
            derived.append(f.name)
            continue
        doc = docs.get(f.name, "")
        if not doc and (table, f.name) in (guide or {}):
            doc = guide[(table, f.name)] + " *(scenario guide)*"
        if not doc and cls.__name__ == "SweepConfig":
            doc = (f"a list of `{f.name}` values (a run key): every combination of the "
                   "lists is one run")
        doc = toml_words(doc)
        unit = split_unit(doc)[0]  # the meaning keeps it: "seconds before the run stops"
        meaning = "; ".join(m for m in (doc, accepted_values(cls, f.name)) if m)
        rows.append({"key": f.name, "type": toml_type(f, unit), "default": default_text(f),
                     "meaning": meaning})
    # keys of the file that fill a field under another name (or several fields): the guide's
    for (t, k), doc in (guide or {}).items():
        if (t == table and k and not k.startswith("=") and k not in names
                and cls.__name__ != "RoadConfig"):  # the road keys share [world]
            meaning = doc
            example = guide.get((t, "=" + k), "")
            rows.append({"key": k, "type": GUIDE_TYPES[(t, k)], "default": "(unset)",
                         "meaning": f"{meaning} (e.g. `{k} = {example}`)"})
    return rows, derived


#: what a section is for, in a user's words (a dataclass's docstring speaks to the code's
#: readers; the sections without an entry here use it)
INTROS = {
    "top level": "The keys outside any table.",
    "[world]": "The voxel world of the robot teams: its size and cells (its obstacles in "
               "`[world.obstacles]`). With `network` (next section) the run is on a road "
               "network instead, where `size`, `cell`, `physics` and obstacles are refused.",
    "[world] (road networks)": "A road network instead of the voxel world: the keys "
                               "`network`, `blocks`, `block`, `speed` and `congestion` of "
                               "`[world]`.",
    "[world.obstacles]": "Boxes standing on the ground of the voxel world.",
    "[fleet]": "The vehicles: how many, their speeds and seats, where they start (a start file "
               "may add shifts: [driver shifts](../../howto/shifts.md)) and the fleet-sizing "
               "strategy.",
    "[fleet.energy]": "Batteries (road networks; no batteries without the table): capacity, "
                      "consumption, idle draw, the reserve a car keeps.",
    "[tasks]": "The requests: a generated source (`static`, `periodic`, `poisson`, "
               "`empirical`) or a trace of your own trips, and the limits a rider accepts.",
    "[dispatch]": "Who decides, and how: the allocator and the planner, batching, what a "
                  "pair costs, the plugins' parameters, when a booked ride enters.",
    "[faults]": "Breakdowns and radio blackouts; none by default.",
    "[reposition]": "What idle vehicles do (road networks): the repositioner, how often it is "
                    "called and what it sees; its parameters in `[reposition.<name>]`.",
    "[chargers] and [charging]": "Charging stations (`[chargers]`, with `[fleet.energy]`) and "
                                 "the charging strategy (`[charging]`; its parameters in "
                                 "`[charging.<name>]`).",
    "[sweep]": "Lists of run keys: every combination is one run, written to its own partition.",
    "[acceptor]": "Offers riders may decline: the acceptor, how often a declined ride is "
                  "offered again, its parameters in `[acceptor.<name>]`; every rider accepts "
                  "without the table.",
}

#: the TOML type of the keys the parser reads into a field of another name (the guide's)
GUIDE_TYPES = {
    ("faults", "file"): "string (a CSV file, relative to the scenario file)",
    ("faults", "blackout_region"): "array of [x0, y0, x1, y1] (metres)",
}


def key_table(title: str, table: str, cls: type, keys: set[str], skip=(),
              guide=None) -> list[str]:
    rows, derived = key_rows(table, cls, keys, skip, guide)
    out = [f"## {title}", ""]
    if title in INTROS:
        out += [INTROS[title]]
    elif cls.__doc__ and not cls.__doc__.startswith(cls.__name__ + "("):
        out += [esc(inspect.cleandoc(cls.__doc__))]
    elif (guide or {}).get((table, "")):
        out += [esc(guide[(table, "")]) + " *(scenario guide)*"]
    out += ["", f"Read into the dataclass `{cls.__name__}`."]
    out += ["", "| key | TOML type | default | meaning |", "|---|---|---|---|",
            *(f"| `{r['key']}` | {esc(r['type'])} | `{esc(r['default'])}` | "
              f"{esc(r['meaning'])} |" for r in rows)]
    if derived:
        out += ["", "Built by the parser, not keys of the file: "
                + ", ".join(f"`{d}`" for d in derived) + "."]
    return out + [""]


def sections() -> list[tuple[str, str, type, tuple[str, ...]]]:
    """``(title, table, dataclass, fields left out)`` of each section of the reference."""
    return [
        ("top level", "", find_class("Scenario"), ("path", "text", "charging", "acceptor",
                                                   "pricing", "transit")),
        ("[world]", "world", find_class("WorldConfig"), ("roads",)),
        ("[world] (road networks)", "world", find_class("RoadConfig"), ("base",)),
        ("[world.obstacles]", "world.obstacles", find_class("ObstacleConfig"), ()),
        ("[fleet]", "fleet", find_class("FleetConfig"), ("energy", "breaks")),
        ("[fleet.energy]", "fleet.energy", find_class("EnergyConfig"), ()),
        ("[fleet.breaks]", "fleet.breaks", find_class("BreaksConfig"), ()),
        ("[tasks]", "tasks", find_class("TaskConfig"), ()),
        ("[dispatch]", "dispatch", find_class("DispatchConfig"), ()),
        ("[comms]", "comms", find_class("CommsConfig"), ()),
        ("[faults]", "faults", find_class("FaultConfig"), ()),
        ("[reposition]", "reposition", find_class("RepositionConfig"), ()),
        # sweep: not a key of the file; tow: [faults]' key, copied here
        ("[chargers] and [charging]", "chargers", find_class("ChargingConfig"), ("sweep", "tow")),
        ("[sweep]", "sweep", find_class("SweepConfig"), ()),
        ("[acceptor]", "acceptor", find_class("AcceptorConfig"), ()),
        ("[pricing]", "pricing", find_class("Pricing"), ()),
        ("[transit]", "transit", find_class("TransitConfig"), ()),
    ]


def reference_keys() -> set[str]:
    """The names the reference takes for keys of the file (see :func:`file_keys`)."""
    return file_keys() | {"blocks", "block", "speed", "network", "congestion"}


def reference_guide() -> dict[tuple[str, str], str]:
    """The scenario guide's comments, ``[charging]``'s also under ``[chargers]``."""
    guide = guide_comments()
    for (t, k), v in list(guide.items()):  # [charging] keys live in ChargingConfig too
        if t == "charging":
            guide.setdefault(("chargers", k), v)
    return guide


def scenario_rows() -> list[tuple[str, dict[str, str]]]:
    """``(section title, row)`` for every key of the reference (what the tests read)."""
    keys, guide = reference_keys(), reference_guide()
    return [(title, row) for title, table, cls, skip in sections()
            for row in key_rows(table, cls, keys, skip, guide)[0]]


def scenario_keys() -> str:
    keys, guide = reference_keys(), reference_guide()
    out = ["# Scenario keys", "",
           "Generated from the typed configuration the scenario parser builds (one frozen "
           "dataclass per table). A type is what the file writes (TOML), with its unit; "
           "the [scenario file guide](../scenario_guide.md) explains the keys with examples, "
           "and `dispatch validate FILE` checks a file against them.", ""]
    for title, table, cls, skip in sections():
        out += key_table(title, table, cls, keys, skip, guide)
    return "\n".join(out)


# ----------------------------------------------------------------------------- command line


def _fmt_action(a: argparse.Action) -> str:
    names = ", ".join(f"`{o}`" for o in a.option_strings) or f"`{a.dest}`"
    if a.option_strings and a.nargs != 0:
        names += f" `{a.metavar or a.dest.upper()}`"
    extra = []
    if a.choices and not isinstance(a, argparse._SubParsersAction):
        extra.append("one of " + ", ".join(f"`{c}`" for c in a.choices))
    if a.default not in (None, False, argparse.SUPPRESS) and a.option_strings:
        extra.append(f"default `{a.default}`")
    text = (a.help or "").replace("%(default)s", str(a.default)).replace("%%", "%")
    return f"| {esc(names)} | {esc(text)}{' (' + '; '.join(extra) + ')' if extra else ''} |"


def command_line() -> str:
    from dispatch.run.commands import installed
    from dispatch.run.parser import OWN_COMMANDS
    from dispatch.run.parser import parser as command_parser

    parser = command_parser(installed(reserved=OWN_COMMANDS))
    out = ["# Command line", "", "Generated from the argument parser of `dispatch.run.parser`, "
           "the commands that other packages register (`dispatch.commands` entry points) "
           "included.", "", "```text", parser.format_usage().strip(), "```", "",
           "| option | meaning |", "|---|---|"]
    sub = None
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            sub = a
        elif not isinstance(a, argparse._HelpAction):
            out.append(_fmt_action(a))
    helps = {c.dest: c.help for c in sub._choices_actions} if sub else {}
    for name, p in (sub.choices.items() if sub else ()):
        out += ["", f"## dispatch {name}", "", esc(helps.get(name) or p.description or ""), "",
                "```text", p.format_usage().strip(), "```", ""]
        rows = [_fmt_action(a) for a in p._actions if not isinstance(a, argparse._HelpAction)]
        if rows:
            out += ["| argument | meaning |", "|---|---|", *rows]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- Parquet tables


def output_meanings() -> dict[str, dict[str, str]]:
    """``{table: {column: meaning}}`` from the tables of the results page: a row whose first
    cell names columns (``a, b, c``) gives each of them its meaning."""
    text = (ROOT / "docs" / "explanation" / "output.md").read_text(encoding="utf-8")
    table, out = "summary", {}
    paragraphs = re.split(r"\n\s*\n", text)
    for para in paragraphs:  # prose: "**table**: ... name (meaning), a, b (meaning) ..."
        for m in re.finditer(r"\*\*(\w+)\*\*(.*?)(?=\*\*\w+\*\*|$)", para, re.S):
            if m.group(2).lstrip().startswith("|"):
                continue
            body = " ".join(m.group(2).split())
            for g in re.finditer(r"(\w+) \(((?:[^()]|\([^()]*\))*)\)", body):
                out.setdefault(m.group(1), {}).setdefault(g.group(1), g.group(2))
    for line in text.splitlines():
        m = re.match(r"\*\*(\w+)\*\*", line)
        if m:
            table = m.group(1)
        if line.startswith("| ") and not line.startswith("|---"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) >= 2:
                for name in re.split(r",\s*", cells[0]):
                    name = name.strip("` ")
                    if re.fullmatch(r"\w+", name):
                        out.setdefault(table, {}).setdefault(name, cells[1])
    return out


def recorder_comments() -> dict[str, dict[str, str]]:
    """``{table: {column: the comment above its group}}`` in the recorder's schemas."""
    src = "\n".join((ROOT / "dispatch" / "output" / f).read_text(encoding="utf-8")
                    for f in ("parquet.py", "legs.py"))  # (legs.py: the optional tables)
    out, table, comment = {}, None, []
    for line in src.splitlines():
        m = re.match(r'\s*"(\w+)": pa\.schema', line)
        if m:
            table, comment = m.group(1), []
        s = line.strip()
        if s.startswith("#"):
            comment.append(s.lstrip("# "))
            continue
        for col in re.findall(r'\("(\w+)", _[SIFB]\)', line):
            if table and comment:
                out.setdefault(table, {})[col] = " ".join(comment)
        if not s.startswith("#"):
            comment = [] if re.search(r'\("\w+", _[SIFB]\)', line) else comment
    return out


def parquet_tables() -> str:
    from dispatch.output.legs import OPTIONAL_SCHEMAS
    from dispatch.output.parquet import SCHEMAS

    meanings, comments = output_meanings(), recorder_comments()
    out = ["# Parquet tables", "",
           "Generated from the recorder's schemas (`dispatch.output.parquet.SCHEMAS`): every "
           "table a run writes, under `OUT/<table>/<partition>/part-0.parquet` (Hive "
           "partitions: the run keys). The meaning (with its unit) comes from the "
           "[results page](../../explanation/output.md), else from the recorder's comment.", ""]
    for name, schema in {**SCHEMAS, **OPTIONAL_SCHEMAS}.items():
        if name in OPTIONAL_SCHEMAS:  # (written only where a scenario asks for it)
            out += [f"## {name}", "", f"Only where the scenario asks for it "
                    f"(`dispatch.output.legs.OPTIONAL_SCHEMAS`; {name}: `[transit]`).", ""]
            out += ["| column | type | meaning |", "|---|---|---|"]
        else:
            out += [f"## {name}", "", "| column | type | meaning |", "|---|---|---|"]
        for f in schema:
            m = meanings.get(name, {}).get(f.name) or comments.get(name, {}).get(f.name, "")
            if f.name == "run_id":
                m = m or "the run's id (its run keys joined by `__`)"
            out.append(f"| `{f.name}` | {f.type} | {esc(m)} |")
        out.append("")
    return "\n".join(out)


def generate(app=None) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    pages = {"scenario_keys.md": scenario_keys, "command_line.md": command_line,
             "parquet_tables.md": parquet_tables}
    for name, make in pages.items():
        text = make()
        path = OUT / name
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")  # unchanged pages keep Sphinx's cache


def contract_directive():
    """``.. dispatch-contract:: Name ...``: ``autoclass`` of each class, found in whichever
    module of ``dispatch`` defines it (modules move; the contract's name stays). Made here,
    not at import, so that the tests read this module without Sphinx installed."""
    from docutils import nodes
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective
    from sphinx.util.nodes import nested_parse_with_titles

    class ContractDirective(SphinxDirective):
        required_arguments = 1
        optional_arguments = 20

        def run(self):
            lines = []
            for name in self.arguments:
                cls = find_class(name)
                lines += [f".. autoclass:: {cls.__module__}.{name}", "   :members:",
                          "   :show-inheritance:", ""]
            node = nodes.section()
            node.document = self.state.document
            nested_parse_with_titles(self.state, StringList(lines, source="dispatch-contract"),
                                     node)
            return node.children

    return ContractDirective


def setup(app):
    app.connect("builder-inited", generate)
    app.add_directive("dispatch-contract", contract_directive())
    return {"version": "1", "parallel_read_safe": True}
