"""The C heap's settings for a run: big per-decision arrays reuse the heap's memory.

A batched decision over a large fleet builds a few arrays of megabytes each (the cost matrix,
its copy in the problem, the allocator's work arrays) and frees them before the next one. glibc
serves a block that large with its own ``mmap`` and gives it back at ``free`` (or trims the
heap's top), so every decision page-faults its arrays in again: on a batched day of 10,000 taxis
(350 x 4,000 matrices every 30 s) that was a fifth of the process's CPU time, all in the kernel
(``sys``). :func:`keep_large_blocks` raises the size served by ``mmap`` to
``MMAP_THRESHOLD`` and the free top the heap keeps to ``TRIM_THRESHOLD``, so such blocks come
from (and return to) the heap. Allocation only: no number a run computes changes; the peak
memory stays about the same (the blocks were resident while in use either way).

It is process-wide and set once (each :class:`dispatch.decide.dispatcher.Dispatcher` asks); it does
nothing off glibc, or where the user set the heap's parameters through the environment
(``MALLOC_*_`` variables, ``GLIBC_TUNABLES``).
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys

log = logging.getLogger(__name__)

#: blocks below this many bytes come from the heap (glibc's own ceiling for it: 32 MiB)
MMAP_THRESHOLD = 32 << 20
#: free memory at the heap's top kept for the next decision instead of given back
TRIM_THRESHOLD = 128 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameter numbers (malloc.h)

_state: dict[str, bool] = {}


def keep_large_blocks() -> bool:
    """Set the heap's thresholds (see the module doc) once per process; True if they are set
    (now or before), False where it does nothing."""
    if "set" in _state:
        return _state["set"]
    _state["set"] = ok = _apply()
    return ok


def _apply() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    if "GLIBC_TUNABLES" in os.environ or any(
            k.startswith("MALLOC_") and k.endswith("_") for k in os.environ):
        return False  # the user's own heap settings stand
    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
        libc.gnu_get_libc_version  # glibc only (mallopt's parameters are glibc's)
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1 \
        and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    log.debug("heap: large blocks kept (%s)", "set" if ok else "refused")
    return ok
