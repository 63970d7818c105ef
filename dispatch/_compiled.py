"""Compiled (numba) helpers of the kernel's per-trip hot path, and the decorators that compile.

:func:`leg_sums` turns a node path into a leg's cumulative seconds and metres (two per trip:
to the pickup, to the drop-off). It adds the edges one by one in path order, as
``itertools.accumulate`` and ``numpy.cumsum`` do, so the sums are the same floats bit for bit.
:func:`legs_at` says where driving vehicles are at a decision.

numba is imported when the first function compiles, never by importing this module: numba's
import and the loading of the first compiled function from its on-disk cache cost about 0.4 s
of CPU, many times what a ten-request run spends in these functions. So a function made by
:func:`kernel` runs as the plain Python it is written in (the same operations on the same
doubles: the same results bit for bit) while the process is young, and is compiled, or loaded
from numba's cache, once the process has spent :data:`INTERPRET_SECONDS` in such plain calls
or has compiled anything (numba then costs little more): a long run pays at most about that
much extra, a short one never pays for numba. :func:`jit` compiles at once (functions that
compiled code calls, in modules that compile anyway). Compiled code is cached on disk
(``cache=True``); where no cache directory is writable it is compiled in every process instead.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
import types

import numpy as np

#: CPU seconds of plain-Python calls of :func:`kernel` functions (and of their plain twins, see
#: :func:`charge`) after which a process compiles them: an eighth of what numba's import and
#: its first cache load cost, five times what a ten-request road run spends in them (about
#: 0.01 s), so a longer run pays at most this much before it compiles. (The calling thread's
#: CPU time: a loaded machine's waits do not count.)
INTERPRET_SECONDS = 0.05
_MODES = ("auto", "python", "compiled")
#: ``mode``: see :func:`set_mode`; ``spent``: plain-Python seconds so far; ``compiled``: whether
#: a kernel module has been handed to numba in this process
_state = {"mode": "auto", "spent": 0.0, "compiled": False}
_lock = threading.RLock()
#: id -> plain function compiled inline into its compiled callers (:func:`inline`)
_INLINE: dict = {}


def _options(**options):
    """``numba.njit(cache=True, **options)``, without the disk cache where none is writable."""
    import numba

    def wrap(fn):
        try:
            return numba.njit(cache=True, **options)(fn)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            return numba.njit(cache=False, **options)(fn)

    return wrap


def jit(fn):
    """``numba.njit(cache=True)``, without the disk cache where none is writable (imports numba
    now: for functions that compiled code calls, in modules that compile anyway)."""
    return _options()(fn)


def set_mode(mode: str) -> None:
    """Run :func:`kernel` functions as ``"python"`` or ``"compiled"`` from now on, or ``"auto"``
    (the default: plain Python for the process's first :data:`INTERPRET_SECONDS` of such calls,
    then compiled); the seconds spent count from zero again. The results are the same in every
    mode (tests compare them); a kernel once compiled stays so in ``"auto"``."""
    if mode not in _MODES:
        raise ValueError(f"kernel mode must be one of {_MODES}, not {mode!r}")
    with _lock:
        _state["mode"], _state["spent"] = mode, 0.0


def interpreting() -> bool:
    """Whether a :func:`kernel` function called now runs as plain Python; the plain twins of
    compiled searches (a planner's scipy search in place of its compiled one) follow the same
    choice."""
    mode = _state["mode"]
    if mode != "auto":
        return mode == "python"
    return (not _state["compiled"] and _state["spent"] < INTERPRET_SECONDS
            and "numba" not in sys.modules)


def charge(seconds: float) -> None:
    """Count ``seconds`` of CPU (``time.thread_time``) spent in a plain twin of a compiled
    function against :data:`INTERPRET_SECONDS` (the kernels' own plain calls count
    themselves)."""
    with _lock:
        _state["spent"] += seconds


def inline(fn):
    """``fn`` unchanged for Python callers; compiled into each compiled caller of its module
    (``numba.njit(inline="always")``, made when the module's :func:`kernel` functions are)."""
    _INLINE[id(fn)] = fn
    return fn


class Kernel:
    """A function numba compiles, called as the function: plain Python while
    :func:`interpreting` (where made with ``interpret=True``), else compiled (numba imported,
    and the function compiled or loaded from the disk cache, at the first such call).
    ``py_func`` is the plain function, :attr:`compiled` numba's dispatcher of it."""

    def __init__(self, fn, *, interpret: bool, **options) -> None:
        functools.update_wrapper(self, fn)
        self.py_func, self.interpret, self.options = fn, interpret, options
        self._compiled = None

    @property
    def compiled(self):
        """numba's dispatcher of the function (made now, with those of the other kernels of
        its module, if not yet; numba compiles each, or reads it from its cache, at its first
        call)."""
        if self._compiled is None:
            with _lock:
                if self._compiled is None:
                    _dispatchers(self.py_func.__globals__)
        return self._compiled

    def __call__(self, *args):
        if self.interpret and interpreting():
            t = time.thread_time()
            try:
                return self.py_func(*args)
            finally:
                charge(time.thread_time() - t)
        c = self._compiled
        return (self.compiled if c is None else c)(*args)


def kernel(fn=None, *, interpret: bool = True, **options):
    """Decorator: the function as a :class:`Kernel` (``@kernel``, or
    ``@kernel(interpret=False, nogil=True)``: ``options`` go to ``numba.njit``).
    ``interpret=False`` for loops the interpreter would run for seconds (a search over a whole
    city's network): compiled at the first call."""
    if fn is None:
        return lambda f: Kernel(f, interpret=interpret, **options)
    return Kernel(fn, interpret=interpret, **options)


def _dispatchers(names: dict) -> None:
    """Make numba's dispatchers of the kernels of the module whose globals are ``names``, each
    over a copy of those globals in which the module's kernels and :func:`inline` helpers are
    numba's (numba reads a function's globals: compiled code calls compiled code); a kernel of
    another module named there is its own module's dispatcher."""
    import numba

    _state["compiled"] = True
    seen = dict(names)
    mine = []
    for key, value in names.items():
        if isinstance(value, Kernel):
            if value.py_func.__globals__ is names:
                fn = value.py_func
                twin = types.FunctionType(fn.__code__, seen, fn.__name__, fn.__defaults__,
                                          fn.__closure__)
                seen[key] = _options(**value.options)(twin)
                mine.append((value, seen[key]))
            else:
                seen[key] = value.compiled
        elif _INLINE.get(id(value)) is value:
            seen[key] = numba.njit(inline="always")(value)
    for value, dispatcher in mine:
        value._compiled = dispatcher


@kernel
def leg_sums(indptr, indices, seconds, metres, nodes, t0, m0):  # pragma: no cover - compiled
    """``(times, metres, ok)`` of the path ``nodes`` in a CSR graph whose rows hold each
    node's out-edges (``indices``: heads; ``seconds`` / ``metres``: the edges' values):
    ``times[0] = t0``, ``times[i] = times[i - 1] + seconds`` of the edge ``nodes[i - 1] ->
    nodes[i]`` (likewise ``metres`` from ``m0``). ``ok`` is False when a step is not an edge
    (or names no node); the arrays are then meaningless."""
    k = nodes.size
    n = indptr.size - 1
    times = np.empty(k)
    out_m = np.empty(k)
    times[0] = t0
    out_m[0] = m0
    for i in range(1, k):
        u = nodes[i - 1]
        v = nodes[i]
        if u < 0 or u >= n:
            return times, out_m, False
        e = -1
        for j in range(indptr[u], indptr[u + 1]):
            if indices[j] == v:
                e = j
                break
        if e < 0:
            return times, out_m, False
        times[i] = times[i - 1] + seconds[e]
        out_m[i] = out_m[i - 1] + metres[e]
    return times, out_m, True


@kernel
def legs_at(times, nodes, length, prev, rows, now, starts, out_k, node, rem, out_i,
            on):  # pragma: no cover - compiled
    """Where vehicles driving legs are at ``now`` (:class:`dispatch.plan.en_route.LegTable`): for
    each ``q``, the leg in row ``rows[q]`` of ``times`` / ``nodes`` (its first ``length``
    entries; ``prev``: its start point's), started at ``starts[q]``: writes
    :meth:`dispatch.api.legs.Leg.next_at`'s ``(node, remaining)`` of ``now - starts[q]`` into
    ``node[out_k[q]]``, ``rem[out_k[q]]`` and whether it stands on the node into
    ``on[out_i[q]]``, by the same comparisons and subtractions (``max``, ``bisect_right``)."""
    for q in range(rows.size):
        r = rows[q]
        n = length[r]
        t = now - starts[q]
        k = out_k[q]
        if t >= times[r, n - 1]:
            node[k], rem[k], on[out_i[q]] = nodes[r, n - 1], 0.0, True
            continue
        if 0.0 > t:  # max(t, 0.0)
            t = 0.0
        lo, hi = 0, n  # bisect_right
        while lo < hi:
            mid = (lo + hi) // 2
            if t < times[r, mid]:
                hi = mid
            else:
                lo = mid + 1
        if lo == 0:
            left = times[r, 0] - t
            here = prev[r] < 0 or left <= 0.0
            node[k], rem[k], on[out_i[q]] = nodes[r, 0], 0.0 if here else left, here
        elif t == times[r, lo - 1]:
            node[k], rem[k], on[out_i[q]] = nodes[r, lo - 1], 0.0, True
        else:
            left = times[r, lo] - t
            node[k], rem[k], on[out_i[q]] = nodes[r, lo], left if left > 0.0 else 0.0, \
                left <= 0.0
    return 0
