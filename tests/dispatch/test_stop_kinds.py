"""A stop kind is one declaration and one handler (dispatch.plan.kinds): the table is complete
(every kind a stop is ever built with has exactly one handler), a kind class without a handler
is refused when it is defined, and the table refuses two handlers of one kind."""

from __future__ import annotations

import ast

import pytest

from dispatch.plan import kinds, stops
from dispatch.plan.breaks import BREAK
from tests.conftest import ROOT


def _kinds_built() -> set[str]:
    """Every kind constant a ``Stop(...)`` is built with anywhere in dispatch/ (its first
    argument's name, resolved through the modules' constants)."""
    names = {n: getattr(stops, n) for n in ("PICKUP", "DROPOFF", "CHARGE", "REPOSITION", "DEPOT")}
    names["BREAK"] = BREAK
    built = set()
    for path in (ROOT / "dispatch").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Stop" \
                    and node.args and isinstance(node.args[0], ast.Name) \
                    and node.args[0].id in names:
                built.add(names[node.args[0].id])
    return built


def test_every_kind_a_stop_is_built_with_has_exactly_one_handler():
    built = _kinds_built()
    assert built >= {stops.PICKUP, stops.DROPOFF, stops.CHARGE, stops.REPOSITION, stops.DEPOT,
                     BREAK}  # the walk saw the kernel's stops
    assert built <= set(kinds.TABLE)
    assert all(k.name == name for name, k in kinds.TABLE.items())
    assert len({type(k) for k in kinds.TABLE.values()}) == len(kinds.TABLE)


def test_a_kind_without_a_handler_is_refused_when_it_is_defined():
    with pytest.raises(TypeError, match="must set name and define arrive"):
        class Wait(stops.StopKind):  # noqa: F841 - refused as it is defined
            name = "wait"
    with pytest.raises(TypeError, match="must set name and define arrive"):
        class Nameless(stops.StopKind):  # noqa: F841
            def arrive(self, op, v, stop):
                yield from ()
                return True


def test_the_table_refuses_two_handlers_of_one_kind():
    class Other(kinds.Pickup):
        """Another pickup handler."""

    with pytest.raises(TypeError, match="'pickup' has two handlers"):
        kinds.table(kinds.Pickup(), Other())


def test_the_declarations_say_what_the_fleet_and_decisions_read():
    t = kinds.TABLE
    # a repositioning move is cut by a request; every other stop is kept
    assert [n for n, k in t.items() if not k.kept] == [stops.REPOSITION]
    # a plan of only a visit or a break is neither idle nor busy; a move and the way home idle
    assert {n for n, k in t.items() if k.idle} == {stops.REPOSITION, stops.DEPOT}
