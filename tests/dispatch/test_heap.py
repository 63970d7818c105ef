"""dispatch.heap: the heap's thresholds are set once per process, and never over the user's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PROBE = "from dispatch.heap import keep_large_blocks as k; print(k(), k())"


def _probe(extra_env: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items()
           if not (k.startswith("MALLOC_") or k == "GLIBC_TUNABLES")}
    env.update(extra_env, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_set_once_on_glibc():
    import platform

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("not glibc")
    assert _probe({}) == "True True"


def test_user_settings_stand():
    assert _probe({"MALLOC_TOP_PAD_": "0"}) == "False False"
    assert _probe({"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=0"}) == "False False"
