"""Benchmark: ``dispatch replay`` on two city days (issue 30's bounds), measured in headless
Chromium (Debian's ``chromium``, driven by Playwright) with software rendering.

Days: **Chicago**, ``scenarios/chicago_taxi.toml`` with 1,000 taxis, ``hungarian`` batched
every 30 s (the scenario's sweep reduced to that run); **Manhattan pooled**,
``scenarios/nyc_manhattan.toml`` (NYC taxi requests of 2014-12-21 on the OSM street network)
with 500 taxis of 4 seats and ``max_delay`` 600 s. ``--duration`` cuts the days (simulated
seconds; default: the scenarios' own). For each: the run's wall seconds, then the page's size
(bound 60 MB), its write time (bound 30 s), the time from opening it to its first frame
(``window.replay.readyAt``, bound 5 s) and the frames per second while it plays at 60x
(``requestAnimationFrame`` callbacks over ``--seconds``, bound >= 30), each printed as a ratio
to its bound (<= 1 is within it; fps: bound / measured).

Run: ``.venv/bin/python benchmarks/replay.py [--duration 7200] [--seconds 5] [--only chicago]
[--out DIR]`` (needs /usr/bin/chromium and ``pip install playwright``).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.replay import write_replay  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
BOUNDS = {"size_mb": 60.0, "write_s": 30.0, "interactive_s": 5.0, "fps": 30.0}


def chicago(folder: Path) -> Path:
    t = (ROOT / "scenarios/chicago_taxi.toml").read_text(encoding="utf-8")
    t = re.sub(r"\n\[sweep\].*", "\n", t, flags=re.S)  # one run: the keys below
    t = re.sub(r"(?m)^allocator = .*$", 'allocator = "hungarian"', t)
    t = re.sub(r"(?m)^batch_window = .*$", "batch_window = 30.0", t)
    t = re.sub(r"(?m)^agents = .*$", "agents = 1000", t)
    p = folder / "chicago_1000_bw30.toml"
    p.write_text(t, encoding="utf-8")
    return p


def pooled(folder: Path) -> Path:
    t = (ROOT / "scenarios/nyc_manhattan.toml").read_text(encoding="utf-8")
    t = re.sub(r'(?m)^name = .*$', 'name = "nyc_pooled_500x4"', t)
    t = re.sub(r"(?m)^agents = .*$", "agents = 500\ncapacity = 4", t)
    t = re.sub(r"(?m)^max_wait = (.*)$", r"max_wait = \1\nmax_delay = 600.0", t)
    p = folder / "nyc_pooled_500x4.toml"
    p.write_text(t, encoding="utf-8")
    return p


DAYS = {"chicago": chicago, "pooled": pooled}


def simulate(scenario: Path, out: Path, duration: float | None) -> float:
    cmd = [sys.executable, "-c", "import sys; from dispatch.run.cli import main; sys.exit(main())",
           "run", str(scenario), "--out", str(out), "--overwrite"]
    if duration:
        cmd += ["--duration", str(duration)]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True)
    return time.perf_counter() - t


def browse(page: Path, seconds: float) -> tuple[float, float]:
    """(seconds from opening the page to its first frame, frames per second at 60x)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM,
                              args=["--disable-gpu", "--disable-software-rasterizer=false"])
        pg = b.new_page(viewport={"width": 1400, "height": 850})
        pg.route("**/*", lambda r: r.continue_() if r.request.url.startswith("file://")
                 else r.abort())
        pg.goto(page.resolve().as_uri(), timeout=120_000)
        pg.wait_for_selector("body[data-ready='1']", timeout=120_000)
        ready = pg.evaluate("window.replay.readyAt") / 1000.0
        pg.evaluate("window.replay.seek(window.replay.span[0] + 6 * 3600)")
        pg.evaluate("window.replay.play(60)")
        pg.wait_for_timeout(1000)
        f0, t0 = pg.evaluate("[window.replay.frames(), performance.now()]")
        pg.wait_for_timeout(int(seconds * 1000))
        f1, t1 = pg.evaluate("[window.replay.frames(), performance.now()]")
        b.close()
    return ready, (f1 - f0) / ((t1 - t0) / 1000.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, help="simulated seconds (default: the days')")
    ap.add_argument("--seconds", type=float, default=5.0, help="seconds of play measured")
    ap.add_argument("--only", choices=sorted(DAYS))
    ap.add_argument("--out", type=Path, help="keep the runs and pages here")
    args = ap.parse_args()
    base = args.out or Path(tempfile.mkdtemp(prefix="replay_bench_"))
    base.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, make in DAYS.items():
        if args.only and name != args.only:
            continue
        run_dir = base / name
        sim = simulate(make(base), run_dir, args.duration)
        t = time.perf_counter()
        page = write_replay(run_dir, base / f"{name}.html")
        write = time.perf_counter() - t
        size = page.stat().st_size / 1e6
        ready, fps = browse(page, args.seconds)
        rows.append((name, sim, size, write, ready, fps))
        print(f"{name}: simulated in {sim:.1f} s; page {size:.1f} MB "
              f"({size / BOUNDS['size_mb']:.2f} of the bound), written in {write:.1f} s "
              f"({write / BOUNDS['write_s']:.2f}), interactive after {ready:.2f} s "
              f"({ready / BOUNDS['interactive_s']:.2f}), {fps:.1f} frames/s at 60x "
              f"({BOUNDS['fps'] / max(fps, 1e-9):.2f})", flush=True)
    ok = all(s <= BOUNDS["size_mb"] and w <= BOUNDS["write_s"] and r <= BOUNDS["interactive_s"]
             and f >= BOUNDS["fps"] for _, _, s, w, r, f in rows)
    print("within every bound" if ok else "OUT OF BOUNDS")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
