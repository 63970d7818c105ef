"""The sweep's dimensions declared once (:mod:`dispatch.config.runkeys`): the sweep lists, a run's
keys,
partition, run id, digest and file metadata all follow the one tuple; ``batch_window`` is a run
key like ``n_agents``; the CLI's trip table shows 95 % intervals over seeds; ``dispatch sweep``
takes ``--duration``."""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq

from dispatch.config import runkeys
from dispatch.config.sweep import SweepConfig
from dispatch.output.parquet import SCHEMAS
from dispatch.output.printed import print_tables
from dispatch.run import cli
from dispatch.run.resume import _base_settings, run_digest
from dispatch.scenario.load import load_scenario
from tests.analysis.helpers import run_tiny_road

ROOT = Path(__file__).resolve().parents[2]


def test_one_declaration_drives_the_sweep_and_the_run():
    names = runkeys.key_names()
    assert names == ["scenario", "allocator", "planner", "reposition", "batch_window",
                     "n_agents", "seed"]
    swept = {k.sweep for k in runkeys.RUN_KEYS if k.sweep}
    assert swept == {f.name for f in dataclasses.fields(SweepConfig)}  # a list per key
    assert all(k in SCHEMAS["summary"].names for k in names)  # a summary column per key
    sc = load_scenario(ROOT / "scenarios" / "chicago_taxi.toml")
    for spec in sc.runs():
        assert list(spec.keys) == names
        # it sweeps batch_window and declares no repositioning
        assert list(spec.partition) == [n for n in names if n != "reposition"]
        for k in runkeys.RUN_KEYS:  # every swept value comes from its [sweep] list
            if k.sweep and getattr(sc.sweep, k.sweep):
                assert spec.keys[k.name] in getattr(sc.sweep, k.sweep)
    assert runkeys.point_settings()["dispatch"] == ("allocator", "planner", "batch_window")
    assert runkeys.instance_keys() == tuple(n for n in names if n != "allocator")


def test_run_ids_stay_distinct_per_batch_window_and_unchanged_without_one():
    sc = load_scenario(ROOT / "scenarios" / "chicago_taxi.toml")
    specs = sc.runs()
    assert len({s.run_id for s in specs}) == len(specs)
    assert {s.batch_window for s in specs} == {0.0, 30.0}
    assert {s.run_id.split("__")[3] for s in specs} == {"bw0", "bw30"}
    assert {s.scenario.name for s in specs} == {"chicago_taxi"}  # the name is kept
    plain = load_scenario(ROOT / "scenarios" / "manhattan.toml").runs()[0]
    assert plain.run_id == "manhattan__fcfs__dijkstra__n50__s0"  # as before the run key
    assert list(plain.partition) == ["scenario", "allocator", "planner", "n_agents", "seed"]


def _old_digest(spec) -> str:
    """run_digest as versions before the declaration computed it (markers must stay valid)."""
    doc = _base_settings(spec.scenario.text)
    obj = {"base": doc, "run_id": spec.run_id, "seed": spec.seed, "agents": spec.agents,
           "allocator": spec.allocator, "planner": spec.planner,
           "reposition": spec.reposition,
           "batch_window": float(spec.scenario.dispatch.batch_window)}
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def test_run_digests_of_scenarios_without_a_swept_window_are_unchanged():
    for name in ("manhattan.toml", "paper_static.toml"):
        for spec in load_scenario(ROOT / "scenarios" / name).runs()[:3]:
            assert run_digest(spec) == _old_digest(spec)


def test_files_list_their_run_keys_and_the_summary_its_window(tmp_path):
    out = run_tiny_road(tmp_path, "tiny", "[sweep]\nbatch_window = [0.0, 2.5]\n")
    files = sorted((out / "summary").rglob("part-0.parquet"))
    assert [f.relative_to(out / "summary").parts[3] for f in files] == ["batch_window=0",
                                                                        "batch_window=2.5"]
    for f in sorted(out.rglob("part-0.parquet")):
        meta = pq.read_schema(f).metadata
        assert json.loads(meta[b"dispatch.run_keys"]) == runkeys.key_names()
    (tmp_path / "plain").mkdir()
    plain = run_tiny_road(tmp_path / "plain", "plain")
    row = pq.read_table(next((plain / "summary").rglob("part-0.parquet"))).to_pylist()[0]
    assert row["batch_window"] == 0.0  # a column of every summary, a level only when swept
    assert not any("batch_window=" in str(p) for p in plain.rglob("*"))


def _trip_summary(alloc: str, seed: int, served: int) -> dict:
    return {"scenario": "c", "allocator": alloc, "planner": "dijkstra", "n_agents": 10,
            "seed": seed, "space": "road", "batch_window": 0.0, "n_tasks": 100,
            "tasks_completed": served, "tasks_rejected": 100 - served, "tasks_expired": 0,
            "tasks_unreachable": 0, "tasks_cut_off": 0, "tasks_failed": 0,
            "wait_time_mean": 60.0 + seed, "empty_distance": 1000.0, "distance": 4000.0,
            "alloc_seconds": 0.5, "total_cost": 1.0, "decisions": 10,
            "conflict_free_rate": 1.0, "first_decision_seconds": 0.01}


def _render(summaries) -> str:
    from rich.console import Console

    buf = io.StringIO()
    print_tables(summaries, Console(file=buf, width=80, force_terminal=False))
    return buf.getvalue()


def test_trip_table_shows_95_percent_intervals_over_seeds():
    """Three seeds: under each row the half-width of the 95 % Student-t interval (served 80,
    85, 90 %: mean 85 %, sd 5, t(0.975, 2) = 4.303: 12.4 %); one seed: no interval row."""
    rows = [_trip_summary(a, s, 80 + 5 * s) for a in ("fcfs", "hungarian") for s in (0, 1, 2)]
    text = _render(rows)
    assert "95 % interval" in " ".join(text.split())  # (the title wraps at 80 columns)
    lines = text.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["hungarian"])
    assert lines[i].split()[3] == "85.0%"
    assert lines[i + 1].split()[:3] == ["±0", "±12.4%", "±12.4%"]  # trips, served, rejected
    assert lines[i + 1].split()[4] == "±2.5"  # wait 60, 61, 62 s
    assert max(map(len, lines)) <= 80 and "…" not in text
    one = _render([_trip_summary(a, 0, 80) for a in ("fcfs", "hungarian")])
    assert "±" not in one and "95 % interval" not in one


def test_sweep_takes_duration(tmp_path, capsys):
    (tmp_path / "trips.csv").write_text("t,origin_node,dest_node\n0,0,2\n50,3,5\n")
    (tmp_path / "fleet.csv").write_text("vehicle_id,node\n0,0\n")
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\nduration = 1000.0\n[world]\nnetwork = "manhattan"\n'
                    'blocks = [3, 2]\nblock = 100.0\nspeed = 10.0\n[fleet]\n'
                    'start = "fleet.csv"\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                    '[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\n'
                    '[sweep]\nseed = [0, 1]\n')
    assert cli.main(["sweep", str(path), "--duration", "20", "--workers", "1",
                     "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    files = sorted((tmp_path / "out" / "summary").rglob("part-0.parquet"))
    assert len(files) == 2
    for f in files:
        assert pq.read_table(f).column("sim_time").to_pylist() == [20.0]
        text = pq.read_schema(f).metadata[b"dispatch.scenario"].decode()
        assert "duration = 20.0  # dispatch run --duration" in text
    assert cli.main(["sweep", str(path), "--duration", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--duration" in capsys.readouterr().err


def _as_an_older_version_wrote_it(out: Path) -> None:
    """Rewrite the files of ``out`` as versions before the batch window was a run key wrote
    them: no ``batch_window`` column, no ``dispatch.run_keys``; markers list the new sizes."""
    for f in out.rglob("part-0.parquet"):
        t = pq.read_table(f)
        if "batch_window" in t.column_names:
            t = t.drop_columns(["batch_window"])
        meta = {k: v for k, v in t.schema.metadata.items() if k != b"dispatch.run_keys"}
        pq.write_table(t.replace_schema_metadata(meta), f)
    for m in (out / "_runs").rglob("done.json"):
        marker = json.loads(m.read_text())
        marker["files"] = {rel: (out / rel).stat().st_size for rel in marker["files"]}
        m.write_text(json.dumps(marker))


def test_a_sweep_over_an_older_folder_of_variants_resumes_it(tmp_path):
    """A folder whose windows were scenario variants (``tiny-immediate``, ``tiny-batch30s``):
    a sweep takes its complete runs as its own (skipped, read as scenario ``tiny`` with their
    window), runs only what the sweep added (a seed), and the folder reads once per run, every
    table's rows with their run's window; ``force`` redoes them in the new layout and the older
    copies go."""
    from analysis.io import open_results
    from dispatch.run.resume import holds_results, legacy_variant
    from dispatch.run.runner import execute, sweep

    out = run_tiny_road(tmp_path, "tiny", "[sweep]\nbatch_window = [0.0, 30.0]\n")
    for f in list(out.iterdir()):  # keep only the older layout, written below
        shutil.rmtree(f)
    specs = load_scenario(tmp_path / "tiny.toml").runs()
    old = [legacy_variant(s) for s in specs]
    assert [o.run_id for o in old] == ["tiny-immediate__fcfs__dijkstra__n2__s0",
                                       "tiny-batch30s__fcfs__dijkstra__n2__s0"]
    execute(old, out)
    _as_an_older_version_wrote_it(out)
    assert all(holds_results(out, s) for s in specs)  # dispatch run refuses without --force
    outcomes = sweep(specs, out, workers=1)
    assert [o.status for o in outcomes] == ["skipped", "skipped"]
    assert [(o.summary["scenario"], o.summary["batch_window"]) for o in outcomes] == [
        ("tiny", 0.0), ("tiny", 30.0)]
    (tmp_path / "tiny.toml").write_text((tmp_path / "tiny.toml").read_text()
                                        .replace("[sweep]\n", "[sweep]\nseed = [0, 1]\n"))
    more = load_scenario(tmp_path / "tiny.toml").runs()
    assert [o.status for o in sweep(more, out, workers=1)] == ["skipped", "done"] * 2
    res = open_results(out)
    s = res.summary
    assert len(s) == 4 and set(s["scenario"]) == {"tiny"}
    assert sorted(zip(s["batch_window"], s["seed"])) == [(0.0, 0), (0.0, 1), (30.0, 0),
                                                         (30.0, 1)]
    tasks = res.table("tasks")
    by_run = tasks.groupby("run_id")["batch_window"].unique()
    assert {r: list(v) for r, v in by_run.items()} == dict(zip(s["run_id"],
                                                               ([w] for w in s["batch_window"])))
    assert [o.status for o in sweep(more, out, workers=1, overwrite=True)] == ["done"] * 4
    assert not any("-batch30s" in str(p) or "-immediate" in str(p) for p in out.rglob("*.parquet"))
    assert len(open_results(out).summary) == 4
