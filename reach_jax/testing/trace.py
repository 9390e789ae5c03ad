"""A compiled run of one learner that keeps what every step did, for tests and plots (model §5)."""

from __future__ import annotations

import jax

from reach_jax.config import Config
from reach_jax.config.schema import DEFAULT_SPEED, Speed
from reach_jax.engine import chunk, rollout


def make_trace(cfg: Config, n_steps: int, speed: Speed = DEFAULT_SPEED):
    """Compiled `(state, plan, hyper) -> (state, StepInfo stacked over n_steps)` of one learner."""

    def trace(state, plan, hyper):
        def step_body(carry, u):
            new, info = rollout.learner_step(carry[0], u, plan, hyper, cfg, speed=speed)
            return (new, None), info

        state, _, info = chunk.scan_steps(step_body, state, n_steps, cfg, speed=speed)
        return state, info

    return jax.jit(trace)
