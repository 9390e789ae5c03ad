#!/usr/bin/env bash
# Issue 62's held-out geometry run (studies/geometry/PLAN.md): trains runs/geometry_heldout on both cores, or resumes it
# bit for bit from its newest checkpoint, then evaluates it (each visual field into eval/geometry_<k>/) and applies
# the plan's rule. Run from the repository root; resumable: a run that exists is resumed, an evaluated one is not
# evaluated again.
set -euo pipefail
py=${PYTHON:-.venv/bin/python}
run=runs/geometry_heldout
if [ -f "$run/config.json" ]; then
  "$py" -m reach_jax.train --resume "$run" --quiet
else
  "$py" -m reach_jax.train --config studies/geometry/heldout_config.json --trials 2e6 --seeds 8 --seed 20261208 \
    --chunk-steps 200000 --out "$run" --quiet
fi
[ -f "$run/eval/geometries.json" ] || "$py" -m reach_jax.evaluate "$run"
"$py" studies/geometry/verdict.py "$run" --out studies/geometry/verdict
