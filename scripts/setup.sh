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
    PYTHONWARNINGS=ignore .venv/bin/python -m pip install -q -e ".[test]" 2>&1 \
        | grep -vE "is ignored|^\s*$" || true
    .venv/bin/python -c "import dispatch, simpy, pybullet, scipy, pyarrow" >/dev/null
    rm -f .venv/.installed-*
    touch "$stamp"
fi
