#!/usr/bin/env bash
# Sets everything up and runs the paper's static scenario (Tables I and III), writing Parquet.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# --force: the script rewrites its own results folder (runs/paper_static) on every call
exec .venv/bin/dispatch run scenarios/paper_static.toml --force "$@"
