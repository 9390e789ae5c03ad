#!/usr/bin/env bash
# The landed code before the one-kernel step (c0a0a95, a git worktree at $BASE) against this commit, alternated,
# alone on the machine: throughput.py --quick at every batch size, twice each. Run from the repository root.
set -euo pipefail
here=benchmarks/results/one-kernel-20261207
BASE=${BASE:-/tmp/base}
for round in 1 2; do
  (cd "$BASE" && env -u XLA_FLAGS PYTHONPATH="$BASE" "$OLDPWD/.venv/bin/python" benchmarks/throughput.py --quick \
    --batches 1 2 4 8 32 128 512 --run "$OLDPWD/runs/table2" --json "$OLDPWD/$here/c0a0a95-$round.json")
  env -u XLA_FLAGS .venv/bin/python benchmarks/throughput.py --quick --batches 1 2 4 8 32 128 512 \
    --json $here/head-$round.json
done
