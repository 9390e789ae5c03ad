"""The layout of a learner's random stream: the uniform draws of each step and what each one is for (model §5).

Every random quantity of training is a uniform draw in [0, 1) keyed by the learner's key and the step's index,
so a chunk of any length, a block of any size and the NumPy oracle all see the same stream.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config import Config
from reach_jax.env import task


def n_uniforms(cfg: Config) -> int:
    """Uniform draws one step consumes: 2 for the exploration noise, then one new trial's TrialDraws.

    The catch draw comes last: a longer draw leaves the earlier values unchanged (threefry is partitionable),
    so adding it left every earlier run's stream as it was.
    """
    return 2 + 2 + 2 * cfg.task.target_candidates + 2 + 1


def step_uniforms(key: jax.Array, first_step: jax.Array, n_steps: int, cfg: Config) -> jax.Array:
    """(n_steps, n_uniforms) draws in [0, 1) of one learner's steps first_step, first_step + 1, ...

    A step's draws depend only on the learner's key and the step's index, so blocks of any size (and
    chunks of any length) see the same stream.
    """
    return jax.vmap(lambda i: jax.random.uniform(jax.random.fold_in(key, i), (n_uniforms(cfg),)))(
        first_step + jnp.arange(n_steps)
    )


def split_uniforms(u: jax.Array, cfg: Config) -> tuple[jax.Array, task.TrialDraws]:
    """(n_uniforms,) draws in [0, 1) -> ((2,) noise draws in [-1, 1), TrialDraws of a possible new trial)."""
    k = cfg.task.target_candidates
    unit = 2.0 * u[:2] - 1.0
    draws = task.TrialDraws(
        start=u[2:4], target=u[4 : 4 + 2 * k].reshape(k, 2), force=u[4 + 2 * k : 6 + 2 * k], catch=u[6 + 2 * k]
    )
    return unit, draws
