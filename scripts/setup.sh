#!/usr/bin/env bash
# Creates .venv (if missing) and installs the project with its test extras, saying each step
# (what it installs, step N of 5, seconds taken) so that a first set-up is seen to move.
# Idempotent: reinstalls only when pyproject.toml changed since the last successful install.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
STEPS=5
started=$SECONDS
step_start=$SECONDS

# step N "what": one line on stderr before a step; done_step: its time
step() {
    step_start=$SECONDS
    echo "setup [$1/$STEPS] ${*:2}" >&2
}
done_step() {
    echo "setup       done in $((SECONDS - step_start)) s" >&2
}
# pip install ARGS: one line per package pip collects ("setup       numpy>=1.26"), so a long
# step is seen to move; the rest of pip's output is left out, its errors (stderr) are not,
# but for the build back end's notes on editable installs ("... is ignored"), noise here.
pip_install() {
    .venv/bin/python -m pip install --progress-bar off "$@" \
        2> >(grep -v "is ignored" >&2) \
        | sed -nE 's/^Collecting ([^ ]+).*/setup       \1/p' >&2
}

stamp=.venv/.installed-$(sha1sum pyproject.toml | cut -c1-16)
if [ ! -f "$stamp" ]; then
    echo "setup: installing into .venv (first time, or pyproject.toml changed); about 3.5 min" \
         "on 2 cores with an empty pip cache, most of it step 3" >&2
    step 1 "virtual environment .venv ($("$PY" --version 2>&1))"
    if [ ! -x .venv/bin/python ]; then
        "$PY" -m venv .venv
    fi
    .venv/bin/python -m pip install -q --upgrade pip 2> >(grep -v "is ignored" >&2)
    done_step
    # torch first, pinned: the magnnet extra pins the same version, so nothing below resolves
    # torch again (another version would pull gigabytes of CUDA libraries).
    step 2 "torch 2.13.0 (MAGNNET's network; the largest download)"
    pip_install "torch==2.13.0"
    done_step
    step 3 "this project (editable), its test and magnnet extras: about 100 packages" \
           "(numpy, simpy, pybullet, pyarrow, pandas, matplotlib, ray, ...), one line each"
    PYTHONWARNINGS=ignore pip_install -e ".[test,magnnet]"
    done_step
    step 4 "checking the imports (dispatch, simpy, pybullet, scipy, pyarrow, torch, pettingzoo)"
    # (PyBullet prints its build time on stderr when imported: left out, its errors are not)
    .venv/bin/python -c "import dispatch, simpy, pybullet, scipy, pyarrow, torch, pettingzoo" \
        >/dev/null 2> >(grep -v "^pybullet build time" >&2)
    rm -f .venv/.installed-*
    touch "$stamp"
    done_step
fi
# The replay's browser tests (tests/analysis/test_replay_browser.py) drive Debian's chromium
# through Playwright (no browser download); where it cannot be installed they skip, naming it.
if [ ! -x /usr/bin/chromium ]; then
    if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
        step 5 "Debian's chromium (apt-get; the replay's browser tests)"
        if { apt-get install -y -q chromium || { apt-get update -q && apt-get install -y -q chromium; }; } \
            >/dev/null 2>&1; then
            done_step
        else
            echo "setup: apt-get install chromium failed: the replay's browser tests will skip" >&2
        fi
    else
        echo "setup: no /usr/bin/chromium (Debian package 'chromium'; run: sudo apt-get install" \
             "chromium): the replay's browser tests will skip" >&2
    fi
fi
if [ $((SECONDS - started)) -gt 0 ]; then
    echo "setup: ready in $((SECONDS - started)) s (.venv)" >&2
fi
