"""A scenario's configuration written once (issue 39): every default of a scenario key lives in
its section's dataclass in ``dispatch/config/``; the parser reads it from there, never from a
literal of its own; ``dispatch/config`` imports no behaviour."""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import pytest

from dispatch.api.acceptor import Pricing
from dispatch.config.comms import CommsConfig
from dispatch.config.dispatching import DispatchConfig
from dispatch.config.energy import ChargingConfig, EnergyConfig
from dispatch.config.faults import FaultConfig
from dispatch.config.fleet import FleetConfig
from dispatch.config.offers import AcceptorConfig
from dispatch.config.reposition import RepositionConfig
from dispatch.config.scenario import Scenario
from dispatch.config.sweep import SweepConfig
from dispatch.config.tasks import TaskConfig
from dispatch.config.transit import TransitConfig
from dispatch.config.world import ObstacleConfig, RoadConfig, WorldConfig
from dispatch.scenario.load import parse_scenario
from tests.conftest import ROOT

#: every section's dataclass, as the parser reads it
SECTIONS = (Scenario, WorldConfig, RoadConfig, ObstacleConfig, FleetConfig, EnergyConfig,
            TaskConfig, DispatchConfig, CommsConfig, FaultConfig, RepositionConfig,
            ChargingConfig, SweepConfig, AcceptorConfig, Pricing, TransitConfig)
PARSER = ("dispatch/scenario/load.py", "dispatch/scenario/sections.py",
          "dispatch/scenario/transit.py")
GETTERS = {"get", "number", "string", "flag", "vec3", "int_list", "str_list"}


def _parsed(doc: dict) -> Scenario:
    return parse_scenario(doc, Path("/nowhere/minimal.toml"))


def test_an_empty_file_is_the_dataclasses_defaults():
    sc = _parsed({})
    expected = Scenario(name="minimal", path=sc.path, text="")
    assert sc == expected
    for f in dataclasses.fields(Scenario):  # (the same, section by section: a clearer failure)
        assert getattr(sc, f.name) == getattr(expected, f.name), f.name


def test_empty_road_tables_are_the_dataclasses_defaults():
    """The tables a voxel world has none of: a road network, batteries, chargers, pricing, an
    acceptor, faults and repositioning, each written with nothing (or only what it needs)."""
    sc = _parsed({"world": {"network": "manhattan"}, "fleet": {"energy": {}}, "chargers": {},
                  "charging": {}, "faults": {}, "reposition": {}, "pricing": {"base": 0.0},
                  "acceptor": {"name": "always"}})
    assert sc.world == WorldConfig(roads=RoadConfig(network="manhattan", base=Path("/nowhere")),
                                   physics=False)
    assert sc.fleet.energy == EnergyConfig()
    assert math.isinf(sc.fleet.energy.max_charge_kw)
    assert sc.charging == ChargingConfig()
    assert sc.faults == FaultConfig()
    assert sc.reposition == RepositionConfig(declared=True)
    assert sc.pricing == Pricing()
    assert sc.acceptor == AcceptorConfig()
    assert sc.dispatch == DispatchConfig(planner="dijkstra")  # a road network's own planner


def _literal(node: ast.expr):
    try:
        return ast.literal_eval(node)
    except ValueError:
        return _NOT_LITERAL


_NOT_LITERAL = object()


def _same(a, b) -> bool:
    a = tuple(a) if isinstance(a, list) else a
    b = tuple(b) if isinstance(b, list) else b
    return type(a) is type(b) and a == b or (
        isinstance(a, (int, float)) and isinstance(b, (int, float))
        and not isinstance(a, bool) and not isinstance(b, bool) and a == b)


def _field_defaults() -> dict[str, list]:
    """``{field name: [its default in each section that has one]}``."""
    out: dict[str, list] = {}
    for cls in SECTIONS:
        for f in dataclasses.fields(cls):
            if f.default is not dataclasses.MISSING:
                out.setdefault(f.name, []).append(f.default)
            elif f.default_factory is not dataclasses.MISSING:
                out.setdefault(f.name, []).append(f.default_factory())
    return out


def _getter_defaults(path: Path):
    """``(line, key, default)`` of every getter call of ``path`` that passes a literal
    default of its own."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in GETTERS and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)):
            continue
        given = node.args[1:2] + [k.value for k in node.keywords if k.arg == "default"]
        for d in given:
            value = _literal(d)
            if value is not _NOT_LITERAL:
                yield node.lineno, node.args[0].value, value


@pytest.mark.parametrize("module", PARSER)
def test_the_parser_writes_no_default_of_its_own(module):
    """No getter of the parser is given a literal default: a left-out key takes its field's
    (a default that depends on another setting is computed; ``given`` reads a key that has
    no default, such as a file's name)."""
    defaults = _field_defaults()
    own = [f"{module}:{line}: {key} = {value!r}"
           + (" (its field's default, written again)"
              if any(_same(value, d) for d in defaults.get(key, ())) else "")
           for line, key, value in _getter_defaults(ROOT / module)]
    assert not own, "\n".join(own)


def test_the_check_would_see_a_default_written_again(tmp_path):
    bad = tmp_path / "parser.py"
    bad.write_text('agents = f.number("agents", 8, lo=1)\nok = f.number("agents", lo=1)\n'
                   'cell = w.get("cell", default=1.0)\n', encoding="utf-8")
    assert [(k, v) for _, k, v in _getter_defaults(bad)] == [("agents", 8), ("cell", 1.0)]


def test_config_imports_no_behaviour():
    """``dispatch/config`` imports the ground, ``files`` and ``api`` floors and itself only."""
    allowed = ("dispatch.config", "dispatch.api", "dispatch.files", "dispatch.errors")
    found = []
    for path in sorted((ROOT / "dispatch" / "config").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{path.name}: {n}" for n in names
                      if n.startswith("dispatch") and not n.startswith(allowed)]
    assert not found
