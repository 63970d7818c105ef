"""Our 26-connected A* reproduces the MovingAI 3D voxel benchmark (Warframe map A1).

The map is 896 x 390 x 255 = 89 million voxels: a bool grid, and :func:`planners.graph.astar`
reads moves from the occupancy (no per-voxel move masks). The movement model of the benchmark
is ours (see the data's PROVENANCE): 26-connected, steps of 1, sqrt 2, sqrt 3, every voxel of a
step's bounding box free. The default run checks a deterministic sample of short problems (and
one path cell by cell); ``-m slow`` checks problems spread over the whole length range.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dispatch.api.motion import check_path, path_length
from dispatch.api.voxels import Grid
from planners import graph as G
from tests.conftest import missing_data

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "movingai_3d"
MAP = DATA / "A1.3dmap"
SCEN = DATA / "A1.3dmap.3dscen"

needs_data = pytest.mark.skipif(not (MAP.is_file() and SCEN.is_file()),
                                reason=missing_data(DATA, "the MovingAI 3D map A1"))


def load_voxels(path: Path) -> Grid:
    """A ``.3dmap``: first line ``voxel X Y Z``, then one ``x y z`` line per blocked voxel."""
    head, body = path.read_text().split("\n", 1)
    kind, *dims = head.split()
    assert kind == "voxel" and len(dims) == 3
    shape = tuple(int(v) for v in dims)
    xyz = np.array(body.split(), dtype=np.int64).reshape(-1, 3)
    occ = np.zeros(shape, dtype=bool)
    occ[xyz[:, 0], xyz[:, 1], xyz[:, 2]] = True
    return Grid(occ, 1.0)


def load_problems(path: Path) -> np.ndarray:
    """Rows ``sx sy sz gx gy gz optimal ratio`` as an ``(n, 8)`` float array, file order."""
    lines = path.read_text().splitlines()
    assert lines[0].startswith("version")
    return np.array([ln.split() for ln in lines[2:] if ln.strip()], dtype=float)


@pytest.fixture(scope="module")
def voxels():
    return load_voxels(MAP)


@pytest.fixture(scope="module")
def problems():
    return load_problems(SCEN)


def check(grid: Grid, rows: np.ndarray, with_path: bool = False) -> int:
    for r in rows:
        start = tuple(int(v) for v in r[:3])
        goal = tuple(int(v) for v in r[3:6])
        length, path = G.astar(grid, start, goal, True)
        assert path is not None, (start, goal)
        assert abs(length - r[6]) < 1e-4, (start, goal, length, r[6])
        assert path[0] == start and path[-1] == goal
        if with_path:
            check_path(grid, path, True)
            assert abs(path_length(path) - r[6]) < 1e-4
    return len(rows)


def sample(problems: np.ndarray, count: int, max_length: float, min_length: float = 0.0):
    """``count`` problems with ``min_length < length <= max_length``, spread over the file."""
    idx = np.flatnonzero((problems[:, 6] > min_length) & (problems[:, 6] <= max_length))
    return problems[idx[np.linspace(0, len(idx) - 1, num=count).round().astype(int)]]


@needs_data
def test_map_and_problems_load(voxels, problems):
    assert voxels.shape == (896, 390, 255)
    assert int(voxels.occupied.sum()) == 123_236
    assert problems.shape == (5000, 8)
    # the listed ratio is optimal / octile: the 3D octile distance of motion.octile
    from dispatch.api.motion import octile

    r = problems[0]
    assert r[6] / octile(tuple(r[:3]), tuple(r[3:6])) == pytest.approx(r[7], abs=1e-3)


@needs_data
def test_short_problems(voxels, problems):
    assert check(voxels, sample(problems, 24, max_length=60.0), with_path=True) == 24


@needs_data
def test_medium_problems(voxels, problems):
    assert check(voxels, sample(problems, 6, max_length=150.0, min_length=60.0)) == 6


@needs_data
def test_sample_includes_detours(voxels, problems):
    """The sample is not all straight shots: some optimal paths are longer than octile."""
    rows = sample(problems, 24, max_length=60.0)
    octile_only = [abs(r[7] - 1.0) < 1e-9 for r in rows]
    assert not all(octile_only)  # some problems need detours around voxels


@needs_data
def test_blocked_and_out_of_bounds_endpoints(voxels):
    blocked = tuple(int(v) for v in np.argwhere(voxels.occupied[:80, :90, :70])[0])
    free = (101, 109, 191)
    assert not voxels.occupied[free]
    assert G.astar(voxels, free, blocked, True) == (math.inf, None)
    assert G.astar(voxels, (-1, 0, 0), free, True) == (math.inf, None)
    assert G.astar(voxels, free, free, True) == (0.0, [free])


@pytest.mark.slow
@needs_data
@pytest.mark.parametrize("part", range(4))
def test_spread_of_problems(voxels, problems, part):
    """Every 25th problem (200 in all, short to 900 voxels long), in four parts."""
    rows = problems[::25][part::4]
    assert check(voxels, rows) == len(rows)
