"""Compiled functions run as the plain Python they are written in while a process is young
(:mod:`dispatch._compiled`), and a road planner's fields come from scipy's Dijkstra meanwhile:
the same results, bit for bit, as the compiled code, kernel by kernel and run by run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dispatch import _compiled
from dispatch.run.runner import execute
from dispatch.scenario.load import load_scenario
from dispatch.space.roads import RoadNetwork, load_network, manhattan
from planners import _road_fast
from planners.road import RoadPlanner
from tests.dispatch.test_determinism import read_run
from tests.dispatch.test_one_request import assert_same_tables

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def mode():
    """:func:`dispatch._compiled.set_mode`, back to ``"auto"`` after the test."""
    yield _compiled.set_mode
    _compiled.set_mode("auto")


def random_network(seed: int) -> RoadNetwork:
    """A random road network: nodes at random points, each joined both ways to its nearest
    neighbours, edge seconds its metres over a speed drawn per edge, either a float (few exact
    ties) or whole seconds (many equally fast paths: where searches must break ties alike)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 160))
    xy = rng.random((n, 2)) * rng.choice([500.0, 3000.0, 20000.0])
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    near = np.argsort(d, axis=1)[:, 1:int(rng.integers(2, 6))]
    u = np.repeat(np.arange(n), near.shape[1])
    v = near.ravel()
    u, v = np.concatenate([u, v]), np.concatenate([v, u])
    keep = np.unique(u * n + v)
    u, v = keep // n, keep % n
    metres = d[u, v]
    seconds = metres / rng.uniform(3.0, 30.0, u.size)
    if seed % 2:
        seconds = np.maximum(np.round(seconds / 20.0), 1.0) * 20.0
    return RoadNetwork.from_edges(f"random-{seed}", xy, np.arange(n), u, v, seconds=seconds,
                                  metres=metres)


NETWORKS = [("grid", lambda: manhattan(9, 7, block=173.0, speed=7.3))] + [
    (f"random-{s}", lambda s=s: random_network(s)) for s in range(8)]


def _both_modes(call):
    """``(call() with the kernels as plain Python, call() compiled)``, back to ``"auto"``."""
    _compiled.set_mode("python")
    try:
        plain = call()
        _compiled.set_mode("compiled")
        return plain, call()
    finally:
        _compiled.set_mode("auto")


@pytest.mark.parametrize("which", [name for name, _ in NETWORKS])
def test_searches_as_plain_python_equal_the_compiled_ones(which):
    """A* paths, paths walked down a field, and complete fields (the planner's scipy twin against
    the compiled Dijkstra), to and from nodes, on grids full of equally fast paths and on random
    networks, compared exactly."""
    net = dict(NETWORKS)[which]()
    planner = RoadPlanner(net)
    rng = np.random.default_rng(7)
    nodes = rng.integers(0, net.n, 12)
    for to in (True, False):
        plain, compiled = _both_modes(lambda: planner._dijkstra(nodes, to=to))
        for a, b in zip(plain, compiled, strict=True):
            assert np.array_equal(a, b)  # bit for bit (no tolerance)
            assert not a.flags.writeable
    _, hk, hn, path = planner._scratch
    scratch = planner._astar
    for k in range(60):
        s, g = (int(x) for x in rng.integers(0, net.n, 2))
        args = (*planner._graph, planner._xy, planner._inv_speed, s, g)
        n_plain = _road_fast.astar.py_func(*args, *scratch, hk, hn, path)
        plain_path = path[:n_plain].tolist()
        assert np.isinf(scratch[0]).all()  # the scratch is left as found
        n_comp = _road_fast.astar.compiled(*args, *scratch, hk, hn, path)
        assert plain_path == path[:n_comp].tolist()
        field = compiled[k % len(compiled)] if k % 2 else planner._dijkstra([g], to=True)[0]
        goal = int(nodes[k % len(nodes)]) if k % 2 else g
        if k % 2 and not np.isfinite(field).all():
            continue
        d_args = (*planner._graph, field, planner._order, s, goal, path)
        n_plain = _road_fast.descend.py_func(*d_args)
        plain_path = path[:max(n_plain, 0)].tolist()
        assert n_plain == _road_fast.descend.compiled(*d_args)
        assert plain_path == path[:max(n_plain, 0)].tolist()


def test_leg_kernels_as_plain_python_equal_the_compiled_ones():
    """A leg's sums along random paths (some not paths: then ``ok`` is False in both) and where
    driving vehicles are at random times, plain and compiled, compared exactly."""
    net = random_network(3)
    t = net.time
    csr = (t.indptr.copy(), t.indices.copy(), t.data.copy(), net.length.data.copy())
    rng = np.random.default_rng(5)
    for _ in range(50):
        route = net.route(int(rng.integers(net.n)), int(rng.integers(net.n)))
        nodes = route.nodes.astype(np.int64) if rng.random() < 0.8 else rng.integers(
            -1, net.n + 1, int(rng.integers(2, 6)))
        t0, m0 = float(rng.random() * 9), float(rng.random() * 90)
        plain = _compiled.leg_sums.py_func(*csr, nodes, t0, m0)
        comp = _compiled.leg_sums.compiled(*csr, nodes, t0, m0)
        assert bool(plain[2]) == bool(comp[2])
        if plain[2]:
            assert np.array_equal(plain[0], comp[0]) and np.array_equal(plain[1], comp[1])
    rows, width = 30, 9
    length = rng.integers(1, width + 1, rows)
    times = np.cumsum(rng.choice([0.0, 0.5, 3.25, 7.0], (rows, width)), axis=1)
    times[rng.random((rows, width)) < 0.2] += 0.1
    times = np.sort(times, axis=1)
    nodes = rng.integers(0, 50, (rows, width))
    prev = rng.integers(-1, 50, rows)
    for now in (0.0, 0.5, 3.25, 5.0, 11.0, 40.0):
        q = int(rng.integers(1, rows))
        which = np.sort(rng.choice(rows, q, replace=False))
        starts = rng.choice([0.0, 0.5, 1.0, 2.75], q)
        out_k = rng.permutation(q)
        out_i = rng.permutation(q)
        got = []
        for fn in (_compiled.legs_at.py_func, _compiled.legs_at.compiled):
            node, rem, on = np.full(q, -7), np.full(q, -1.0), np.zeros(q, dtype=bool)
            fn(times, nodes, length, prev, which, now, starts, out_k, node, rem, out_i, on)
            got.append((node.tolist(), rem.tolist(), on.tolist()))
        assert got[0] == got[1]


def run_tables(name: str, out: Path, kernels: str, duration: float | None) -> tuple[dict, float]:
    """The tables of scenario ``name``'s first run (its first ``duration`` simulated seconds,
    or all of it) with the kernels run as ``kernels``, and the seconds spent in plain ones."""
    overrides = [] if duration is None else [("duration", str(duration), "test")]
    scenario = load_scenario(ROOT / "scenarios" / name, ignore_limits=True,
                             overrides=overrides)
    _compiled.set_mode(kernels)
    try:
        execute(scenario.runs()[:1], out)
        spent = _compiled._state["spent"]
    finally:
        _compiled.set_mode("auto")
    return read_run(out), spent


@pytest.mark.parametrize("name,duration", [
    ("manhattan.toml", None), ("manhattan_hotspot.toml", None), ("manhattan_faults.toml", 3600.0),
    ("nyc_manhattan_pooled.toml", 600.0)])
def test_a_run_with_plain_kernels_equals_a_compiled_one(tmp_path, name, duration):
    """Shipped road scenarios, whole or their first minutes (on the small grid every search is
    a plain one: A*, fields, legs), run with plain and with compiled kernels: the same tables,
    bit for bit."""
    plain, spent = run_tables(name, tmp_path / "plain", "python", duration)
    compiled, none = run_tables(name, tmp_path / "compiled", "compiled", duration)
    assert spent > 0 and none == 0  # the plain run ran plain code, the compiled one none
    assert_same_tables(plain, compiled)


def test_a_young_process_runs_plain_then_compiles(tmp_path):
    """In a new process the kernels run as plain Python (numba not imported) until
    ``INTERPRET_SECONDS`` have been spent; the next call compiles (numba imported)."""
    code = """
import sys
import numpy as np
from dispatch import _compiled
from dispatch.space.roads import manhattan
net = manhattan(3, 3)
e = net._edges
args = (*e._leg_csr, np.array([0, 1, 2]), 0.0, 0.0)
assert _compiled.interpreting()
first = _compiled.leg_sums(*args)
assert "numba" not in sys.modules and _compiled.leg_sums._compiled is None
_compiled.charge(_compiled.INTERPRET_SECONDS)
assert not _compiled.interpreting()
second = _compiled.leg_sums(*args)
assert "numba" in sys.modules and _compiled.leg_sums._compiled is not None
assert first[0].tolist() == second[0].tolist() == [0.0, 20.0, 40.0]
print("ok")
"""
    proc = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True,
                          cwd=tmp_path, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_set_mode_refuses_an_unknown_mode(mode):
    with pytest.raises(ValueError, match="kernel mode"):
        mode("fast")
    mode("python")
    assert _compiled.interpreting()
    mode("compiled")
    assert not _compiled.interpreting()


def test_chicago_fields_from_scipy_equal_the_compiled_search():
    """On a city's network (11,180 nodes, float times) the planner's plain fields equal the
    compiled Dijkstra's, bit for bit."""
    net = load_network("chicago", base=ROOT)
    planner = RoadPlanner.__new__(RoadPlanner)  # only the search: no hierarchy built
    planner.space = net
    t = net.time
    tt = t.T.tocsr()
    tt.sort_indices()
    planner._graph_t = (tt.indptr.astype(np.int64), tt.indices.astype(np.int64),
                        np.ascontiguousarray(tt.data, dtype=np.float64))
    planner._graph = (t.indptr.astype(np.int64), t.indices.astype(np.int64),
                      np.ascontiguousarray(t.data, dtype=np.float64))
    planner._scratch = (np.zeros(net.n, dtype=np.bool_), np.empty(t.nnz + 1),
                        np.empty(t.nnz + 1, dtype=np.int64), np.empty(net.n, dtype=np.int64))
    nodes = np.random.default_rng(2).integers(0, net.n, 6)
    for to in (True, False):
        plain, compiled = _both_modes(lambda: planner._dijkstra(nodes, to=to))
        for a, b in zip(plain, compiled, strict=True):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(40))
def test_largest_component_without_scipys_graph_module_where_connected(seed):
    """Random directed graphs, strongly connected or not (components of equal size among them):
    the nodes kept are scipy's largest strongly connected component (of equal ones, the lowest
    label), and the breadth-first check says "strongly connected" exactly where scipy counts
    one component."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from dispatch.space.road_edges import largest_component, strongly_connected

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    m = int(rng.integers(0, 4 * n))
    u, v = rng.integers(0, n, m), rng.integers(0, n, m)
    if seed % 3 == 0:  # a ring through every node: strongly connected
        u = np.concatenate([u, np.arange(n)])
        v = np.concatenate([v, (np.arange(n) + 1) % n])
    time = csr_matrix((rng.uniform(1, 9, u.size), (u, v)), shape=(n, n))
    count, labels = connected_components(time, directed=True, connection="strong")
    want = labels == int(np.argmax(np.bincount(labels, minlength=1)))
    assert strongly_connected(time) == (count == 1)
    assert largest_component(time).tolist() == want.tolist()
