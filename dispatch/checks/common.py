"""What the plugin checks share: the report of verdicts, the construction and declaration
checks, the replay under another global random state, and the small spaces they run on.

    from dispatch.checks.allocators import check_allocator
    from dispatch.checks.planners import check_planner
    from dispatch.checks.repositioners import check_repositioner
    from dispatch.checks.chargers import check_charger

    report = check_allocator(MyAllocator, some_param=3)   # keyword arguments: the constructor's
    assert report.ok, report                              # str(report): one line per check

    report = check_planner(MyPlanner)                     # on a small voxel world / road grid
    report = check_planner(MyPlanner, space)              # or on a space of your own

    report = check_repositioner(MyRepositioner, zone=500)  # on random views of a road grid

From the command line: ``dispatch check NAME`` (an installed allocator, planner,
repositioner or charging strategy). Each check module's docstring lists its checks; the
``deterministic`` and ``rng`` checks of every kind are :func:`replay`'s.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dispatch.api import registry
from dispatch.api.space import space_class
from dispatch.errors import PluginError


@dataclass(frozen=True)
class CheckResult:
    """One check's verdict: passed (``ok``), failed, or ``skipped`` (it had nothing to run on:
    every case stopped at an earlier check; never ``ok``)."""

    name: str
    ok: bool
    detail: str
    skipped: bool = False

    @property
    def mark(self) -> str:
        return "pass" if self.ok else "skip" if self.skipped else "FAIL"


@dataclass
class Report:
    """The verdicts of one plugin: ``ok`` when every check passed; ``str``: one line each."""

    plugin: str
    results: list[CheckResult] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    def failed(self) -> list[CheckResult]:
        return [r for r in self.results if not r.ok]

    def add(self, name: str, failures: list[str], passed: str, *, ran: int | None = None,
            of: int | None = None, after: str = "") -> None:
        """Record check ``name``: failed on the first of ``failures``, else passed with
        ``passed``. A check that depends on an earlier one says on how many cases it ``ran``
        (``of`` the cases; None: all): on none it is skipped (never passed), naming the check it
        waited for (``after``); on some, its pass says on how many."""
        if failures:
            more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
            self.results.append(CheckResult(name, False, failures[0] + more))
        elif ran == 0:
            self.results.append(CheckResult(
                name, False, f"not run: no case got past {after or 'the earlier checks'}",
                skipped=True))
        elif ran is not None and of is not None and ran < of:
            self.results.append(CheckResult(name, True, f"{passed} (on the {ran} of {of} cases "
                                                        f"that got past {after})"))
        else:
            self.results.append(CheckResult(name, True, passed))

    def __str__(self) -> str:
        return "\n".join(f"{r.mark} {r.name}: {r.detail}" for r in self.results)


def describe_error(e: BaseException) -> str:
    msg = " ".join(str(e).split())
    return f"{type(e).__name__}: {msg[:300]}" if msg else type(e).__name__


def perturb_global_rng(k: int) -> None:
    import sys

    random.seed(k)
    np.random.seed(k)
    torch = sys.modules.get("torch")  # only if a plugin imported it
    if torch is not None:
        torch.manual_seed(k)


def declared(kind: str, cls) -> tuple[Report, registry.Capabilities | None]:
    """A fresh report for plugin class ``cls`` of ``kind`` and what it declares (the
    registry's record); a class the registry would refuse (it does not subclass its kind's
    base class, or declares a capability without the method it needs) fails "construct"
    with the reason, and its declaration is None."""
    try:
        caps = registry.capabilities(kind, cls)
    except PluginError as e:
        report = Report(cls.__qualname__)
        report.add("construct", [str(e)], "")
        return report, None
    return Report(caps.name or cls.__name__), caps


def constructed(kind: str, cls, params: dict) -> tuple[Report, registry.Capabilities | None]:
    """:func:`declared`, with the "construct" check: ``cls(**params)`` must not raise
    (``report.ok`` says whether it did not)."""
    report, caps = declared(kind, cls)
    if caps is None:
        return report, caps
    try:
        cls(**params)
    except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
        report.add("construct", [f"{cls.__name__}(**{params!r}) raised {describe_error(e)}"], "")
        return report, caps
    report.add("construct", [], f"{cls.__name__}(**{params!r})")
    return report, caps


def replay(label: str, call: Callable[[], Any], first: Any, differs: list[str],
            global_rng: list[str], *, same: Callable[[Any, Any], bool] = lambda a, b: a == b,
            show: Callable[[Any], str] = str, given: str = "input") -> None:
    """Replay a check: ``call()`` (a fresh plugin on a fresh copy of the ``given`` input) must
    give ``first`` again, and again under another global random state. A call that raises or
    answers otherwise is appended to ``differs``; one whose answer follows the global random
    state, to ``global_rng``."""
    try:
        perturb_global_rng(1)
        again = call()
        perturb_global_rng(987654)
        other = call()
    except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
        differs.append(f"{label}: a second call raised {describe_error(e)}")
        return
    if not same(again, first):
        differs.append(f"{label}: the same {given} gave {show(again)}, then {show(first)}")
    elif not same(other, first):
        global_rng.append(f"{label}: the answer changed with the global random state "
                          f"({show(first)} vs {show(other)}); draw only from the seeded "
                          f"generator it is given")


def first_answer(report: Report, call: Callable[[], Any], what: str) -> tuple[bool, Any]:
    """``(True, call())`` under a fixed global random state; ``(False, None)`` when it raised,
    with the failed "valid" check saying ``what`` raised what."""
    try:
        perturb_global_rng(1)
        return True, call()
    except Exception as e:  # noqa: BLE001 - any exception is a failure of the plugin
        report.add("valid", [f"{what} raised {describe_error(e)}"], "")
        return False, None


def add_replayed(report: Report, call: Callable[[], Any], first: Any, given: str,
                 answers: str) -> None:
    """The "deterministic" and "rng" checks of :func:`replay` on one input (``given``: what
    the plugin is given; ``answers``: what it answers), added to ``report``."""
    differs, global_rng = [], []
    replay(given, call, first, differs, global_rng, given=given)
    report.add("deterministic", differs, f"same {given}, same {answers}")
    report.add("rng", global_rng, f"{answers} do not depend on the global random state")


def same_snapshot(a: tuple, b: tuple) -> bool:
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray):
            if not isinstance(y, np.ndarray) or x.shape != y.shape or \
                    not np.array_equal(x, y, equal_nan=True):
                return False
        elif x != y:
            return False
    return True


def small_world(seed: int = 0):
    """A 12 x 12 x 6 m voxel world of 1 m cells with 4 obstacles (the voxel space's
    :meth:`~dispatch.api.space.Space.small`)."""
    return space_class("voxel").small(seed)


def small_network():
    """A 6 x 5 Manhattan grid, 100 m blocks, 10 m/s (the road space's
    :meth:`~dispatch.api.space.Space.small`)."""
    return space_class("road").small()
