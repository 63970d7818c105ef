"""A road run's network stored beside its results (dispatch/output/space_files.py) and read back by
analysis.network without dispatch: once per folder, the same nodes, edges and free-flow times
as the network the run drove on; a folder without it gives no network (and says why)."""

from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest

from analysis.io import open_results
from analysis.network import METADATA_KEY, direct_seconds, road_network
from tests.analysis.helpers import run_tiny_road


@pytest.fixture(scope="module")
def road_folder(tmp_path_factory):
    return run_tiny_road(tmp_path_factory.mktemp("net"), "net", '[sweep]\nseed = [0, 1]\n')


def test_stored_once_and_equal_to_the_network_driven(road_folder):
    from dispatch.space.roads import manhattan

    stored = sorted((road_folder / "_spaces").iterdir())
    assert len(stored) == 1 and stored[0].name.startswith("road-")  # two runs, one network
    assert sorted(p.name for p in stored[0].iterdir()) == ["edges.parquet", "nodes.parquet"]
    res = open_results(road_folder)
    run_ids = list(res.summary["run_id"])
    assert len(run_ids) == 2
    metas = [res.metadata(r, t) for r in run_ids for t in ("tasks", "summary", "vehicles")]
    assert {m[METADATA_KEY] for m in metas} == {f"_spaces/{stored[0].name}"}

    net = road_network(metas[0], [road_folder])
    truth = manhattan(3, 2, 100.0, 10.0)
    assert net.name == "manhattan"
    assert np.array_equal(net.xy, truth.xy[:, :2])
    t = truth.time.tocoo()
    assert np.array_equal(net.edges, np.column_stack([t.row, t.col]))
    nodes = np.arange(truth.n)
    o, d = np.repeat(nodes, truth.n), np.tile(nodes, truth.n)
    assert np.array_equal(net.free_flow_seconds(o, d), truth.distances_from(nodes).ravel())
    assert np.array_equal(net.nodes_at(truth.xy[:, :2]), nodes)
    direct = direct_seconds(res.table("tasks"), net)
    assert np.isfinite(direct).all() and (direct > 0).any()


def test_a_voxel_run_keeps_no_space_files(tmp_path):
    from dispatch.run.runner import execute
    from dispatch.scenario.load import load_scenario
    from tests.conftest import write_scenario

    out = tmp_path / "out"
    execute(load_scenario(write_scenario(tmp_path)).runs(), out)
    assert not (out / "_spaces").exists()
    res = open_results(out)
    assert METADATA_KEY not in res.metadata(res.summary["run_id"].iloc[0], "tasks")


def test_a_folder_without_its_network_has_none(road_folder, tmp_path, caplog):
    copy = tmp_path / "copy"
    shutil.copytree(road_folder, copy, ignore=shutil.ignore_patterns("_spaces"))
    res = open_results(copy)
    meta = res.metadata(res.summary["run_id"].iloc[0], "tasks")
    with caplog.at_level(logging.INFO, logger="analysis.network"):
        assert road_network(meta, [copy]) is None
    assert "not found" in caplog.text
    older = {k: v for k, v in meta.items() if k != METADATA_KEY}  # written before the files
    with caplog.at_level(logging.INFO, logger="analysis.network"):
        assert road_network(older, [road_folder]) is None
    assert "before networks were stored" in caplog.text


def test_a_killed_writers_temporary_file_is_removed_a_live_ones_kept(tmp_path):
    """A run killed while it wrote ``_spaces/.../nodes.parquet`` leaves ``.nodes.parquet.tmp-
    <pid>``; the next run that stores the space removes it (its process is gone) and keeps a
    temporary file whose writer still runs."""
    import os
    import subprocess
    import sys

    from dispatch.output.space_files import store
    from dispatch.space.roads import manhattan

    space = manhattan(3, 2, 100.0, 10.0)
    rel = store(tmp_path, space)["dispatch.output.space_files"]
    folder = tmp_path / rel
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    stale = folder / f".nodes.parquet.tmp-{int(dead.stdout)}"
    live = folder / f".edges.parquet.tmp-{os.getppid()}"
    stale.write_bytes(b"PAR1")
    live.write_bytes(b"PAR1")
    store(tmp_path, space)
    assert not stale.exists() and live.exists()
    assert sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")) == [
        "edges.parquet", "nodes.parquet"]
