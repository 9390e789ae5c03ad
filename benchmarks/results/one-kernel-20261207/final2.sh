#!/usr/bin/env bash
# A second round right after final.sh, --quick, in the other order (this commit first), for the machine's drift.
set -euo pipefail
here=benchmarks/results/one-kernel-20261207
BASE=${BASE:-/tmp/base}
env -u XLA_FLAGS .venv/bin/python benchmarks/throughput.py --quick --json $here/final2-head.json
(cd "$BASE" && env -u XLA_FLAGS PYTHONPATH="$BASE" "$OLDPWD/.venv/bin/python" benchmarks/throughput.py --quick \
  --run "$OLDPWD/runs/table2" --json "$OLDPWD/$here/final2-c0a0a95.json")
