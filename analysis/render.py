"""Drawing a recorded run as an animation: a voxel run from PyBullet camera images (headless),
a road (taxi) run on its map with matplotlib (:mod:`analysis.road_render`).

The scene is rebuilt from the run's Parquet tables alone: the ground and the obstacle boxes from
``obstacles`` (world size in its metadata), the vehicles from ``vehicles`` (start cells) and
their positions over time from ``events`` (see :mod:`analysis.timeline`); tasks appear when
released (red), turn yellow when assigned and vanish when closed. Each frame is a
``getCameraImage`` with the CPU ``ER_TINY_RENDERER`` of a ``DIRECT`` client, so no display or
GPU is needed; Pillow writes the GIF (an ``.mp4`` needs ``imageio`` with ``imageio-ffmpeg``).

PyBullet and Pillow are imported when :func:`render_run` is called, never at import; the
world's boxes and vehicles are drawn as the run's own PyBullet mirror draws them
(:mod:`dispatch.space.physics`, imported then too).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
from pathlib import Path

import numpy as np

from analysis.io import Results, open_results
from analysis.timeline import positions_at, trajectories

log = logging.getLogger(__name__)

GROUND = (0.80, 0.82, 0.78, 1)
TASK_OPEN = (0.85, 0.10, 0.10, 1)
TASK_ASSIGNED = (0.95, 0.80, 0.10, 1)
HIDDEN = (0.0, 0.0, -1e4)


def _physics():
    """The kernel's drawing of the voxel world (:mod:`dispatch.space.physics`: PyBullet
    imported and connected quietly, boxes, vehicles' bodies, their colours), imported when a
    voxel run is drawn: importing :mod:`analysis` needs no ``dispatch``."""
    from dispatch.space import physics

    return physics


class _Scene:
    """A DIRECT PyBullet client holding visual-only bodies of one run."""

    def __init__(self, world, obstacles, vehicles, tasks, marker: float) -> None:
        self.draw = draw = _physics()
        self.p = p = draw.import_pybullet()
        self.c = draw.connect_direct(p)
        w, d, _ = world
        self._box((0, 0, -0.1), (w, d, 0.0), GROUND)
        for b in obstacles.itertuples(index=False):
            self._box((b.x0, b.y0, b.z0), (b.x1, b.y1, b.z1), draw.OBSTACLE_RGBA)
        self.vehicles = {
            int(v.agent_id): draw.vehicle_body(p, self.c, v.kind == "uav", (v.x0, v.y0, v.z0),
                                               radius=marker, half=(marker, marker, marker * 0.7))
            for v in vehicles.itertuples(index=False)}
        self.tasks = {}
        for t in tasks.itertuples(index=False):
            shape = p.createVisualShape(p.GEOM_CYLINDER, radius=marker * 0.8,
                                        length=marker * 0.5, rgbaColor=TASK_OPEN,
                                        physicsClientId=self.c)
            body = p.createMultiBody(0, -1, shape, basePosition=HIDDEN, physicsClientId=self.c)
            self.tasks[int(t.task_id)] = (body, (t.x, t.y, t.z))

    def _box(self, lo, hi, rgba) -> int:
        return self.draw.box_body(self.p, self.c, [(a + b) / 2 for a, b in zip(lo, hi)],
                                  [(b - a) / 2 for a, b in zip(lo, hi)], rgba)

    def place(self, body: int, pos) -> None:
        self.p.resetBasePositionAndOrientation(body, list(map(float, pos)), (0, 0, 0, 1),
                                               physicsClientId=self.c)

    def colour(self, body: int, rgba) -> None:
        self.p.changeVisualShape(body, -1, rgbaColor=rgba, physicsClientId=self.c)

    def image(self, view, proj, width: int, height: int) -> np.ndarray:
        p = self.p
        _, _, rgba, _, _ = p.getCameraImage(width, height, viewMatrix=view,
                                            projectionMatrix=proj, renderer=p.ER_TINY_RENDERER,
                                            physicsClientId=self.c)
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3]

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.p.disconnect(physicsClientId=self.c)


def _task_states(tasks):
    """Per task: (released, assigned, closed) times; NaN where it never happened."""
    out = {}
    for t in tasks.itertuples(index=False):
        closed = t.closed_at if not math.isnan(t.closed_at) else math.inf
        out[int(t.task_id)] = (t.released_at, t.assigned_at, closed)
    return out


def render_run(source: Results | str | os.PathLike, out: str | os.PathLike | None = None, *,
               run_id: str | None = None, fps: int = 10, seconds: float | None = None,
               size: tuple[int, int] = (480, 360), yaw: float = 30.0,
               pitch: float = -45.0) -> Path:
    """Render one run of ``source`` (a run folder, a sweep folder with ``run_id``, or a
    :class:`Results`) as an animated GIF (or MP4) at ``out``; returns the file written.

    The run's simulated time is mapped onto ``seconds`` of animation (default: as long as the
    run, at most 12 s) at ``fps`` frames per second.
    """
    res = source if isinstance(source, Results) else open_results(source)
    if run_id is None:
        ids = res.run_ids()
        if len(ids) != 1:
            from analysis.report import default_run

            run_id = default_run(res.summary)
            log.info("%d runs; rendering %s (choose one with run_id)", len(ids), run_id)
        else:
            run_id = ids[0]
    run = res.run(run_id)
    s = run["summary"].iloc[0]
    end = float(s["sim_time"]) if len(run["summary"]) else float(run["events"]["t"].max())
    if seconds is None:
        seconds = min(max(end, 2.0), 12.0)
    n_frames = max(2, round(fps * seconds))
    out = Path(out) if out is not None else res.sources[0].path / f"{run_id}.gif"
    if out.suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"{out}: the animation must be a .gif or an .mp4 file")
    if s.get("space") == "road":  # a taxi run: on its map, with matplotlib
        from analysis.network import road_network
        from analysis.road_render import road_frames

        net = road_network(res.metadata(run_id, "tasks"), [src.path for src in res.sources])
        frames = road_frames(run, net, end=end, n_frames=n_frames, size=size,
                             title=f"{s['allocator']}, N = {s['n_agents']}")
        _write(frames, out, fps)
        return out
    world = res.world(run_id)[0]

    marker = max(0.45 * res.world(run_id)[1], max(world) / 45)
    traj = trajectories(run["events"], run["vehicles"])
    life = _task_states(run["tasks"])
    scene = _Scene(world, run["obstacles"], run["vehicles"], run["tasks"], marker)
    p = scene.p
    try:
        # the whole world box in view: its bounding sphere fits the vertical field of view
        fov = 45.0
        target = (world[0] / 2, world[1] / 2, world[2] * 0.35)
        dist = 0.4 * math.hypot(*world) / math.sin(math.radians(fov / 2))
        view = p.computeViewMatrixFromYawPitchRoll(target, dist, yaw, pitch, 0, 2)
        proj = p.computeProjectionMatrixFOV(fov, size[0] / size[1], 0.1, dist * 4)
        frames = []
        shown = {}
        for k in range(n_frames):
            t = end * k / (n_frames - 1)
            for agent, pos in positions_at(traj, t).items():
                scene.place(scene.vehicles[agent], pos)
            for task, (body, cell) in scene.tasks.items():
                released, assigned, closed = life[task]
                state = ("hidden" if not released <= t < closed else
                         "assigned" if assigned <= t else "open")
                if shown.get(task) != state:
                    scene.place(body, HIDDEN if state == "hidden" else cell)
                    if state != "hidden":
                        scene.colour(body, TASK_ASSIGNED if state == "assigned" else TASK_OPEN)
                    shown[task] = state
            frames.append(_caption(scene.image(view, proj, *size), f"t = {t:6.1f} s", run_id))
    finally:
        scene.close()
    _write(frames, out, fps)
    return out


def _caption(rgb: np.ndarray, text: str, title: str):
    from PIL import Image, ImageDraw

    img = Image.fromarray(rgb)
    draw = ImageDraw.Draw(img)
    draw.rectangle((0, 0, img.width, 16), fill=(255, 255, 255))
    draw.text((4, 2), f"{title}   {text}", fill=(0, 0, 0))
    physics = _physics()
    legend = (("UAV", physics.UAV_RGBA), ("UGV", physics.UGV_RGBA), ("task open", TASK_OPEN),
              ("assigned", TASK_ASSIGNED))
    x = 4
    for label, rgba in legend:
        colour = tuple(int(255 * c) for c in rgba[:3])
        draw.rectangle((x, img.height - 13, x + 9, img.height - 4), fill=colour)
        draw.text((x + 12, img.height - 15), label, fill=(0, 0, 0))
        x += 14 + 7 * len(label) + 8
    return img


def _write(frames, out: Path, fps: int) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp{out.suffix}")
    if out.suffix.lower() == ".gif":
        frames[0].save(tmp, save_all=True, append_images=frames[1:],
                       duration=round(1000 / fps), loop=0, optimize=False)
    else:
        try:
            import imageio.v3 as iio
        except ImportError as e:
            raise ValueError("an .mp4 needs imageio and imageio-ffmpeg "
                             "(pip install imageio imageio-ffmpeg); a .gif needs neither") from e
        iio.imwrite(tmp, np.stack([np.asarray(f) for f in frames]), fps=fps,
                    extension=".mp4")
    tmp.replace(out)
