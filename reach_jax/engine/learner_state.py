"""What one learner carries from step to step: its agent, its environment and its counters (model §5).

Units: steps and trials are counts; N_max is in steps. Arrays carry no learner axis here; batches stack them.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax import env
from reach_jax.agent import learner, network
from reach_jax.config import Config, n_inputs
from reach_jax.env import protocol, task, trial_log
from reach_jax.physics import encoding


class Stats(NamedTuple):
    """Counters of trials that ended since the last reset (one chunk)."""

    trials: jax.Array  # () trials ended
    goals: jax.Array  # () ended at the goal
    outs: jax.Array  # () ended at a joint limit
    caps: jax.Array  # () ended at the safety cap
    trial_steps: jax.Array  # () summed length of the ended trials [steps]
    drifted: jax.Array  # () ended trials whose target drifted


def zero_stats() -> Stats:
    """All counters at zero."""
    return Stats(*(jnp.array(0, jnp.int32) for _ in Stats._fields))


@struct.dataclass
class AgentState:
    """The network and what its learning carries from step to step."""

    params: dict  # network parameters
    pending: learner.Pending  # the step awaiting its TS update
    pending_learning: jax.Array  # () bool: the block of the pending step's trial updates the weights
    n_max: jax.Array  # () N_max of eq. 3 [steps]


@struct.dataclass
class Counters:
    """Steps taken, and what the trials of this chunk did."""

    steps: jax.Array  # () steps taken since the start of training
    stats: Stats  # counters since the last chunk boundary


@struct.dataclass
class LearnerState:
    """Everything one learner carries from step to step."""

    key: jax.Array  # PRNG key of the learner's per-step draws (`random_stream`); fixed for its life
    agent: AgentState
    env: env.EnvState  # the trial under way, its condition and block, the curriculum, the trials ended
    counters: Counters
    trace: trial_log.TrialTrace | None = None  # this trial's movement so far; None without a per-trial log


def init_learner(key: jax.Array, plan: protocol.Plan, cfg: Config) -> LearnerState:
    """Fresh learner: new weights, first trial at the initial curriculum distance in its plan's first condition."""
    k_param, k_trial, k_run = jax.random.split(key, 3)
    draws = task.draw_trial(k_trial, cfg)
    state = env.reset(draws, plan, cfg)
    start = state.trial.arm
    rows = encoding.coded_support(start, start, jnp.zeros(2), cfg)
    return LearnerState(
        key=k_run,
        agent=AgentState(
            params=network.init_params(k_param, cfg),
            pending=learner.empty_pending(n_inputs(cfg), cfg.network.hidden[0], rows),
            pending_learning=state.block.learning,
            n_max=jnp.asarray(cfg.learner.n_max_init, dtype=float),  # strong-typed, as the chunk returns it
        ),
        env=state,
        counters=Counters(steps=jnp.array(0, jnp.int32), stats=zero_stats()),
        trace=trial_log.start_trace(start, state.trial.target, cfg) if cfg.train.trial_log_every else None,
    )


def without_params(state: LearnerState) -> LearnerState:
    """state with the network parameters left out (None)."""
    return state.replace(agent=state.agent.replace(params=None))
