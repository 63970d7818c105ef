"""With reservation-based execution a vehicle may be held up on the way (a detour around
other vehicles' reservations): a request whose vehicle is not at the pickup by its deadline
expires then, never picked up late, and the vehicle is idle from there on."""

from __future__ import annotations

from soak import invariants
from soak.generate import Case
from soak.runner import run_case
from tests.conftest import ROOT

CASE = ROOT / "tests" / "soak_cases" / "reservation_late_pickup"


def test_held_up_vehicle_gives_the_request_up_at_its_deadline(tmp_path):
    case = Case.read(CASE)
    got = run_case(case, tmp_path / "run")
    assert got.status == "ok", got.violations[:3]
    tables = invariants.read_tables(tmp_path / "run" / "out")
    tasks, ev = tables["tasks"], tables["events"]
    up = tasks[tasks.picked_up_at.notna()]
    assert (up.picked_up_at <= up.released_at + up.max_wait + 1e-9).all()
    # the requests the decision gave out but the vehicle reached too late (these two were
    # picked up 0.33 s and 0.44 s late before): assigned once, closed expired at the deadline
    given_up = tasks[tasks.task_id.isin([4, 144])]
    assert (given_up.state == "expired").all()
    assert (given_up.closed_at == given_up.released_at + given_up.max_wait).all()
    for tid in (4, 144):
        mine = ev[ev.task_id == tid]
        assert mine.event.tolist() == ["release", "assign", "depart", *["move"] * (
            (mine.event == "move").sum()), "expire"], mine.event.tolist()
        # its vehicle is idle at that instant and takes the next request from there
        agent = mine[mine.event == "assign"].agent_id.iloc[0]
        at = mine[mine.event == "expire"].t.iloc[0]
        after = ev[(ev.agent_id == agent) & (ev.t == at)].event.tolist()
        assert "idle" in after
    v = tables["vehicles"]
    assert (v.busy_seconds <= float(tables["summary"].sim_time.iloc[0]) + 1e-9).all()
