#!/bin/bash
# The real training loop, HEAD (8112324) with its defaults, HEAD with the actor targets unclipped (the version-9 recipe), and dd39cb5 (config version 9) with its defaults; alternated, alone on the machine. Run from the repository; /tmp/old9 is a worktree of dd39cb5.
for r in 1 2; do
  cd /work/main && PYTHONPATH=/work/main .venv/bin/python -m reach_jax.train --trials 30000 --seeds 2 --out /tmp/pair/head-$r > /tmp/pair/head-$r.log 2>&1
  cd /work/main && PYTHONPATH=/work/main .venv/bin/python -m reach_jax.train --trials 30000 --seeds 2 --set learner.actor_target_bound=0.0 --out /tmp/pair/headv9-$r > /tmp/pair/headv9-$r.log 2>&1
  cd /tmp/old9 && PYTHONPATH=/tmp/old9 /work/main/.venv/bin/python -m reach_jax.train --trials 30000 --seeds 2 --out /tmp/pair/old9-$r > /tmp/pair/old9-$r.log 2>&1
done
