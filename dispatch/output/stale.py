"""Temporary files a killed writer left behind.

Every file of a results folder is written under a temporary name ``.<name>.tmp-<pid>`` and
renamed when whole (atomic); a process killed in between leaves its temporary file, which no
reader opens (the leading ``.``) but which would stay in the folder for good."""

from __future__ import annotations

import os
from pathlib import Path


def remove_stale_temps(path: Path) -> int:
    """Remove the temporary files of ``path`` (``.<name>.tmp-<pid>``) that processes no longer
    running left behind (killed mid-write); a live writer's file is kept. Returns how many."""
    gone = 0
    for tmp in path.parent.glob(f".{path.name}.tmp-*"):
        try:
            pid = int(tmp.name.rsplit("-", 1)[1])
        except ValueError:
            continue
        if pid != os.getpid() and _alive(pid):
            continue
        tmp.unlink(missing_ok=True)
        gone += 1
    return gone


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # (another user's process: alive)
        return True
    return True
