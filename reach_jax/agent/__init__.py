"""The agent layer: the 125-30-10-3 network, the TS actor-critic learner (eq. 1-3) and its exploration."""

from reach_jax.agent.exploration import actor_gain, noise, quiet, schedule, value_scale
from reach_jax.agent.learner import Pending, empty_pending, ts_step, ts_targets, ts_update, update_n_max
from reach_jax.agent.network import (
    ActorCritic,
    apply,
    dense_layers,
    init_params,
    pad_hidden,
    squash,
    symmetric_uniform,
    torque,
    unpad_hidden,
    with_dense_layers,
)

__all__ = [
    "ActorCritic",
    "Pending",
    "actor_gain",
    "apply",
    "dense_layers",
    "empty_pending",
    "init_params",
    "noise",
    "pad_hidden",
    "quiet",
    "schedule",
    "squash",
    "symmetric_uniform",
    "torque",
    "ts_step",
    "ts_targets",
    "ts_update",
    "unpad_hidden",
    "update_n_max",
    "value_scale",
    "with_dense_layers",
]
