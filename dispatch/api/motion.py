"""Movement rules shared by every planner, the vehicles and the checks.

UAVs move in 3D, 26-connected: a step changes 1, 2 or 3 coordinates by one cell and has length
1, sqrt(2) or sqrt(3) cells. UGVs move on the ground layer (k = 0), 8-connected, steps of 1 or
sqrt(2) cells. A step is legal only if *every* cell of its bounding box is free (the MovingAI
rule: no corner or edge cutting), so a 2-D diagonal needs both orthogonal neighbours free and a
3-D diagonal the whole 2x2x2 block.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from dispatch.api.voxels import Grid
from dispatch.locations import Cell

#: 26 neighbour offsets in 3D, ordered lexicographically.
OFFSETS_3D: tuple[Cell, ...] = tuple(
    d for d in itertools.product((-1, 0, 1), repeat=3) if d != (0, 0, 0)
)
#: 8 neighbour offsets on the ground layer (dz = 0).
OFFSETS_2D: tuple[Cell, ...] = tuple(d for d in OFFSETS_3D if d[2] == 0)


def offsets(flies: bool) -> tuple[Cell, ...]:
    """The neighbour offsets of a vehicle that flies (UAV) or drives (UGV)."""
    return OFFSETS_3D if flies else OFFSETS_2D


def step_length(a: Cell, b: Cell) -> float:
    """Length in cells of the step from ``a`` to ``b`` (1, sqrt 2 or sqrt 3)."""
    return math.sqrt(sum(abs(x - y) for x, y in zip(a, b)))


def step_is_legal(grid: Grid, a: Cell, b: Cell, flies: bool) -> bool:
    """True if a vehicle may step from ``a`` to the neighbouring cell ``b``."""
    d = tuple(y - x for x, y in zip(a, b))
    if max(abs(v) for v in d) != 1 or not grid.in_bounds(b) or not grid.in_bounds(a):
        return False
    if not flies and (a[2] != 0 or b[2] != 0):
        return False
    lo = tuple(min(x, y) for x, y in zip(a, b))
    hi = tuple(max(x, y) + 1 for x, y in zip(a, b))
    return not grid.occupied[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]].any()


def path_length(path: list[Cell]) -> float:
    """Length in cells of a path given as consecutive cells."""
    return sum(step_length(a, b) for a, b in zip(path, path[1:]))


def check_path(grid: Grid, path: list[Cell], flies: bool) -> None:
    """Raise ValueError unless every step of ``path`` is legal for the vehicle kind."""
    if not path:
        raise ValueError("empty path")
    if not grid.is_free(path[0]):
        raise ValueError(f"path starts in a blocked cell {path[0]}")
    for a, b in zip(path, path[1:]):
        if not step_is_legal(grid, a, b, flies):
            raise ValueError(f"illegal step {a} -> {b} for a {'UAV' if flies else 'UGV'}")


def octile(a: Cell, b: Cell) -> float:
    """Exact obstacle-free 26-connected (or 8-connected in a plane) distance in cells.

    Admissible and consistent for A*: sorted absolute deltas d1 >= d2 >= d3 give
    ``(sqrt3 - sqrt2) d3 + (sqrt2 - 1) d2 + d1``.
    """
    d = sorted((abs(a[0] - b[0]), abs(a[1] - b[1]), abs(a[2] - b[2])), reverse=True)
    return (math.sqrt(3) - math.sqrt(2)) * d[2] + (math.sqrt(2) - 1) * d[1] + d[0]


def as_array(cells) -> np.ndarray:
    """Cells as an ``(n, 3)`` int64 array."""
    return np.asarray(cells, dtype=np.int64).reshape(-1, 3)


#: Seconds by which two reservations of one cell may overlap without conflicting (float noise;
#: :func:`occupancy`).
EPS = 1e-9


def step_seconds(a: Cell, b: Cell, speed: float, cell_m: float) -> float:
    """Duration of the step ``a -> b`` at ``speed`` m/s with cells of ``cell_m`` metres."""
    return step_length(a, b) * cell_m / speed


def step_box(a: Cell, b: Cell) -> list[Cell]:
    """Every cell of the bounding box of the step ``a -> b`` (both ends included), C order."""
    ranges = [range(min(x, y), max(x, y) + 1) for x, y in zip(a, b)]
    return [c for c in itertools.product(*ranges)]  # type: ignore[misc]


# ----------------------------------------------------------------------------- timed routes

Route = list[tuple[float, Cell]]


def overlaps(s1: float, e1: float, s2: float, e2: float) -> bool:
    """Whether ``[s1, e1)`` and ``[s2, e2)`` overlap by more than :data:`EPS`."""
    return s1 < e2 - EPS and s2 < e1 - EPS


def occupancy(route: Route, speed: float, cell_m: float) -> list[tuple[Cell, float, float]]:
    """The reservations ``(cell, start, end)`` of a timed route (the one definition of the time
    model: the kernel, planners and tests all use it).

    A *timed route* is a list ``[(t0, c0), (t1, c1), ..., (tn, cn)]`` of cells and the times the
    vehicle is *in* them: it stands in ``c0`` from ``t0``, and step ``i`` (``c_{i-1} -> c_i``, a
    legal move) takes ``d_i = step length x cell size / speed`` seconds and ends at ``t_i``; it
    starts at ``t_i - d_i >= t_{i-1}`` (the difference is a wait in ``c_{i-1}``). Reservations
    are half-open intervals ``[start, end)`` of continuous time on cells:

    * a cell a vehicle stands in is held from when it started entering it until the end of the
      step that leaves it;
    * during a step the vehicle holds every cell of the step's bounding box (from cell, to cell
      and, for a diagonal, the corner cells it sweeps past: the same box that must be free of
      obstacles), so two vehicles can never cross diagonals in one 2x2 block; a head-on swap
      (``A -> B`` while another goes ``B -> A`` at overlapping times) holds both cells twice and
      is a conflict like any other;
    * the route's last cell is held to infinity: a vehicle that arrives, serves, goes idle (or
      never had a task) stands where it is, holding its cell until it is given a route again.
      So a plan may end only in a cell nobody else reserves later.

    Two reservations conflict when they share a cell and overlap by more than :data:`EPS`
    seconds (:func:`overlaps`: a vehicle may enter a cell at the instant another's step out of
    it ends).
    """
    out: list[tuple[Cell, float, float]] = []
    since = route[0][0]
    for (_, a), (t, b) in zip(route, route[1:]):
        dep = t - step_seconds(a, b, speed, cell_m)
        out.append((a, since, t))
        out.extend((c, dep, t) for c in step_box(a, b) if c != a and c != b)
        since = dep
    out.append((route[-1][1], since, math.inf))
    return out
