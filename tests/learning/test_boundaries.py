"""The learning package's place (issue 28): beside the kernel, above it. The kernel imports
nothing of ``learning``; ``learning`` uses ``dispatch`` through its public modules and names
only, and imports no plugin (plugins import it: ``hungarian``'s ``value`` option); ``dispatch
train value`` finds its trainer through the ``dispatch.trainers`` entry point."""

from __future__ import annotations

import ast
import tomllib

from tests.conftest import ROOT
from tests.dispatch.test_boundaries import PLUGIN_PACKAGES, _imports, _top


def test_the_kernel_imports_nothing_of_learning():
    assert [(f, m) for f, m in _imports("dispatch") if _top(m) == "learning"] == []


def test_learning_imports_no_plugin_and_no_analysis():
    assert [(f, m) for f, m in _imports("learning")
            if _top(m) in (*PLUGIN_PACKAGES, "analysis")] == []


def test_learning_uses_only_public_modules_and_names_of_the_kernel():
    bad, used = [], set()
    for path in sorted((ROOT / "learning").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and not node.level \
                    and _top(node.module or "") == "dispatch":
                used.add(node.module)
                private = [p for p in node.module.split(".") if p.startswith("_")]
                bad += [f"{path.relative_to(ROOT)}: {node.module}.{a.name}"
                        for a in node.names if private or a.name.startswith("_")]
    assert bad == []
    assert {"dispatch.scenario.load", "dispatch.api.contracts"} <= used  # the walk saw the imports


def test_the_value_trainer_is_the_learning_module_and_its_data_ship_with_it():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert meta["project"]["entry-points"]["dispatch.trainers"]["value"] == "learning.value_train"
    assert "learning*" in meta["tool"]["setuptools"]["packages"]["find"]["include"]
    assert meta["tool"]["setuptools"]["package-data"]["learning"] == ["data/values/*"]
    assert (ROOT / "learning" / "data" / "values" / "chicago_n500.npz").is_file()
