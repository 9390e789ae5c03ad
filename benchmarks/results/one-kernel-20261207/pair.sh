#!/usr/bin/env bash
# Alternates the loop pass on and off (the results are bit-identical either way), alone on the machine:
# throughput.py --quick at every batch size, twice each.  Run from the repository root.
set -euo pipefail
here=benchmarks/results/one-kernel-20261207
for round in 1 2; do
  .venv/bin/python benchmarks/throughput.py --quick --batches 1 2 4 8 32 128 512 --json $here/threshold-on-$round.json
  XLA_FLAGS="--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1024" \
    .venv/bin/python benchmarks/throughput.py --quick --batches 1 2 4 8 32 128 512 --json $here/threshold-off-$round.json
done
