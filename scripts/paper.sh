#!/usr/bin/env bash
# Sets everything up and runs the paper's static scenario (Tables I and III), writing Parquet.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/dispatch run scenarios/paper_static.toml "$@"
