"""The common workload of benchmarks/peers.py: what every simulator is fed must be what it says."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import peers_sumo
import peers_workload as pw


def test_generate_is_seeded_and_uniform():
    w, t, o, d, s = pw.generate(20_000, 300, 2.0, seed=5)
    again = pw.generate(20_000, 300, 2.0, seed=5)
    for a, b in zip((t, o, d, s), again[1:]):
        assert np.array_equal(a, b)
    assert not np.array_equal(t, pw.generate(20_000, 300, 2.0, seed=6)[1])
    assert w.requests == t.size == 20_000 and s.size == 300 and w.nodes == 400
    assert np.all(np.diff(t) >= 0) and t[0] >= 0 and t[-1] < 7200
    assert np.all(o != d) and o.min() >= 0 and max(o.max(), d.max()) < 400
    # uniform over the intersections: every node, each count within 5 sigma of 50
    counts = np.bincount(o, minlength=400)
    assert abs(counts - 50).max() < 5 * np.sqrt(50)
    # a Poisson process: inter-arrival times exponential with mean horizon / count
    gaps = np.diff(t)
    assert gaps.mean() == pytest.approx(7200 / 20_000, rel=0.03)
    assert gaps.std() == pytest.approx(gaps.mean(), rel=0.05)


def test_write_read_round_trip_and_prefix(tmp_path):
    w, t, o, d, s = pw.generate(500, 20, 1.0, seed=1, drain=100.0)
    pw.write(tmp_path, w, t, o, d, s)
    w2, t2, o2, d2, s2 = pw.read(tmp_path)
    assert w2 == w and w.end == w.horizon + 100.0
    assert np.allclose(t2, t, atol=5e-4) and np.array_equal(o2, o) and np.array_equal(d2, d)
    assert np.array_equal(s2, s)
    cut, tp, op, dp = pw.prefix(w, t, o, d, 100, drain=50.0)
    assert cut.requests == 100 and cut.vehicles == 20 and np.array_equal(op, o[:100])
    assert np.array_equal(tp, t[:100]) and np.array_equal(dp, d[:100])
    assert cut.horizon == np.ceil(t[99]) and cut.end == cut.horizon + 50.0


def test_metrics_by_hand():
    nan = float("nan")
    m = pw.metrics(np.array([0.0, 10.0, 20.0, 30.0]), np.array([5.0, 40.0, nan, 31.0]),
                   np.array([50.0, nan, nan, 60.0]), 12_345.0)
    assert m["requests"] == 4 and m["served"] == 2 and m["picked"] == 3
    assert m["wait_mean"] == pytest.approx((5 + 30 + 1) / 3)
    assert m["wait_p90"] == pytest.approx(np.percentile([5, 30, 1], 90))
    assert m["vehicle_km"] == pytest.approx(12.345)


def test_sumo_stops_lie_on_a_shortest_path():
    """The person's first edge and drop-off edge are the ends of one monotone shortest path,
    so neither leg needs a detour (checked against Manhattan distances on every pair)."""
    w = pw.generate(1, 1, 1.0, seed=0, columns=6, rows=5)[0]
    c, r = w.node_xy(np.arange(w.nodes))
    dist = np.abs(c[:, None] - c[None, :]) + np.abs(r[:, None] - r[None, :])
    for o in range(w.nodes):
        for d in range(w.nodes):
            if o == d:
                continue
            (a, b), (x, y) = peers_sumo.first_last_edges(w, o, d)
            assert a == o and y == d and dist[a, b] == 1 and dist[x, y] == 1
            assert dist[b, d] == dist[o, d] - 1 and dist[o, x] == dist[o, d] - 1
            if dist[o, d] == 1:  # one edge: picked up 5 m in, dropped at its end
                assert (a, b) == (x, y)
            else:  # b, then x: still on a shortest path
                assert dist[b, x] == dist[o, d] - 2


def test_ours_runner_serves_the_workload(tmp_path):
    """The project's runner reads the workload as trace + start file: every request released,
    served with the fcfs rule (3 taxis, 12 sparse requests: each waits exactly the grid
    distance of the nearest idle taxi, computed here by hand)."""
    w, t, o, d, s = pw.generate(12, 3, 2.0, seed=3, drain=3600.0)
    pw.write(tmp_path, w, t, o, d, s)
    out = tmp_path / "ours.json"
    subprocess.run([sys.executable, str(BENCH / "peers_ours.py"), str(tmp_path), str(out)],
                   check=True, cwd=BENCH.parent)
    row = json.loads(out.read_text())
    assert row["requests"] == 12 and row["served"] == 12 and row["picked"] == 12
    # replay: at each release, idle taxis are those whose last drop-off is done
    c, r = w.node_xy(np.arange(w.nodes))
    dist = (np.abs(c[:, None] - c[None, :]) + np.abs(r[:, None] - r[None, :])) * w.block
    where, free_at, waits, metres = s.copy(), np.zeros(3), [], 0.0
    for ti, oi, di in zip(t, o, d):
        idle = np.flatnonzero(free_at <= ti)
        assert idle.size, "the test expects an idle taxi at every release"
        v = idle[np.argmin(dist[where[idle], oi])]
        pick = dist[where[v], oi] / w.speed
        waits.append(pick)
        metres += dist[where[v], oi] + dist[oi, di]
        free_at[v] = ti + pick + dist[oi, di] / w.speed
        where[v] = di
    assert row["wait_mean"] == pytest.approx(np.mean(waits), abs=1e-6)
    assert row["vehicle_km"] == pytest.approx(metres / 1000)


def test_ride_metrics_by_hand():
    """Shared-ride metrics over the requests served: detour = in-vehicle / direct time, delay =
    drop-off - release - direct time, shared share, occupancy = passenger-km / vehicle-km."""
    nan = float("nan")
    released = np.array([0.0, 10.0, 20.0])
    picked = np.array([5.0, 15.0, nan])
    done = np.array([45.0, 75.0, nan])
    direct = np.array([20.0, 30.0, 40.0])
    m = pw.metrics(released, picked, done, 2_000.0, direct=direct,
                   shared=np.array([True, False, True]), passenger_m=3_000.0)
    assert m["served"] == 2 and m["served_share"] == pytest.approx(2 / 3)
    assert m["detour_mean"] == pytest.approx((40 / 20 + 60 / 30) / 2)
    assert m["delay_mean"] == pytest.approx(((45 - 0 - 20) + (75 - 10 - 30)) / 2)
    assert m["shared_rate"] == pytest.approx(0.5)  # the unserved third is not counted
    assert m["occupancy"] == pytest.approx(1.5) and m["passenger_km"] == pytest.approx(3.0)


def test_limits_and_jittered_streets(tmp_path):
    """The windows are release + max_wait and release + direct + max_delay; direct times are
    Manhattan distances on the plain grid and Dijkstra's on jittered streets, and the GraphML
    the project reads gives the same fastest times."""
    from dispatch.files.roads import read_graphml
    from dispatch.space.roads import RoadNetwork

    w, t, o, d, s = pw.generate(50, 3, 1.0, seed=2, columns=5, rows=4, max_wait=120.0,
                                max_delay=300.0)
    lp, ld = w.latest(t, o, d)
    (ox, oy), (dx, dy) = w.node_xy(o), w.node_xy(d)
    l1 = (np.abs(ox - dx) + np.abs(oy - dy)) * w.block / w.speed
    assert np.allclose(lp, t + 120.0) and np.allclose(ld, t + l1 + 300.0)
    jw, jt, jo, jd, js = pw.generate(50, 3, 1.0, seed=2, columns=5, rows=4, jitter=0.1)
    assert np.array_equal(jt, t) and np.array_equal(jo, o) and np.array_equal(js, s)
    u, _, metres = jw.streets()
    assert u.size == 4 * 4 + 5 * 3 and np.all(np.abs(metres / w.block - 1) <= 0.1)
    assert len(set(metres.tolist())) == metres.size
    direct = jw.direct(jo, jd)
    assert not np.allclose(direct, l1) and np.all(np.abs(direct / l1 - 1) <= 0.1 + 1e-12)
    pw.write(tmp_path, jw, jt, jo, jd, js)
    net = RoadNetwork.from_graph(read_graphml(tmp_path / "grid.graphml"))
    from scipy.sparse.csgraph import dijkstra

    times = dijkstra(net.time)
    idx = [net.index_of(i) for i in range(jw.nodes)]
    assert np.allclose(times[np.ix_(idx, idx)][jo, jd], direct, rtol=0, atol=1e-9)
    assert pw.read(tmp_path)[0] == jw


def test_ridepy_driven_seconds_is_the_union_per_vehicle():
    import peers_ridepy

    vehicle = np.array([0, 0, 1, 0, -1, 1])
    start = np.array([0.0, 5.0, 1.0, 20.0, 0.0, 2.0])
    stop = np.array([10.0, 8.0, 3.0, 25.0, 99.0, 4.0])
    # vehicle 0: [0, 10] and [20, 25]; vehicle 1: [1, 4]; -1 is left out
    assert peers_ridepy.driven_seconds(vehicle, start, stop) == pytest.approx(10 + 5 + 3)


@pytest.mark.parametrize("window", [None, 30.0])
def test_ours_runner_pools(tmp_path, window):
    """A 4-seat workload through the project's runner with the added-time objective: every
    request within its limits, rejected or (batched) expired, and the shared-ride metrics
    consistent. Without a window each request is decided at its release; with a 30 s window
    (``pooling.py --batch-window 30``) the scenario says so and decisions come up to 30 s after
    the release."""
    import pyarrow.parquet as pq

    from dispatch.scenario.load import load_scenario

    w, t, o, d, s = pw.generate(60, 3, 0.25, seed=4, drain=2000.0, capacity=4, max_wait=300.0,
                                max_delay=300.0)
    pw.write(tmp_path, w, t, o, d, s)
    out = tmp_path / "ours.json"
    extra = [] if window is None else [repr(window)]
    subprocess.run([sys.executable, str(BENCH / "peers_ours.py"), str(tmp_path), str(out),
                    "hungarian", "added_time", *extra], check=True, cwd=BENCH.parent)
    row = json.loads(out.read_text())
    name = "ours_hungarian" if window is None else "ours_hungarian_bw30"
    [spec] = load_scenario(tmp_path / f"{name}.toml", ignore_limits=True).runs()
    assert spec.scenario.dispatch.batch_window == (window or 0.0)
    [part] = (tmp_path / f"{name}_out" / "tasks").rglob("part-*.parquet")
    tasks = pq.read_table(part)
    late = tasks["assigned_at"].to_numpy() - tasks["released_at"].to_numpy()
    late = late[np.isfinite(late)]
    if window is None:
        assert row["expired"] == 0 and np.all(late == 0)
    else:
        assert late.max() > 0 and np.all((late >= 0) & (late <= window + 1e-9))
    assert row["served"] + row["rejected"] + row["expired"] == 60 and row["served"] > 0
    assert 0 <= row["wait_mean"] <= 300 and 0 <= row["delay_mean"] <= 300
    assert row["detour_mean"] >= 1 - 1e-9 and 0 < row["shared_rate"] <= 1
    assert row["occupancy"] == pytest.approx(row["passenger_km"] / row["vehicle_km"])


def test_pooling_series_per_batch_window():
    """``pooling.py --batch-window 0 30``: one series of ours per window (0 is today's run, named
    ``ours``), labelled as batched, each run by peers_ours.py with its window."""
    import peers
    import pooling

    series = pooling.ours_series([30.0, 0.0, 30.0])
    assert series == {"ours-30": ("hungarian", "added_time", "30.0"),
                      "ours": ("hungarian", "added_time")}
    assert pooling.label_of("ours-30") == "ours (batched 30 s)"
    assert pooling.label_of("ours") == "ours" and pooling.label_of("ridepy") == "RidePy"
    cmd = peers.command("ours-30", Path("w"), Path("w/ours-30.json"), series)
    assert Path(cmd[1]).name == "peers_ours.py" and cmd[-3:] == ["hungarian", "added_time", "30.0"]
    assert peers.command("ours", Path("w"), Path("o.json"))[-2:] == ["w", "o.json"]
