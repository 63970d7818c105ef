"""The soak (``soak/``, ``dispatch soak``): its scenarios are drawn from the seed alone, its
checks catch each kind of broken promise in tables written by a real run and then tampered
with, its shrinker finds the smallest failing case, a slice of it passes (every violation
either none or an expected failure of ``soak.known``), and every shrunk regression case of
``tests/soak_cases/`` runs clean."""

from __future__ import annotations

import json
import math

import pytest

from dispatch.run.cli import main
from soak import invariants, shrink
from soak.generate import Case, draw
from soak.runner import Outcome, run_case
from soak.sweep import soak
from tests.conftest import ROOT

CASES = sorted((ROOT / "tests" / "soak_cases").glob("*/scenario.toml"))


def test_draw_is_the_seed_alone():
    a, b = draw(3, 7), draw(3, 7)
    assert a.text() == b.text() and a.files == b.files
    texts = {draw(3, i).text() for i in range(20)}
    assert len(texts) == 20
    assert {draw(3, i, "voxel").world for i in range(5)} == {"voxel"}
    assert {draw(3, i, "road").world for i in range(5)} == {"road"}


def test_both_worlds_and_the_features_are_drawn():
    docs = [draw(0, i).doc for i in range(300)]
    sections = set().union(*docs)
    assert {"faults", "comms", "reposition", "acceptor", "pricing", "chargers",
            "charging"} <= sections
    keys = {f"{s}.{k}" for d in docs for s, t in d.items() if isinstance(t, dict) for k in t}
    for want in ("fleet.capacity", "fleet.breaks", "fleet.energy", "fleet.sizing",
                 "tasks.max_walk", "tasks.prebook_share", "dispatch.prebook",
                 "dispatch.objective", "dispatch.batch_window", "world.congestion",
                 "world.obstacles", "tasks.service_time", "dispatch.out_of_reach"):
        assert want in keys, want
    allocators = {d["dispatch"]["allocator"] for d in docs}
    assert {"hungarian", "greedy", "fcfs", "random", "auction", "local_hungarian", "rtv",
            "magnnet"} <= allocators
    # Manhattan's street network with the subway, and learned values on the grids
    assert any(d["world"].get("network") == "manhattan_osm" for d in docs)
    assert {d["transit"]["mode_choice"] for d in docs if "transit" in d} == {
        "cheapest", "logit", "train_first"}
    params = [p for d in docs for p in d["dispatch"].get("allocator_params", {}).values()]
    assert {k for p in params for k in p} == {"value", "value_weight", "value_reward"}
    assert any("value" in d.get("reposition", {}).get("demand", {}) for d in docs)


def test_a_case_with_a_value_file_writes_and_reads_it_back(tmp_path):
    from soak.generate import Case
    from learning.value import ZoneValue

    case = next(c for c in (draw(11, i, "road") for i in range(100)) if c.blobs)
    case.write(tmp_path)
    back = Case.read(tmp_path)
    assert back.blobs == case.blobs and back.text() == case.text()
    ZoneValue.load(tmp_path / "value.npz")  # a valid file of the case's network


@pytest.fixture(scope="module")
def pooled_run(tmp_path_factory):
    """A shared-ride run with walks on a small grid: its case and tables."""
    for i in range(200):
        case = draw(5, i, "road")
        d = case.doc
        if d["fleet"].get("capacity", 1) > 1 and "prebook_share" not in d["tasks"] \
                and "booked_at" not in case.files["trips.csv"][0] and "faults" not in d \
                and d["tasks"].get("max_wait") and d["tasks"].get("max_delay") \
                and len(case.files["trips.csv"][1]) > 10:
            folder = tmp_path_factory.mktemp("pooled")
            got = run_case(case, folder)
            if got.status == "ok":
                tables = invariants.read_tables(folder / "out")
                if (tables["tasks"].state == "completed").sum() > 3:
                    return case, tables
    pytest.fail("no pooled case drawn")


def _broken(case, tables) -> set[str]:
    return {name for name, _ in invariants.check(case.doc, tables)}


def test_a_clean_run_breaks_nothing(pooled_run):
    case, tables = pooled_run
    assert invariants.check(case.doc, tables) == []


@pytest.mark.parametrize("tamper, invariant", [
    (lambda t: t["tasks"].__setitem__("picked_up_at", t["tasks"].picked_up_at - 1e4),
     "pickup_not_early"),
    (lambda t: t["tasks"].__setitem__("max_wait", 0.0), "wait_limit"),
    (lambda t: t["tasks"].__setitem__("max_delay", -1.0), "delay_limit"),
    (lambda t: t["vehicles"].__setitem__("capacity", 0), "capacity"),
    (lambda t: t["tasks"].__setitem__("walk_to_board_m", 1e6), "walk_limit"),
    (lambda t: t["vehicles"].__setitem__("shift_end", -1.0), "shift"),
    (lambda t: t["summary"].__setitem__("tasks_completed", -1), "summary_counts"),
    (lambda t: t["vehicles"].__setitem__("speed", 1e-3), None),  # (roads read the world's)
])
def test_each_check_catches_its_promise_broken(pooled_run, tamper, invariant):
    case, tables = pooled_run
    tampered = {k: v.copy() for k, v in tables.items()}
    tamper(tampered)
    if invariant is None:
        assert invariants.check(case.doc, tampered) == []
    else:
        assert invariant in _broken(case, tampered)


def test_checks_of_events(pooled_run):
    case, tables = pooled_run
    ev = tables["events"].copy()
    # a second terminal event; a vehicle moved faster than the streets allow; an assign
    # after the task closed; a break with riders aboard
    done = tables["tasks"][tables["tasks"].state == "completed"].iloc[0]
    extra = ev[(ev.event == "complete") & (ev.task_id == done.task_id)].copy()
    late = extra.assign(event="assign", t=done.closed_at + 10.0)
    first = ev[(ev.event == "pickup") & (ev.task_id == done.task_id)].iloc[0]
    on_break = ev.iloc[[ev.index.get_loc(first.name)]].assign(
        event="break_start", task_id=-1, t=first.t + 1e-3)
    jump = on_break.assign(event="idle", t=first.t + 2e-3, x=first.x + 1e5)
    import pandas as pd
    t = dict(tables, events=pd.concat([ev, extra, late, on_break, jump], ignore_index=True))
    got = _broken(case, t)
    assert {"one_terminal_state", "assign_open_only", "break_empty", "reachable"} <= got


def test_energy_checks():
    doc = {"fleet": {"energy": {"battery_kwh": 10.0, "soc0": 0.5}}}
    import pandas as pd
    veh = pd.DataFrame({"agent_id": [0], "kwh_charged": [1.0], "kwh_drawn": [2.0],
                        "soc_end": [0.4], "soc_min": [-0.01]})
    tables = {"summary": pd.DataFrame({"kwh_drawn": [2.0], "kwh_charged": [1.0]}),
              "vehicles": veh, "soc": pd.DataFrame({"t": [0.0], "agent_id": [0], "soc": [0.5]})}
    ev = pd.DataFrame({"event": ["idle"], "agent_id": [0]})
    ok = list(invariants._energy(doc, {}, tables, None, ev, veh))
    assert ok == []
    veh2 = veh.assign(soc_end=0.41)
    assert len(list(invariants._energy(doc, {}, tables, None, ev, veh2))) == 1
    assert len(list(invariants._soc(doc, {}, tables, None, ev, veh))) == 1  # no stranding
    stranded = pd.DataFrame({"event": ["stranded"], "agent_id": [0]})
    assert list(invariants._soc(doc, {}, tables, None, stranded, veh)) == []


def test_same_tables_ignores_wall_clock_only(pooled_run):
    _, tables = pooled_run
    other = {k: v.copy() for k, v in tables.items()}
    other["summary"]["alloc_seconds"] = 99.0
    assert invariants.same_tables(tables, other) == []
    other["tasks"].loc[0, "picked_up_at"] = math.pi
    assert invariants.same_tables(tables, other) == ["tasks"]


def test_shrink_finds_the_smallest_failing_case(tmp_path, monkeypatch):
    # a stand-in for a run: it "fails" while the demand holds trip (13 -> 34) and walks are on
    def fake(case: Case, directory, **kw) -> Outcome:
        rows = case.files["trips.csv"][1]
        bad = "max_walk" in case.doc["tasks"] and any(r[1] == 13 and r[2] == 34 for r in rows)
        return Outcome("violations", [("wait_limit", "x")]) if bad else Outcome("ok")

    monkeypatch.setattr(shrink, "run_case", fake)
    case = draw(0, 0, "road")
    case.doc["tasks"]["max_walk"] = 300.0
    case.doc["comms"] = {"range": 100.0}
    header, rows = case.files["trips.csv"]
    rows.insert(len(rows) // 2, [50.0, 13, 34] + [None] * (len(header) - 3))
    small = shrink.shrink(case, fake(case, None), tmp_path)
    assert [r[1:3] for r in small.files["trips.csv"][1]] == [[13, 34]]
    assert small.doc["tasks"] == {"source": "trace", "trace": "trips.csv", "max_walk": 300.0}
    assert "comms" not in small.doc and small.files["trips.csv"][0] == ["t", "origin_node",
                                                                         "dest_node"]
    path = shrink.write_regression(small, fake(small, None), tmp_path / "cases", "walk")
    assert path.read_text().startswith("# soak regression: wait_limit")
    assert Case.read(path.parent).doc == small.doc


@pytest.mark.parametrize("path", CASES, ids=[p.parent.name for p in CASES])
def test_regression_case(path, tmp_path):
    case = Case.read(path.parent)
    got = run_case(case, tmp_path / "run")
    head = path.read_text(encoding="utf-8").split("\nname", 1)[0]
    if "now refused" in head:  # a combination that cannot work: one line naming the key
        assert got.status == "refused" and "dispatch.reassign" in got.message, got.message
    else:
        assert got.status == "ok", (got.status, got.message, got.violations[:3])


def test_ci_slice(tmp_path):
    """A few dozen short runs over both worlds: no crash, no hang, and no violation that
    ``soak.known`` does not name."""
    tally = soak(30, 2026, tmp_path, limit=60.0, twice_every=5)
    assert tally.runs == 30
    assert tally.unexplained == 0, tally.failures
    assert tally.status["ok"] + tally.status["violations"] >= 20  # most are valid and ran
    assert tally.worlds["road"] and tally.worlds["voxel"]


def test_command_table_and_resume(tmp_path, capsys):
    out = tmp_path / "soak"
    code = main(["soak", "--runs", "3", "--seed", "7", "--out", str(out)])
    text = capsys.readouterr().out
    lines = [line for line in text.splitlines() if line.strip()]  # (the bar leaves a blank)
    assert code in (0, 1)
    assert lines[0].startswith("3 runs (")
    assert all(len(line) <= 80 for line in lines if "│" in line or "┃" in line)
    assert "wait_limit" in text and "hang" in text
    rows = (out / "results.jsonl").read_text().splitlines()
    assert len(rows) == 3 and {json.loads(r)["run"] for r in rows} == {"7_0", "7_1", "7_2"}
    assert (out / "runs" / "7_0" / "scenario.toml").exists()
    # cut the last line as a kill would: the rerun runs that one again, the others are read
    (out / "results.jsonl").write_text("\n".join(rows[:2]) + "\n" + rows[2][:10])
    main(["soak", "--runs", "3", "--seed", "7", "--out", str(out)])
    again = [line for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert again[0] == lines[0]


def test_command_refuses_bad_options(capsys):
    assert main(["soak", "--runs", "0"]) == 2
    assert "--runs must be >= 1" in capsys.readouterr().err
