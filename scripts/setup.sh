#!/usr/bin/env bash
# Creates .venv (if missing) and installs the project with its test extras.
# Idempotent: reinstalls only when pyproject.toml changed since the last successful install.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
stamp=.venv/.installed-$(sha1sum pyproject.toml | cut -c1-16)
if [ ! -f "$stamp" ]; then
    .venv/bin/python -m pip install -q --upgrade pip 2>&1 | grep -v "is ignored" || true
    # Build-backend chatter about editable installs is noise for a newcomer; errors still show.
    # torch first, pinned: the magnnet extra pins the same version, so nothing below resolves
    # torch again (another version would pull gigabytes of CUDA libraries).
    .venv/bin/python -m pip install -q "torch==2.13.0" 2>&1 | grep -vE "is ignored|^\s*$" || true
    PYTHONWARNINGS=ignore .venv/bin/python -m pip install -q -e ".[test,magnnet]" 2>&1 \
        | grep -vE "is ignored|^\s*$" || true
    .venv/bin/python -c "import dispatch, simpy, pybullet, scipy, pyarrow, torch, pettingzoo" >/dev/null
    rm -f .venv/.installed-*
    touch "$stamp"
fi
# The replay's browser tests (tests/analysis/test_replay_browser.py) drive Debian's chromium
# through Playwright (no browser download); where it cannot be installed they skip, naming it.
if [ ! -x /usr/bin/chromium ]; then
    if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
        { apt-get install -y -q chromium || { apt-get update -q && apt-get install -y -q chromium; }; } \
            >/dev/null 2>&1 \
            || echo "setup: apt-get install chromium failed: the replay's browser tests will skip"
    else
        echo "setup: no /usr/bin/chromium (Debian package 'chromium'; run: sudo apt-get install" \
             "chromium): the replay's browser tests will skip"
    fi
fi
