#!/usr/bin/env bash
# Train the paper's model by PPO from scratch for each N (issue 19), one command per
# checkpoint, one after the other on one thread; then compare with the shipped checkpoints on
# unseen seeds. Usage: scripts/train_paper_ppo.sh [N ...]   (default: 4 8 12 20)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
export OMP_NUM_THREADS=1
sizes=${*:-4 8 12 20}
for n in $sizes; do
  /usr/bin/time -f "N=$n wall %e s" "$PY" -m dispatch.run.cli train magnnet --variant paper \
    --agents "$n" --out "runs/train/paper_ppo_n$n"
done
args=()
for n in $sizes; do args+=("$n=runs/train/paper_ppo_n$n/model.pt"); done
"$PY" benchmarks/paper_ppo.py --count 50 --sizes $sizes --checkpoint "${args[@]}"
