#!/usr/bin/env bash
# The final pairing, alone on the machine (any long run paused): the landed code before the one-kernel step
# (c0a0a95, a git worktree at $BASE) and this commit, full throughput.py at every batch size, one after the other;
# this commit with fused multiply-adds allowed (--xla_cpu_max_isa=AVX2 in XLA_FLAGS, which keeps our AVX flag out);
# then the profile by part and the report of what the step loop compiles to. Run from the repository root.
set -euo pipefail
here=benchmarks/results/one-kernel-20261207
BASE=${BASE:-/tmp/base}
(cd "$BASE" && env -u XLA_FLAGS PYTHONPATH="$BASE" "$OLDPWD/.venv/bin/python" benchmarks/throughput.py \
  --run "$OLDPWD/runs/table2" --json "$OLDPWD/$here/final-c0a0a95.json")
env -u XLA_FLAGS .venv/bin/python benchmarks/throughput.py --json $here/final-head.json
XLA_FLAGS=--xla_cpu_max_isa=AVX2 .venv/bin/python benchmarks/throughput.py --quick --batches 1 8 128 \
  --json $here/final-head-fma.json
env -u XLA_FLAGS .venv/bin/python benchmarks/profile.py --json $here/final-profile.json
env -u XLA_FLAGS .venv/bin/python benchmarks/kernels.py --learners 1 8 128 --ir 8 128 --json $here/final-kernels.json
