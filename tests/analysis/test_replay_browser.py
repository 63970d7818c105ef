"""``dispatch replay`` in a real browser: Debian's ``chromium`` driven by Playwright (no
browser download). The page's counts equal counts computed here from the Parquet tables;
it draws vehicles, follows a clicked one, shows two runs side by side and the state of
charge, loads nothing from the network, and shows text from the input files as text. The
errors on a bad folder are checked without a browser."""

from __future__ import annotations

import shutil
from io import BytesIO
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.dataset as ds
import pytest

from dispatch.run.runner import execute
from dispatch.scenario.load import load_scenario
from tests.conftest import run_cli

CHROMIUM = Path("/usr/bin/chromium")
EVIL = "</script><script>document.title='x'</script>"
KPIS = ("waiting", "onboard", "delivered", "rejected", "declined", "cutoff", "booked", "walking")

ROAD = """\
name = "<b>ev</b>{evil}"
seed = 1
duration = 3000.0
[world]
network = "manhattan"
blocks = [6, 6]
block = 200.0
speed = 10.0
[fleet]
agents = 6
capacity = 2
[fleet.energy]
battery_kwh = 2.0
wh_per_km = 150.0
soc0 = 0.8
sample = 300.0
[chargers]
file = "st.csv"
[charging.threshold]
low = 0.3
high = 0.9
[tasks]
source = "poisson"
rate = 0.03
count = 60
max_wait = 300.0
max_delay = 600.0
[dispatch]
allocator = "{allocator}"
"""


def _road_run(root: Path, allocator: str) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "st.csv").write_text(
        f'station_id,node,plugs,kw\n"{EVIL}",0,1,20\nB,30,2,20\n', encoding="utf-8")
    p = root / "ev.toml"
    p.write_text(ROAD.format(evil=EVIL, allocator=allocator), encoding="utf-8")
    out = root / "run"
    execute(load_scenario(p).runs(), out)
    return out


@pytest.fixture(scope="module")
def road_run(tmp_path_factory) -> Path:
    """A small pooled road run with an electric fleet, a station named like markup."""
    return _road_run(tmp_path_factory.mktemp("replay_road"), "hungarian")


@pytest.fixture(scope="module")
def road_run_b(tmp_path_factory) -> Path:
    return _road_run(tmp_path_factory.mktemp("replay_road_b"), "greedy")


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.skip("needs Debian's chromium package (apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="needs the playwright package (pip install playwright)")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        yield b
        b.close()


class Page:
    """A page of the browser whose every request that is not a file is blocked and
    recorded, with its console messages and script errors."""

    def __init__(self, browser, path: Path, t: float | None = None) -> None:
        self.ctx = browser.new_context(viewport={"width": 1280, "height": 760})
        self.blocked: list[str] = []
        self.requests: list[str] = []
        self.console: list[str] = []

        def route(r):
            if r.request.url.startswith("file://"):
                r.continue_()
            else:
                self.blocked.append(r.request.url)
                r.abort()

        self.ctx.route("**/*", route)
        self.page = self.ctx.new_page()
        self.page.on("request", lambda q: self.requests.append(q.url))
        self.page.on("console", lambda m: self.console.append(f"{m.type}: {m.text}"))
        self.page.on("pageerror", lambda e: self.console.append(f"pageerror: {e}"))
        url = path.resolve().as_uri() + (f"#t={t}" if t is not None else "")
        self.page.goto(url)
        self.page.wait_for_selector("body[data-ready='1']", timeout=30000)

    def kpis(self, view: int = 0) -> dict[str, int]:
        """The counts the panel shows (those of features the run lacks are not shown)."""
        sec = f"section.view[data-run='{view}'] "
        return {k: int(self.page.text_content(sec + f"[data-kpi='{k}']")) for k in KPIS
                if self.page.query_selector(sec + f"[data-kpi='{k}']") is not None}

    def close(self) -> None:
        assert not self.blocked, self.blocked
        assert all(u.startswith("file://") for u in self.requests), self.requests
        assert not [m for m in self.console if "error" in m.split(":")[0]
                    or "Content Security Policy" in m], self.console
        self.ctx.close()


def _table(folder: Path, name: str) -> pd.DataFrame:
    return ds.dataset(folder / name, format="parquet", partitioning="hive").to_table().to_pandas()


def expected_counts(tasks: pd.DataFrame, t: float, walk_speed: float = 1.4) -> dict[str, int]:
    """The issue's definitions, from the tasks table; and those of the demand-responsive
    features (analysis/replay.py's docstring), row by row."""
    def at_or_before(col):
        return tasks[col].notna() & (tasks[col] <= t)

    picked, closed = at_or_before("picked_up_at"), at_or_before("closed_at")
    walking = 0
    for r in tasks.itertuples(index=False):
        if r.walk_to_board_m > 0:  # from release to the boarding point, until pickup / close
            until = min(r.released_at + r.walk_to_board_m / walk_speed,
                        *(x for x in (r.picked_up_at, r.closed_at) if x == x))
            walking += r.released_at <= t < until
        if r.walk_from_alight_m > 0 and r.completed_at == r.completed_at:
            walking += r.completed_at <= t < r.completed_at + r.walk_from_alight_m / walk_speed
    return {"waiting": int((at_or_before("released_at") & ~picked & ~closed).sum()),
            "onboard": int((picked & ~closed).sum()),
            "delivered": int(at_or_before("completed_at").sum()),
            "rejected": int((closed & tasks["state"].isin(["rejected", "expired"])).sum()),
            "declined": int((closed & (tasks["state"] == "declined")).sum()),
            "cutoff": int((closed & (tasks["state"] == "cut_off")).sum()),
            "booked": int((at_or_before("booked_at") & ~picked & ~closed).sum()),
            "walking": int(walking)}


def _times(tasks: pd.DataFrame) -> list[float]:
    """Three times: one a quarter in, one exactly at a pickup, one late in the run."""
    end = float(tasks["closed_at"].max())
    picks = tasks["picked_up_at"].dropna().sort_values()
    return [round(end / 4, 3), float(picks.iloc[len(picks) // 2]), round(end * 0.8, 3)]


def _write(folder: Path, out: Path, *more: str) -> Path:
    r = run_cli("replay", folder, "--out", out, *more)
    assert r.returncode == 0, r.stderr + r.stdout
    return out


def _vehicles_drawn(p: Page, png: bytes) -> tuple[int, int]:
    """(vehicles on the map, those whose pixel in the screenshot has their state's colour)."""
    from PIL import Image

    im = np.asarray(Image.open(BytesIO(png)).convert("RGB")).astype(int)
    colors = p.page.evaluate("window.replay.colors")
    seen = shown = 0
    for v in p.page.evaluate("window.replay.vehicles()"):
        x, y = int(round(v["x"])), int(round(v["y"]))
        if not (0 <= y < im.shape[0] and 0 <= x < im.shape[1]):
            continue
        seen += 1
        c = colors[v["state"]].lstrip("#")
        rgb = np.array([int(c[i:i + 2], 16) for i in (0, 2, 4)])
        shown += int(np.abs(im[y, x] - rgb).sum() < 40)
    return seen, shown


@pytest.mark.parametrize("world", ["road", "voxel"])
def test_counts_match_the_tables(world, road_run, single_run, browser, tmp_path):
    folder = road_run if world == "road" else single_run
    tasks = _table(folder, "tasks")
    page = _write(folder, tmp_path / "replay.html")
    times = _times(tasks)
    p = Page(browser, page, times[0])
    try:
        for i, t in enumerate(times):
            if i:
                p.page.evaluate("t => window.replay.seek(t)", t)
            want = expected_counts(tasks, t)
            assert p.kpis() == {k: want[k] for k in KPIS[:4] + ("cutoff",)}, (t, want)
            assert p.page.evaluate("window.replay.counts()") == want
        # the hash opens the page paused at that time
        assert p.page.evaluate("window.replay.time()") == pytest.approx(times[-1])
        canvas = p.page.query_selector("section.view canvas.map")
        shot = canvas.screenshot()
        from PIL import Image

        im = np.asarray(Image.open(BytesIO(shot)).convert("L"))
        assert im.std() > 5, "blank map"
        seen, shown = _vehicles_drawn(p, shot)
        assert seen >= 3 and shown >= seen - 1, (seen, shown)  # one may hide under another
    finally:
        p.close()


def test_hash_opens_paused_at_that_time(road_run, browser, tmp_path):
    page = _write(road_run, tmp_path / "replay.html")
    p = Page(browser, page, 1234.5)
    try:
        p.page.wait_for_timeout(300)
        assert p.page.evaluate("window.replay.time()") == 1234.5
        assert p.page.text_content("#clock") == "0:20:34"
        p.page.select_option("#speed", "-10")  # reverse
        p.page.click("#play")
        p.page.wait_for_timeout(600)
        p.page.click("#play")
        assert 1234.5 - 60 < p.page.evaluate("window.replay.time()") < 1234.5 - 1
    finally:
        p.close()


def test_jump_to_the_next_event_of_a_kind(road_run, browser, tmp_path):
    ev = _table(road_run, "events")
    page = _write(road_run, tmp_path / "replay.html")
    p = Page(browser, page, 1000.0)
    try:
        for kind in ("pickup", "insert", "charge_start"):
            p.page.evaluate("window.replay.seek(1000)")
            times = ev.loc[(ev["event"] == kind) & (ev["t"] > 1000.0), "t"]
            assert len(times), kind
            p.page.select_option("#jumpkind", kind)
            p.page.click("#jump")
            assert p.page.evaluate("window.replay.time()") == float(times.min())
    finally:
        p.close()


def test_clicking_a_vehicle_shows_its_stop_list(road_run, browser, tmp_path):
    tasks = _table(road_run, "tasks")
    t = _times(tasks)[0]
    riding = tasks[(tasks["picked_up_at"] <= t) & (tasks["closed_at"] > t)]
    assert len(riding), "no ride at the chosen time"
    page = _write(road_run, tmp_path / "replay.html")
    p = Page(browser, page, t)
    try:
        box = p.page.query_selector("section.view canvas.map").bounding_box()
        ids = sorted(_table(road_run, "vehicles")["agent_id"].astype(int))
        pos = {i: p.page.evaluate("i => window.replay.screen(i)", i) for i in ids}

        def isolated(i):
            return min((np.hypot(*(np.subtract(pos[i], pos[j]))) for j in ids if j != i),
                       default=99) > 16

        candidates = [int(a) for a in riding["agent_id"] if isolated(int(a))]
        assert candidates, "every riding vehicle is next to another one"
        v = candidates[0]
        p.page.mouse.click(box["x"] + pos[v][0], box["y"] + pos[v][1])
        p.page.wait_for_selector(f"[data-panel='follow'] [data-vehicle='{v}']")
        stops = p.page.text_content("[data-panel='follow'] [data-panel='stops']")
        for task in riding.loc[riding["agent_id"] == v, "task_id"]:
            assert f"drop-off of request {int(task)}" in stops
        riders = p.page.text_content("[data-panel='follow']")
        assert "riders: request" in riders and "state of charge" in riders
    finally:
        p.close()


def test_compare_shows_both_runs(road_run, road_run_b, browser, tmp_path):
    page = _write(road_run, tmp_path / "replay.html", "--compare", str(road_run_b))
    tasks = [_table(road_run, "tasks"), _table(road_run_b, "tasks")]
    t = _times(tasks[0])[0]
    p = Page(browser, page, t)
    try:
        assert len(p.page.query_selector_all("section.view")) == 2
        titles = [p.page.text_content(f"section.view[data-run='{i}'] .title") for i in (0, 1)]
        assert "hungarian" in titles[0] and "greedy" in titles[1]
        for i in (0, 1):
            want = expected_counts(tasks[i], t)
            assert p.kpis(i) == {k: want[k] for k in KPIS[:4] + ("cutoff",)}
            assert p.page.evaluate(f"window.replay.counts({i})") == expected_counts(tasks[i], t)
    finally:
        p.close()


def test_energy_run_shows_the_state_of_charge(road_run, browser, tmp_path):
    page = _write(road_run, tmp_path / "replay.html")
    soc = _table(road_run, "soc")
    t = float(soc["t"].iloc[len(soc) // 2])
    p = Page(browser, page, t)
    try:
        panel = p.page.query_selector("[data-panel='soc']")
        assert panel is not None and panel.is_visible()
        q = soc.loc[soc["t"] == t, "soc"].median()
        assert f"median {100 * q:.0f} %" in panel.text_content()
    finally:
        p.close()


def test_text_from_the_inputs_is_shown_as_text(road_run, browser, tmp_path):
    page = _write(road_run, tmp_path / "replay.html")
    assert EVIL not in page.read_text(encoding="utf-8")  # escaped in the data block
    p = Page(browser, page, 100.0)
    try:
        assert p.page.title() != "x" and "<b>ev</b>" in p.page.title()
        assert EVIL in p.page.text_content("[data-panel='stations']")
        assert "<b>ev</b>" in p.page.text_content("section.view .title")
        assert p.page.query_selector("section.view .title b") is None
        assert p.page.evaluate("document.scripts.length") == 2
    finally:
        p.close()


# ----------------------------------------------------------------------------- no browser
def test_the_replay_needs_no_dispatch_pybullet_or_torch(road_run, single_run, tmp_path):
    """Written with the heavy modules and the dispatch package itself blocked."""
    import subprocess
    import sys

    code = f"""
import sys
for m in ("pybullet", "torch", "dispatch", "simpy", "ray"):
    sys.modules[m] = None
from analysis.replay import write_replay
for src, name in (({str(road_run)!r}, "road"), ({str(single_run)!r}, "voxel")):
    print(write_replay(src, {str(tmp_path)!r} + "/" + name + ".html").stat().st_size > 0)
print([m for m in ("pybullet", "torch", "dispatch") if sys.modules.get(m) is not None])
"""
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=root, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["True", "True", "[]"]


def test_counts_at_agrees_with_the_definitions(road_run):
    from analysis.replay import counts_at

    tasks = _table(road_run, "tasks")
    for t in [0.0, *_times(tasks), float(tasks["closed_at"].max()) + 1]:
        assert counts_at(tasks, t) == expected_counts(tasks, t)


def _error(*args) -> str:
    r = run_cli("replay", *args)
    assert r.returncode != 0
    lines = [x for x in (r.stderr + r.stdout).strip().splitlines() if x.strip()]
    assert len(lines) == 1, lines
    return lines[0]


def _interpolate(kf: pd.DataFrame, agent: int, t: float) -> tuple[float, float]:
    """Where the page draws ``agent`` at ``t``: the last keyframe at or before ``t``, moving in
    a straight line toward the next one."""
    k = kf[kf["agent_id"] == agent]
    ts, xs, ys = (k[c].to_numpy(dtype=float) for c in ("t", "x", "y"))
    i = int(np.searchsorted(ts, t, side="right")) - 1
    if i >= len(ts) - 1 or ts[i + 1] == ts[i]:
        return xs[i], ys[i]
    a = (t - ts[i]) / (ts[i + 1] - ts[i])
    return xs[i] + a * (xs[i + 1] - xs[i]), ys[i] + a * (ys[i + 1] - ys[i])


@pytest.mark.parametrize("world", ["road", "voxel"])
def test_keyframes_keep_every_recorded_position(world, road_run, single_run):
    """Leaving out standing rows changes nothing drawn: at every time a vehicle's position was
    recorded (the last one recorded at that time), the page puts it there."""
    from analysis.replay import POSITION_EVENTS, keyframes

    folder = road_run if world == "road" else single_run
    ev, veh = _table(folder, "events"), _table(folder, "vehicles")
    kf = keyframes(ev, veh)
    assert len(kf) < len(ev[ev["event"].isin(POSITION_EVENTS)]) + len(veh)
    pos = ev[(ev["agent_id"] >= 0) & ev["event"].isin(POSITION_EVENTS)]
    last = pos.groupby(["agent_id", "t"], sort=False).tail(1)
    for r in last.itertuples(index=False):
        assert _interpolate(kf, r.agent_id, r.t) == pytest.approx((r.x, r.y)), r


def test_routed_keyframes_follow_the_streets(road_run):
    """Routing adds only nodes, each drive's added nodes form a path of the network's edges
    from where it departed to where it arrived, and the recorded positions stay."""
    from analysis.replay import _network, keyframes, route_keyframes
    from analysis.replay_data import choose_run

    ev, veh = _table(road_run, "events"), _table(road_run, "vehicles")
    kf = keyframes(ev, veh)
    x, y, _pairs, u, v, sec = _network(choose_run(road_run, None))
    routed = route_keyframes(kf, x, y, u, v, sec)
    assert len(routed) > len(kf)
    node = {(round(a, 6), round(b, 6)): i for i, (a, b) in enumerate(zip(x, y))}
    edges = set(zip(u.tolist(), v.tolist()))
    merged = routed.merge(kf.assign(kept=True), how="left", on=["agent_id", "t", "x", "y", "z"])
    added = merged["kept"].isna().to_numpy()
    assert (~added).sum() == len(kf)  # every recorded position stays
    assert added.any()
    for agent, g in routed.groupby("agent_id"):
        assert g["t"].is_monotonic_increasing
        ids = [node.get((round(a, 6), round(b, 6))) for a, b in zip(g["x"], g["y"])]
        for i in range(1, len(ids)):
            if added[g.index[i]] or added[g.index[i - 1]]:  # a step of a routed drive
                assert (ids[i - 1], ids[i]) in edges, (agent, i)


def test_a_folder_of_several_runs_needs_run(small_sweep, tmp_path):
    line = _error(small_sweep, "--out", tmp_path / "r.html")
    assert str(small_sweep) in line and "--run" in line and "18 runs" in line


def test_a_folder_without_runs(tmp_path):
    (tmp_path / "empty").mkdir()
    line = _error(tmp_path / "empty")
    assert str(tmp_path / "empty") in line


def test_a_truncated_parquet_file_is_named(single_run, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(single_run, copy)
    [part] = list((copy / "tasks").rglob("part-0.parquet"))
    data = part.read_bytes()
    part.write_bytes(data[: len(data) // 2])
    line = _error(copy, "--out", tmp_path / "r.html")
    assert str(part) in line


def _lonlat_city(root: Path) -> Path:
    """A 5 x 5 street grid in longitude / latitude (node-link JSON, crs epsg:4326) near
    Times Square, and a scenario of 3 taxis on it."""
    import json

    nodes, links = [], []
    for i in range(5):
        for j in range(5):
            nodes.append({"id": i * 5 + j, "x": -73.99 + 0.002 * i, "y": 40.75 + 0.002 * j})
    for i in range(5):
        for j in range(5):
            for di, dj, m in ((1, 0, 168.6), (0, 1, 222.4)):
                if i + di < 5 and j + dj < 5:
                    a, b = i * 5 + j, (i + di) * 5 + j + dj
                    links += [{"source": a, "target": b, "length": m, "speed": 10.0},
                              {"source": b, "target": a, "length": m, "speed": 10.0}]
    (root / "grid.json").write_text(json.dumps({"directed": True, "graph": {"crs": "epsg:4326"},
                                                "nodes": nodes, "links": links}))
    p = root / "ll.toml"
    p.write_text('name = "ll"\nseed = 0\nduration = 1500.0\n[world]\nnetwork = "grid.json"\n'
                 '[fleet]\nagents = 3\n[tasks]\nsource = "poisson"\nrate = 0.02\n'
                 'count = 15\nmax_wait = 600.0\n[dispatch]\nallocator = "hungarian"\n',
                 encoding="utf-8")
    execute(load_scenario(p).runs(), root / "run")
    return root / "run"


def test_kepler_trips_in_lon_lat(tmp_path):
    import json

    pytest.importorskip("pyproj")
    run = _lonlat_city(tmp_path)
    r = run_cli("replay", run, "--kepler", "--out", tmp_path / "t.geojson", "--epoch", "1e9")
    assert r.returncode == 0, r.stderr
    fc = json.loads((tmp_path / "t.geojson").read_text())
    assert fc["type"] == "FeatureCollection" and fc["features"]
    vehicles = _table(run, "vehicles")
    by_vehicle: dict[int, list] = {}
    for f in fc["features"]:
        assert f["geometry"]["type"] == "LineString"
        props = f["properties"]
        assert set(props) == {"vehicle_id", "state", "passengers"}
        coords = f["geometry"]["coordinates"]
        assert len(coords) >= 2 and all(len(c) == 4 and c[2] == 0 for c in coords)
        for lon, lat, _, _ in coords:  # on the grid, in degrees
            assert -73.9901 <= lon <= -73.9819 and 40.7499 <= lat <= 40.7581
        ts = [c[3] for c in coords]
        assert ts == sorted(ts) and ts[0] >= 1e9
        by_vehicle.setdefault(props["vehicle_id"], []).append((ts[0], ts[-1], props["state"]))
    assert set(by_vehicle) == set(vehicles["agent_id"].astype(int))
    for spells in by_vehicle.values():  # each vehicle's spells follow each other
        spells.sort()
        assert all(a[1] == pytest.approx(b[0]) for a, b in zip(spells, spells[1:]))
    states = {s for spells in by_vehicle.values() for _, _, s in spells}
    assert {"idle", "to_pickup", "occupied"} <= states


def test_kepler_needs_a_network_with_a_crs(road_run, tmp_path):
    line = _error(road_run, "--kepler", "--out", tmp_path / "t.geojson")
    assert "no CRS" in line and str(road_run) in line


# ----------------------------------------------------------------------------- demand-responsive
# Two small runs of the features of issue 31 on the 6 x 6 grid: (a) riders who walk to meeting
# points, 30 % of the rides booked 10 min ahead, the run cut short so that some requests are
# cut off; (b) offers a rider declines past 150 s of wait, and driver shifts (vehicles 3 and 4
# enter late, 0, 3 and 5 end their shifts and drive to their depots). (Meeting points and
# shifts are two runs: the kernel does not combine them.)
DRT = """\
name = "drt"
seed = 1
duration = {duration}
[world]
network = "manhattan"
blocks = [6, 6]
block = 200.0
speed = 10.0
[fleet]
{fleet}
capacity = 2
[tasks]
source = "poisson"
rate = 0.03
count = 60
max_wait = 300.0
max_delay = 600.0
{tasks}
[dispatch]
allocator = "hungarian"
batch_window = 30.0
{dispatch}
[acceptor]
name = "threshold"
retries = 0
[acceptor.threshold]
max_wait = 150.0
"""
SHIFTS = """\
vehicle_id,node,shift_start,shift_end,depot
0,0,0,1200,0
1,10,0,,
2,14,0,,
3,20,600,1800,20
4,35,900,,35
5,6,0,1500,6
"""
WALK_SPEED = 1.2


@pytest.fixture(scope="module")
def walk_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("replay_walk")
    p = root / "walk.toml"
    p.write_text(DRT.format(duration=1700.0, fleet="agents = 6",
                            tasks=f"max_walk = 250.0\nwalk_speed = {WALK_SPEED}\n"
                                  "prebook_share = 0.3\nprebook_lead = 600.0",
                            dispatch='prebook = "at_booking"'), encoding="utf-8")
    execute(load_scenario(p).runs(), root / "run")
    return root / "run"


@pytest.fixture(scope="module")
def shift_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("replay_shifts")
    (root / "fleet.csv").write_text(SHIFTS, encoding="utf-8")
    p = root / "shifts.toml"
    p.write_text(DRT.format(duration=3000.0, fleet='start = "fleet.csv"\nshift_grace = 300.0',
                            tasks="", dispatch=""), encoding="utf-8")
    execute(load_scenario(p).runs(), root / "run")
    return root / "run"


def _spread(tasks: pd.DataFrame, col: str) -> list[float]:
    """Three times at which something of ``col`` happens (a quarter, half, three quarters
    through its times), a little after."""
    ts = tasks[col].dropna().sort_values().to_numpy()
    return [float(ts[int(len(ts) * q)]) + 5.0 for q in (0.25, 0.5, 0.75)]


def test_counts_at_the_new_states_and_marks(walk_run, shift_run):
    """counts_at agrees with the row-by-row definitions, and each feature's count is seen."""
    from analysis.replay import counts_at

    seen = dict.fromkeys(("declined", "cutoff", "booked", "walking"), 0)
    for folder, speed in ((walk_run, WALK_SPEED), (shift_run, 1.4)):
        tasks = _table(folder, "tasks")
        end = float(tasks["closed_at"].max())
        for t in np.linspace(0.0, end, 41):
            got = counts_at(tasks, t, walk_speed=speed)
            assert got == expected_counts(tasks, t, speed), t
            for k in seen:
                seen[k] = max(seen[k], got[k])
    assert all(seen.values()), seen


def test_the_page_data_carry_walks_bookings_and_offers(walk_run, shift_run, road_run):
    import base64

    from analysis.replay import build_run
    from analysis.replay_data import choose_run

    def arr(o):
        return np.frombuffer(base64.b64decode(o["b"]), dtype=np.dtype(o["t"]).newbyteorder("<"))

    d = build_run(choose_run(walk_run, None), route=False)
    tasks = _table(walk_run, "tasks").sort_values("released_at", kind="stable")
    tk = d["tasks"]
    assert tk["features"] == {"booked": True, "offers": True, "walks": True}
    assert tk["walkSpeed"] == WALK_SPEED  # the scenario's
    np.testing.assert_array_equal(arr(tk["bk"]), tasks["booked_at"].to_numpy())
    np.testing.assert_array_equal(arr(tk["promised"]), tasks["promised"].astype(np.uint8))
    np.testing.assert_allclose(arr(tk["wTo"]), tasks["walk_to_board_m"].fillna(0), rtol=1e-6)
    np.testing.assert_allclose(arr(tk["bx"]) + d["origin"][0], tasks["board_x"], atol=0.01)
    np.testing.assert_allclose(arr(tk["ay"]) + d["origin"][1], tasks["alight_y"], atol=0.01)
    codes = arr(tk["state"])
    states = np.array(d["taskStates"])[codes]
    np.testing.assert_array_equal(states, tasks["state"].to_numpy())  # cut_off: its own code
    s = build_run(choose_run(shift_run, None), route=False)
    assert "declined" in set(np.array(s["taskStates"])[arr(s["tasks"]["state"])])
    plain = build_run(choose_run(road_run, None), route=False)["tasks"]
    assert plain["features"] == {"booked": False, "offers": False, "walks": False}
    assert "bk" not in plain and "wTo" not in plain


def test_duty_spells_of_driver_shifts(shift_run, road_run):
    """Off shift before entering and after leaving, driving home in between; the time on duty
    is the vehicles table's vehicle_hours; no pickup while off shift; the fleet states laid
    over still cover each vehicle's time without gaps."""
    from analysis.replay_duty import duty_spells, overlay
    from analysis.timeline import fleet_states

    ev, veh = _table(shift_run, "events"), _table(shift_run, "vehicles")
    end = float(ev["t"].max())
    sp = duty_spells(ev, veh, end)
    off = sp[sp["state"] == "off_shift"]
    for r in veh.itertuples(index=False):
        mine = off[off["agent_id"] == r.agent_id]
        assert end - (mine["end"] - mine["start"]).sum() == pytest.approx(
            r.vehicle_hours * 3600, abs=1e-6), r.agent_id
    first = off.groupby("agent_id")["start"].min()
    assert first.get(3) == 0.0 and first.get(4) == 0.0  # before their shifts
    assert off.loc[(off["agent_id"] == 3) & (off["start"] == 0.0), "end"].item() == 600.0
    home = sp[sp["state"] == "to_depot"]
    assert set(home["agent_id"]) <= {0, 3, 5} and len(home)
    ends = ev[ev["event"] == "shift_end"].set_index("agent_id")["t"]
    for r in home.itertuples(index=False):
        assert r.end == ends[r.agent_id]
        assert r.start >= veh.set_index("agent_id").loc[r.agent_id, "shift_end"]
    picks = ev[ev["event"] == "pickup"]
    for r in off.itertuples(index=False):
        mine = picks[picks["agent_id"] == r.agent_id]
        assert not ((mine["t"] > r.start) & (mine["t"] < r.end)).any(), r
    plain = fleet_states(ev.assign(run_id="r"), veh.assign(run_id="r"), end=end)
    assert "to_charger" not in set(plain["state"])  # (no battery: a drive home is no charger's)
    st = overlay(plain, sp)
    assert set(st.loc[st["state"] == "to_depot", "agent_id"]) == set(home["agent_id"])
    for _, g in st.groupby("agent_id"):
        assert g["start"].iloc[0] == 0.0 and g["end"].iloc[-1] == end
        np.testing.assert_array_equal(g["start"].to_numpy()[1:], g["end"].to_numpy()[:-1])
    # a run without shifts: no spell
    assert duty_spells(_table(road_run, "events"), _table(road_run, "vehicles"), 3000.0).empty


def test_browser_walking_riders(walk_run, browser, tmp_path):
    tasks = _table(walk_run, "tasks")
    page = _write(walk_run, tmp_path / "replay.html")
    times = _spread(tasks[tasks["walk_to_board_m"] > 0], "released_at")
    p = Page(browser, page, times[0])
    try:
        drawn = 0
        for t in times:
            p.page.evaluate("t => window.replay.seek(t)", t)
            want = expected_counts(tasks, t, WALK_SPEED)
            assert want["walking"] > 0
            assert p.kpis()["walking"] == want["walking"], t
            from PIL import Image

            im = np.asarray(Image.open(BytesIO(
                p.page.query_selector("section.view canvas.map").screenshot())).convert("RGB"))
            drawn += int((np.abs(im.astype(int) - [0x5d, 0x40, 0x37]).sum(axis=2) < 30).sum())
        assert drawn > 0, "no walk drawn"
        assert "walking" in p.page.text_content("[data-legend='walk']")
        assert p.page.query_selector("[data-layer='walks']") is not None
    finally:
        p.close()


def test_browser_booked_rides(walk_run, browser, tmp_path):
    tasks = _table(walk_run, "tasks")
    page = _write(walk_run, tmp_path / "replay.html")
    times = _spread(tasks, "booked_at")
    p = Page(browser, page, times[0])
    try:
        for t in times:
            p.page.evaluate("t => window.replay.seek(t)", t)
            want = expected_counts(tasks, t, WALK_SPEED)["booked"]
            assert p.kpis()["booked"] == want, t
        assert "booked ahead" in p.page.text_content("[data-legend='booked']")
        # a followed vehicle's stop list says which of its pickups are booked rides
        held = tasks[tasks["booked_at"].notna() & (tasks["assigned_at"] < tasks["picked_up_at"])]
        r = held.iloc[0]
        t = float(r["assigned_at"] + r["picked_up_at"]) / 2
        p.page.evaluate("t => window.replay.seek(t)", t)
        assert p.page.evaluate("i => window.replay.follow(i)", int(r["agent_id"]))
        stops = p.page.text_content("[data-panel='follow'] [data-panel='stops']")
        assert f"pickup of request {int(r['task_id'])} (booked at" in stops
    finally:
        p.close()


def test_browser_declined_offers(shift_run, browser, tmp_path):
    tasks = _table(shift_run, "tasks")
    assert (tasks["state"] == "declined").sum() >= 2
    page = _write(shift_run, tmp_path / "replay.html")
    end = float(tasks["closed_at"].max())
    p = Page(browser, page, end / 2)
    try:
        for t in (end / 2, end):
            p.page.evaluate("t => window.replay.seek(t)", t)
            want = expected_counts(tasks, t)
            got = p.kpis()
            assert (got["declined"], got["rejected"]) == (want["declined"], want["rejected"]), t
        assert got["declined"] == int((tasks["state"] == "declined").sum())
        assert "declined" in p.page.text_content("[data-legend='declined']")
    finally:
        p.close()


def test_browser_cut_off_requests(walk_run, browser, tmp_path):
    tasks = _table(walk_run, "tasks")
    n = int((tasks["state"] == "cut_off").sum())
    assert n > 0, "the run's end cut nothing off"
    page = _write(walk_run, tmp_path / "replay.html")
    p = Page(browser, page, float(tasks["closed_at"].max()))
    try:
        box = p.page.query_selector("[data-kpi='cutoff']")
        assert int(box.text_content()) == n
        label = p.page.evaluate("e => e.parentElement.textContent", box)
        assert "cut off" in label and "cancel" not in label
    finally:
        p.close()


def test_browser_driver_shifts(shift_run, browser, tmp_path):
    from analysis.replay_duty import duty_at, duty_spells

    ev, veh = _table(shift_run, "events"), _table(shift_run, "vehicles")
    sp = duty_spells(ev, veh, float(ev["t"].max()))
    home = sp[sp["state"] == "to_depot"].iloc[0]
    times = [300.0, float(home["start"] + home["end"]) / 2, 2000.0]
    page = _write(shift_run, tmp_path / "replay.html")
    p = Page(browser, page, times[0])
    try:
        for t in times:
            p.page.evaluate("t => window.replay.seek(t)", t)
            want = duty_at(sp, veh["agent_id"], t)
            got = {s: int(p.page.text_content(f"[data-state='{s}']")) for s in want}
            assert got == want, t
            states = {v["id"]: v["state"] for v in p.page.evaluate("window.replay.vehicles()")}
            assert sum(s == "off_shift" for s in states.values()) == want["off_shift"]
        assert states[0] == "off_shift"  # its shift ended at 1200, home by 2000
        assert p.page.query_selector("[data-legend='off_shift']") is not None
        p.page.evaluate("window.replay.seek(0)")
        p.page.select_option("#jumpkind", "shift_end")
        p.page.click("#jump")
        assert p.page.evaluate("window.replay.time()") == float(
            ev.loc[ev["event"] == "shift_end", "t"].min())
        p.page.evaluate("t => window.replay.seek(t)", times[-1])
        # off shift: not drawn; the layer draws a ring where the vehicle waits
        from PIL import Image

        def pixel(v):
            x, y = p.page.evaluate("i => window.replay.screen(i)", v)
            im = np.asarray(Image.open(BytesIO(p.page.query_selector(
                "section.view canvas.map").screenshot())).convert("RGB")).astype(int)
            return im[int(round(y)), int(round(x))]

        colors = p.page.evaluate("window.replay.colors")
        drawn = [np.array([int(c.lstrip("#")[i:i + 2], 16) for i in (0, 2, 4)])
                 for s, c in colors.items() if s != "off_shift"]
        assert min(np.abs(pixel(0) - c).sum() for c in drawn) > 40  # no vehicle drawn there
        p.page.click("[data-layer='offshift']")
        x, y = p.page.evaluate("i => window.replay.screen(i)", 0)
        im = np.asarray(Image.open(BytesIO(p.page.query_selector(
            "section.view canvas.map").screenshot())).convert("RGB")).astype(int)
        ring = im[int(round(y)) - 6:int(round(y)) + 7, int(round(x)) - 6:int(round(x)) + 7]
        assert (np.abs(ring - [0xb0, 0xb7, 0xbf]).sum(axis=2) < 40).any()
    finally:
        p.close()


def test_fleet_states_at_end_show_the_state_the_run_ended_in():
    """A vehicle whose last task completes at the run's last instant: with ``at_end`` its
    states end in a zero-length idle row at the end (the replay's last frame shows it idle,
    not at its task with nothing left); without, the rows are as before."""
    from analysis.timeline import fleet_states

    events = pd.DataFrame({"run_id": "r", "agent_id": [0, 0, 0, 1],
                           "event": ["assign", "pickup", "idle", "assign"],
                           "t": [1.0, 2.0, 10.0, 4.0], "task_id": [5, 5, -1, 6]})
    vehicles = pd.DataFrame({"run_id": "r", "agent_id": [0, 1]})
    plain = fleet_states(events, vehicles, end=10.0)
    ended = fleet_states(events, vehicles, end=10.0, at_end=True)
    mine = ended.loc[ended["agent_id"] == 0]
    assert list(mine["state"]) == ["idle", "to_pickup", "occupied", "idle"]
    assert list(mine["start"]) == [0.0, 1.0, 2.0, 10.0] and list(mine["end"]) == [1.0, 2.0,
                                                                                 10.0, 10.0]
    last = (ended["start"] == ended["end"]).to_numpy()
    assert last.sum() == 1
    pd.testing.assert_frame_equal(ended.loc[~last].reset_index(drop=True),
                                  plain.reset_index(drop=True))
    # the other vehicle, on its way when the run ends, keeps its state to the end: no extra row
    other = ended.loc[ended["agent_id"] == 1]
    assert list(other["state"]) == ["idle", "to_pickup"] and other["end"].iloc[-1] == 10.0


@pytest.mark.parametrize("world", ["road", "voxel"])
def test_the_panel_and_the_legend_speak_of_the_run_s_world(world, road_run, single_run, browser,
                                                           tmp_path):
    """Robots carry no riders and no task floats above a street: the voxel page counts the
    vehicles at a task (no riders, no seats) and its legend has tasks in the air; the road page
    counts riders and seats and its legend no air. At the last frame no vehicle is shown at or
    on its way to a task while nothing waits, rides or was cut off."""
    folder = road_run if world == "road" else single_run
    page = _write(folder, tmp_path / "replay.html")
    p = Page(browser, page)
    try:
        occupancy = p.page.text_content("[data-kpi-extra='occupancy']")
        request = p.page.text_content("[data-legend='request']")
        if world == "voxel":
            assert occupancy.startswith("vehicles at a task: ")
            assert "rider" not in occupancy and "seat" not in occupancy
            assert "in the air" in request and request.startswith("task waiting")
        else:
            assert "riders on board" in occupancy and "seats taken" in occupancy
            assert "in the air" not in request
        end = p.page.evaluate("window.replay.span[1]")
        p.page.evaluate("t => window.replay.seek(t)", end)
        counts = p.page.evaluate("window.replay.counts()")
        states = [v["state"] for v in p.page.evaluate("window.replay.vehicles()")]
        # (a vehicle on its way to a request the run's end cut off is shown so: cut off > 0)
        if counts["waiting"] == counts["onboard"] == counts["cutoff"] == 0:
            assert not {"to_pickup", "occupied", "occupied_2", "occupied_3+"} & set(states), \
                (counts, states)
    finally:
        p.close()
