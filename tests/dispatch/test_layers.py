"""The kernel in floors (docs/explanation/layout.md): every sub-package of ``dispatch/`` imports
only its own floor and the floors below it (imports inside functions and under
``TYPE_CHECKING`` counted too), no two modules reach each other, and every folder and every
module reads in one sitting (at most 20 modules a folder, 500 lines a module)."""

from __future__ import annotations

import ast

import networkx as nx
import pytest

from tests.conftest import ROOT

#: the floors, from the ground up ("" is the ground: the modules directly in dispatch/)
FLOORS = ("", "files", "api", "config", "plan", "space", "decide", "fleet", "output",
          "scenario", "checks", "run")


def _modules() -> dict[str, str]:
    """``{dotted module name: its floor}`` of every module of ``dispatch/``."""
    out = {}
    for path in sorted((ROOT / "dispatch").rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = parts[1] if len(parts) > 2 or (
            len(parts) == 2 and (ROOT / "dispatch" / parts[1]).is_dir()) else ""
    return out


def _graph() -> nx.DiGraph:
    mods = _modules()
    g = nx.DiGraph()
    for mod in mods:
        rel = mod.replace(".", "/")
        path = ROOT / (rel + ".py") if (ROOT / (rel + ".py")).exists() else \
            ROOT / rel / "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("dispatch"):
                names = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in mods
                         else node.module for a in node.names]
            for name in names:
                if name in mods and name not in (mod, "dispatch"):
                    g.add_edge(mod, name)
    return g


def test_every_module_stands_on_a_known_floor():
    assert {floor for floor in _modules().values()} == set(FLOORS)


def test_no_import_runs_back_up_a_floor():
    mods, g = _modules(), _graph()
    assert g.number_of_edges() > 200  # the walk saw the kernel's imports
    up = [f"{a} -> {b}" for a, b in g.edges
          if FLOORS.index(mods[b]) > FLOORS.index(mods[a])]
    assert up == []


def test_the_kernel_has_no_import_circle():
    cycles = list(nx.simple_cycles(_graph(), length_bound=8))
    assert cycles == [], f"import circles in dispatch/: {cycles[:5]}"


@pytest.mark.parametrize("floor", [f for f in FLOORS if f])
def test_a_floor_holds_at_most_twenty_modules(floor):
    modules = [p for p in (ROOT / "dispatch" / floor).glob("*.py") if p.stem != "__init__"]
    assert 0 < len(modules) <= 20


def test_no_module_is_over_five_hundred_lines():
    """Every module of ``dispatch/`` reads in one sitting (issue 39's form target)."""
    long = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / "dispatch").rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 500}
    assert long == {}


def test_a_plugin_contract_lives_in_api():
    """What a plugin subclasses (the registry's bases) is in ``dispatch.api``."""
    from dispatch.api import registry

    assert all(base.startswith("dispatch.api.") for base in registry.BASES.values())


#: functions numba compiles, which keep positional parameters (numba's compiled functions take
#: no keyword-only ones): by their decorator, ``jit``, ``kernel`` (called with options or not)
#: or ``_inline`` (dispatch._compiled, dispatch.plan._kernel), and by name the schedule rule of dispatch.plan.stops, written in
#: plain Python and compiled as written by dispatch.plan._kernel's ``_twin``
COMPILED_DECORATORS = {"jit", "kernel", "_inline"}
COMPILED_TWINS = {("dispatch/plan/stops.py", name)
                  for name in ("timetable", "leave", "leave_late", "later")}


def test_no_function_takes_more_than_six_positional_parameters():
    """Issue 39: a function of more than six parameters takes the rest by keyword (``self``
    and ``cls`` not counted), compiled kernels aside."""
    long = []
    for path in sorted((ROOT / "dispatch").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            if ({ast.unparse(d.func if isinstance(d, ast.Call) else d)
                 for d in node.decorator_list} & COMPILED_DECORATORS
                    or (rel, node.name) in COMPILED_TWINS):
                continue
            names = [a.arg for a in node.args.posonlyargs + node.args.args]
            if names[:1] in (["self"], ["cls"]):
                names = names[1:]
            if len(names) > 6:
                long.append(f"{rel}:{node.lineno} {node.name} ({len(names)})")
    assert long == []
