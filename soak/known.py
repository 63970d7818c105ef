"""EXPECTED FAILURES: bugs the soak finds that are known and being fixed elsewhere. A
violation that matches an entry here is counted apart (``known`` in the soak's table) and does
not fail the CI slice; every other violation does. Remove an entry once its fix is merged: the
soak then holds the fix to it.
"""

from __future__ import annotations

from soak.generate import Case


def _prebooked(case: Case) -> bool:
    tasks = case.doc.get("tasks", {})
    trips = case.files.get("trips.csv", ([], []))
    return tasks.get("prebook_share", 0) > 0 or "booked_at" in trips[0]


#: (name, the invariants it breaks, which cases it concerns). Prebooking inserts into plans at
#: any capacity (one seat included): a booked stop's ``earliest`` pushes the riders planned
#: around it past release + max_wait / release + direct + max_delay.
EXPECTED_FAILURES: tuple = (
    ("prebooking pushes riders past their wait and delay limits",
     frozenset({"wait_limit", "delay_limit"}), _prebooked),
)


def known(case: Case, invariant: str) -> str | None:
    """The name of the expected failure that explains ``invariant`` broken by ``case``, or
    None."""
    for name, invariants, applies in EXPECTED_FAILURES:
        if invariant in invariants and applies(case):
            return name
    return None
