#!/usr/bin/env bash
# The plan's two held-out runs (studies/frame/PLAN.md), one after the other on both cores, each evaluated as it ends,
# then the verdict. Run from the repository root; resumable: a run that exists is resumed, an evaluated one skipped.
set -euo pipefail
py=${PYTHON:-.venv/bin/python}
common=(--trials 2e6 --seeds 8 --seed 20261207 --chunk-steps 400000 --conditions none,viscous,viscous_mirror,random,random_nopast)
train() {  # train RUN [FLAGS...]: start it, or resume it if it holds a run
  local run=$1; shift
  if [ -f "$run/config.json" ]; then "$py" -m reach_jax.train --resume "$run" --quiet
  else "$py" -m reach_jax.train "${common[@]}" "$@" --out "$run" --quiet; fi
  [ -f "$run/eval/claims.json" ] || "$py" -m reach_jax.evaluate "$run"
}
train runs/frame_default
train runs/frame_constant --config recipes/constant_exploration.json
"$py" studies/frame/verdict.py runs/frame_default runs/frame_constant --out studies/frame/verdict
