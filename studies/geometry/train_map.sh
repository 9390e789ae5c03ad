#!/usr/bin/env bash
# Issue 62's geometry map on development seeds (studies/geometry/README.md): trains runs/geometry_map, or resumes it
# bit for bit from its newest checkpoint, then evaluates it (each visual field into eval/geometry_<k>/). Run from the
# repository root; resumable: a run that exists is resumed, an evaluated one is not evaluated again.
set -euo pipefail
py=${PYTHON:-.venv/bin/python}
run=runs/geometry_map
# One device: at 128 learners the native kernel ran faster on one core than sharded over two (docs/performance.md).
if [ -f "$run/config.json" ]; then
  "$py" -m reach_jax.train --resume "$run" --devices 1 --quiet
else
  "$py" -m reach_jax.train --config studies/geometry/map_config.json --trials 2e6 --seeds 2 --seed 777005 \
    --chunk-steps 200000 --devices 1 --out "$run" --quiet
fi
[ -f "$run/eval/geometries.json" ] || "$py" -m reach_jax.evaluate "$run"
