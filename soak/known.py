"""EXPECTED FAILURES: bugs the soak finds that are known and being fixed elsewhere. A
violation that matches an entry here is counted apart (``known`` in the soak's table) and does
not fail the CI slice; every other violation does. Remove an entry once its fix is merged: the
soak then holds the fix to it.
"""

from __future__ import annotations

from soak.generate import Case


#: (name, the invariants it breaks, which cases it concerns: a function of the
#: :class:`soak.generate.Case`). Empty: every violation the soak finds fails it. (The
#: prebooking limits bug, a waiting vehicle's plan timed from a stale ``now``, was here until
#: its fix landed.)
EXPECTED_FAILURES: tuple = ()


def known(case: Case, invariant: str) -> str | None:
    """The name of the expected failure that explains ``invariant`` broken by ``case``, or
    None."""
    for name, invariants, applies in EXPECTED_FAILURES:
        if invariant in invariants and applies(case):
            return name
    return None
