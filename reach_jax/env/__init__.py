"""The environment layer: trials run, ended and restarted (`environment`), the task, curriculum, protocols and the
per-trial log."""

from reach_jax.env import curriculum, protocol, task, trial_log
from reach_jax.env.environment import (
    FAIL,
    OUT,
    OUTCOME_NAMES,
    SUCCESS,
    EnvParams,
    EnvState,
    Trial,
    TrialStatus,
    ended,
    env_params,
    next_trial,
    observe,
    observe_trial,
    reset,
    start_trial,
    step,
    step_trial,
)

__all__ = [
    "EnvParams",
    "EnvState",
    "FAIL",
    "OUT",
    "OUTCOME_NAMES",
    "SUCCESS",
    "Trial",
    "TrialStatus",
    "curriculum",
    "ended",
    "env_params",
    "next_trial",
    "observe",
    "observe_trial",
    "protocol",
    "reset",
    "start_trial",
    "step",
    "step_trial",
    "task",
    "trial_log",
]
