"""Reading a sweep folder by hand (file by file, partition values parsed from the path), to
check the analysis package against an independent computation; and the tiny road run the taxi
metrics are checked on by hand."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq


def read_hive_rows(table_dir: Path) -> list[dict]:
    """Every row of every ``part-*.parquet`` below ``table_dir``, with the ``key=value`` folders
    of its path added (integers where they parse)."""
    rows = []
    for f in sorted(Path(table_dir).rglob("part-*.parquet")):
        keys = {}
        for part in f.relative_to(table_dir).parent.parts:
            k, _, v = part.partition("=")
            keys[k] = int(v) if v.lstrip("-").isdigit() else v
        rows += [{**r, **keys} for r in pq.read_table(f).to_pylist()]
    return rows


def run_tiny_road(d: Path, name: str, sweep: str = "") -> Path:
    """Run the hand-checked taxi day in ``d``: a 3 x 2 Manhattan grid (100 m blocks, 10 m/s),
    two taxis at nodes 0 and 5, four trips (one with a 5 s ``max_wait``), ``fcfs``; ``sweep``
    is appended as the scenario's ``[sweep]`` lines. Returns the results folder."""
    from dispatch.run.runner import execute
    from dispatch.scenario.load import load_scenario

    (d / "trips.csv").write_text("t,origin_node,dest_node,max_wait\n0,0,2,\n1,3,5,\n"
                                 "2,4,3,5\n30,1,0,\n")
    (d / "fleet.csv").write_text("vehicle_id,node\n0,0\n1,5\n")
    path = d / f"{name}.toml"
    path.write_text(f'name = "{name}"\nduration = 1000.0\n[world]\nnetwork = "manhattan"\n'
                    'blocks = [3, 2]\nblock = 100.0\nspeed = 10.0\n[fleet]\n'
                    'start = "fleet.csv"\n[tasks]\nsource = "trace"\ntrace = "trips.csv"\n'
                    '[dispatch]\nallocator = "fcfs"\nplanner = "dijkstra"\n' + sweep)
    out = d / "out"
    execute(load_scenario(path).runs(), out)
    return out
