"""The reservation table: who holds which cell when (reservation-based execution,
:mod:`dispatch.plan.traffic`), and a planner's read-only view of it.

A reservation is a half-open interval ``[start, end)`` of continuous time on one cell, held by
one vehicle; the reservations of a timed route are its
:func:`~dispatch.api.motion.occupancy` (the time model) and two conflict when they
:func:`~dispatch.api.motion.overlaps`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple

from dispatch.api.motion import EPS, Route, overlaps, step_is_legal, step_seconds
from dispatch.locations import Cell


def route_error(grid, route: Route, flies: bool, speed: float) -> str | None:
    """Why ``route`` is not a legal timed route of a vehicle, or None."""
    if not route:
        return "empty route"
    for (t0, a), (t1, b) in zip(route, route[1:]):
        if not step_is_legal(grid, a, b, flies):
            return f"illegal step {a} -> {b}"
        if t1 - t0 < step_seconds(a, b, speed, grid.cell) - EPS:
            return f"step {a} -> {b} from t={t0} to t={t1} is faster than {speed} m/s"
    return None


class Entry(NamedTuple):
    """One reservation of one cell: ``[start, end)`` held by vehicle ``owner``. ``committed``
    marks the step the vehicle is executing (it cannot be taken back)."""

    start: float
    end: float
    owner: int
    committed: bool


class ReservationTable:
    """Reservations per cell, and per owner so that an owner's can be replaced at once."""

    def __init__(self) -> None:
        self._cells: dict[Cell, list[Entry]] = {}
        self._owned: dict[int, list[tuple[Cell, Entry]]] = {}

    def add(self, owner: int, cells: Iterable[tuple[Cell, float, float]],
            committed: bool = False) -> None:
        mine = self._owned.setdefault(owner, [])
        for cell, start, end in cells:
            if end - start <= EPS:
                continue
            e = Entry(start, end, owner, committed)
            self._cells.setdefault(cell, []).append(e)
            mine.append((cell, e))

    def clear(self, owner: int) -> None:
        """Drop every reservation of ``owner``."""
        for cell, e in self._owned.pop(owner, ()):
            entries = self._cells[cell]
            entries.remove(e)
            if not entries:
                del self._cells[cell]

    def at(self, cell: Cell) -> list[Entry]:
        """The reservations of one cell (read-only by convention)."""
        return self._cells.get(cell, [])

    def owned(self, owner: int) -> list[tuple[Cell, Entry]]:
        return list(self._owned.get(owner, ()))

    def view(self, include: Callable[[Entry], bool], t0: float,
             extra: dict[Cell, list[tuple[float, float]]] | None = None) -> TableView:
        """The reservations ``include`` keeps (and the ``extra`` intervals per cell), as a
        planner sees them from time ``t0`` on."""
        return TableView(self, include, t0, extra or {})


class TableView:
    """A read-only view of a :class:`ReservationTable` for a planner (the
    :class:`dispatch.api.contracts.Reservations` protocol): :meth:`blocked` gives the sorted,
    merged intervals of the kept reservations of a cell that end after ``t0``."""

    def __init__(self, table: ReservationTable, include: Callable[[Entry], bool],
                 t0: float, extra: dict[Cell, list[tuple[float, float]]]) -> None:
        self._table, self._include, self.t0, self._extra = table, include, t0, extra
        self._cache: dict[Cell, tuple[tuple[float, float], ...]] = {}

    def blocked(self, cell: Cell) -> tuple[tuple[float, float], ...]:
        hit = self._cache.get(cell)
        if hit is None:
            spans = [(e.start, e.end) for e in self._table.at(cell)
                     if e.end > self.t0 + EPS and self._include(e)]
            spans.extend(iv for iv in self._extra.get(cell, ()) if iv[1] > self.t0 + EPS)
            spans.sort()
            merged: list[list[float]] = []
            for s, e in spans:
                if merged and s <= merged[-1][1] + EPS:
                    merged[-1][1] = max(merged[-1][1], e)
                else:
                    merged.append([s, e])
            hit = self._cache[cell] = tuple((s, e) for s, e in merged)
        return hit

    def conflicts(self, cells: Iterable[tuple[Cell, float, float]]) -> bool:
        """Whether any of ``cells``' reservations overlaps a kept one."""
        return any(overlaps(s, e, a, b) for c, s, e in cells for a, b in self.blocked(c))
