"""Training: a pure compiled core over a batch of learners, and an impure shell that runs it in chunks.

`train.run(config)` (or `python -m reach_jax.train`, `train.cli`) trains cfg.train's conditions x seeds as one batch.
`prepare` checks the run and reads what it starts from; `chunks` runs the compiled chunks one after another and
checks that every learner is still finite; between chunks, sinks take each one on the host: metrics, checkpoints,
the progress bar. `health` names the learners that collapsed or fell back. Modules: `core` (the pure core), `loop`
(`chunks`, `run`), `prepare`, `metrics`, `health`, `sinks`, `progress`, `cli`. Units: trials, steps (of cfg.arm.dt
seconds), seconds.
"""

from reach_jax.train import health
from reach_jax.train.core import Finished, NumericsError, chunk_members, finite_learners, make_train, merge_members
from reach_jax.train.loop import chunks, dispatch, numerics_error, run
from reach_jax.train.metrics import hyper_values, metrics_rows, status_line, trial_records
from reach_jax.train.prepare import Prepared, begin, default_run_dir, prepare
from reach_jax.train.progress import LearnerEta, Progress, pow2_batch
from reach_jax.train.sinks import CheckpointSink, MetricsSink, ProgressSink, Sink

__all__ = [
    "CheckpointSink",
    "Finished",
    "LearnerEta",
    "MetricsSink",
    "NumericsError",
    "Prepared",
    "Progress",
    "ProgressSink",
    "Sink",
    "begin",
    "chunk_members",
    "chunks",
    "default_run_dir",
    "dispatch",
    "finite_learners",
    "health",
    "hyper_values",
    "make_train",
    "merge_members",
    "metrics_rows",
    "numerics_error",
    "pow2_batch",
    "prepare",
    "run",
    "status_line",
    "trial_records",
]
