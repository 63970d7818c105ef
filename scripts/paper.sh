#!/usr/bin/env bash
# Sets everything up and runs the paper's static scenario (Tables I and III), writing Parquet.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# --overwrite: the script reruns and rewrites its own results folder (runs/paper_static) on
# every call (without it, runs already there would be shown from the folder, not rerun)
exec .venv/bin/dispatch run scenarios/paper_static.toml --overwrite "$@"
