"""What one learner carries from step to step: its agent, its environment and its counters (model §5).

Units: steps and trials are counts; N_max is in steps. Arrays carry no learner axis here; batches stack them.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from reach_jax import env
from reach_jax.agent import learner, network
from reach_jax.config import Config, n_inputs
from reach_jax.env import protocol, task, trial_log


class Stats(NamedTuple):
    """Counters of trials that ended and steps taken since the last reset (one chunk)."""

    trials: jax.Array  # () trials ended
    goals: jax.Array  # () ended at the goal
    outs: jax.Array  # () ended at a joint limit
    caps: jax.Array  # () ended at the safety cap
    trial_steps: jax.Array  # () summed length of the ended trials [steps]
    drifted: jax.Array  # () ended trials whose target drifted
    clean_goals: jax.Array  # () ended at the goal without drift
    gate_open: jax.Array  # () ended trials run with the drift gate open (`curriculum.drift_open`)
    steps: jax.Array  # () steps taken
    saturated: jax.Array  # () actor outputs beyond cfg.train.saturated_output, two per step
    starts: jax.Array  # () steps that began a trial
    start_value: jax.Array  # () summed critic value p at those steps (float)


def zero_stats() -> Stats:
    """All counters at zero."""
    counts = {name: jnp.array(0, jnp.int32) for name in Stats._fields}
    return Stats(**{**counts, "start_value": jnp.zeros((), float)})  # strong-typed, as the chunk returns it


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
    return LearnerState(
        key=k_run,
        agent=AgentState(
            params=network.init_params(k_param, cfg),
            pending=learner.empty_pending(n_inputs(cfg), cfg.network.hidden[0]),
            pending_learning=state.block.learning,
            n_max=jnp.asarray(cfg.learner.n_max_init, dtype=float),  # strong-typed, as the chunk returns it
        ),
        env=state,
        counters=Counters(steps=jnp.array(0, jnp.int32), stats=zero_stats()),
        trace=trial_log.start_trace(start, state.trial.target, cfg) if cfg.train.trial_log_every else None,
    )


def mechanism_columns(states: LearnerState, cfg: Config) -> dict[str, list]:
    """Per-learner chunk measures of the drift and learning mechanism (model §5), None where nothing was counted.

    clean_rate: share of ended trials at the goal without drift; clean_margin: that share less the drift-aided
    successes' and the outs'; gate_open_rate: share run with the drift gate open; failure: the gate's failure share
    now; saturated_rate: share of actor outputs beyond cfg.train.saturated_output; start_value: mean critic value at
    a trial's first step; w<i>_norm: Frobenius norm of layer i's kernel now. failure and w<i>_norm are np.float32,
    the shares and start_value float.

    Args:
      states: every learner after the chunk, learner axis first (host arrays).
      cfg: the run's config.
    """
    s = jax.tree.map(np.asarray, states.counters.stats)
    trials, steps, starts = (np.maximum(x, 1) for x in (s.trials, s.steps, s.starts))
    n_actor = cfg.network.n_out - 1
    columns = {
        "clean_rate": (s.clean_goals / trials, s.trials),
        "clean_margin": ((2 * s.clean_goals - s.goals - s.outs) / trials, s.trials),
        "gate_open_rate": (s.gate_open / trials, s.trials),
        "saturated_rate": (s.saturated / (n_actor * steps), s.steps),
        "start_value": (s.start_value / starts, s.starts),
    }
    out = {name: [float(v) if n else None for v, n in zip(*pair, strict=True)] for name, pair in columns.items()}
    # Measures of float32 state stay np.float32, so that the metrics row can write them at float32 precision.
    out["failure"] = list(np.asarray(states.env.curriculum.failure, np.float32))
    for i, (kernel, _) in enumerate(network.dense_layers(states.agent.params), 1):
        kernel = np.asarray(kernel)
        out[f"w{i}_norm"] = list(np.linalg.norm(kernel.reshape(len(kernel), -1), axis=1).astype(np.float32))
    return out


def without_params(state: LearnerState) -> LearnerState:
    """state with the network parameters left out (None)."""
    return state.replace(agent=state.agent.replace(params=None))
