"""Per-trial movement measures that adaptation studies plot, gathered in the compiled step, and their buffer (§12).

Units: positions and errors [m], angles [rad], speeds [m/s], durations [s]. A trial's aim is the line from the
hand's start to the target as placed (before any drift). Errors are signed: positive to the left of the aim.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from reach_jax.config import Config
from reach_jax.env.environment import FAIL, OUT, SUCCESS
from reach_jax.physics import arm


def perpendicular(aim, rel):
    """Signed component of `rel` across the unit vector `aim`, + to the left of it (the 2-D cross product).

    Only indexing and arithmetic, so the same float operations run on NumPy arrays and on JAX arrays in jit.

    Args:
      aim: (..., 2) unit vectors.
      rel: (..., 2) vectors [m], broadcast against `aim`.
    """
    return aim[..., 0] * rel[..., 1] - aim[..., 1] * rel[..., 0]


def unit(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis of a NumPy array; NaN where a vector is zero."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.where(n > 0, n, 1.0), np.nan)


# Columns of a trial record, in order; the shell adds learner, trial and chunk (`run_dir.append_trials`).
COLUMNS = (
    "block",  # protocol block the trial ran in
    "catch",  # 1 for a catch trial
    "outcome",  # outcomes.SUCCESS, OUT or FAIL (the cap)
    "duration_s",  # trial length [s]
    "perp_error_m",  # hand's signed distance from the aim at peak hand speed [m]
    "direction_error_rad",  # signed angle from the aim to the hand's displacement at train.direction_time [rad]
    "aim_rad",  # direction of the aim in the shoulder frame [rad]
    "distance_m",  # start-target distance [m]
    "peak_speed",  # peak hand speed [m/s]
)


@struct.dataclass
class TrialTrace:
    """What a running trial has shown so far."""

    start: jax.Array  # (2,) hand position at the trial's start [m]
    aim: jax.Array  # (2,) unit vector from start to target
    distance: jax.Array  # () start-target distance [m]
    peak_speed: jax.Array  # () highest hand speed so far [m/s]
    perp: jax.Array  # () signed distance from the aim when the speed peaked [m]
    direction: jax.Array  # () signed direction error at train.direction_time [rad]; 0 before


def start_trace(start_state: jax.Array, target: jax.Array, cfg: Config) -> TrialTrace:
    """Trace of a trial that starts at arm state `start_state` (4,) toward `target` (2,) [m]."""
    hand = arm.hand_position(start_state[:2], cfg.arm)
    gap = target - hand
    distance = jnp.linalg.norm(gap)
    zero = jnp.zeros((), hand.dtype)
    return TrialTrace(hand, gap / jnp.maximum(distance, 1e-12), distance, zero, zero, zero)


def advance(trace: TrialTrace, hand: jax.Array, hand_vel: jax.Array, t: jax.Array, cfg: Config) -> TrialTrace:
    """Trace after the trial's t-th step, which left the hand at `hand` (2,) [m] moving at `hand_vel` (2,) [m/s]."""
    speed = jnp.linalg.norm(hand_vel)
    moved = hand - trace.start
    faster = speed > trace.peak_speed
    at_direction = t == max(round(cfg.train.direction_time / cfg.arm.dt), 1)
    across = perpendicular(trace.aim, moved)
    direction = jnp.arctan2(across, jnp.sum(trace.aim * moved))  # no dot in the step loop (CPU_XLA_FLAGS)
    return trace.replace(
        peak_speed=jnp.where(faster, speed, trace.peak_speed),
        perp=jnp.where(faster, across, trace.perp),
        direction=jnp.where(at_direction, direction, trace.direction),
    )


def record(trace: TrialTrace, block, catch, goal, out, t, cfg: Config) -> jax.Array:
    """(len(COLUMNS),) float32 record of a trial that ended after t steps."""
    outcome = jnp.where(goal, SUCCESS, jnp.where(out, OUT, FAIL))
    values = (
        block,
        catch,
        outcome,
        t * cfg.arm.dt,
        trace.perp,
        trace.direction,
        jnp.arctan2(trace.aim[1], trace.aim[0]),
        trace.distance,
        trace.peak_speed,
    )
    return jnp.stack([jnp.asarray(v, jnp.float32) for v in values])


class TrialBuffer(NamedTuple):
    """One learner's per-trial records of a chunk, filled from the front."""

    rows: jax.Array  # (capacity, len(COLUMNS)) float32 records
    trial: jax.Array  # (capacity,) int32 index of each recorded trial over the learner's life
    count: jax.Array  # () int32 records written


def empty_buffer(cfg: Config) -> TrialBuffer:
    """A buffer that holds every logged trial of one chunk: at most one trial ends per step."""
    capacity = cfg.train.chunk_steps // max(cfg.train.trial_log_every, 1) + 1
    return TrialBuffer(
        rows=jnp.zeros((capacity, len(COLUMNS)), jnp.float32),
        trial=jnp.zeros(capacity, jnp.int32),
        count=jnp.array(0, jnp.int32),
    )


def log_block(buffer: TrialBuffer, ended: jax.Array, rows: jax.Array, trials: jax.Array, every: int) -> TrialBuffer:
    """buffer with a block of steps' ended trials appended in order, those whose index is a multiple of `every`.

    Written once a block of steps, outside the compiled step loop: a write at a per-learner position inside
    the loop is a scatter, which keeps XLA:CPU from compiling the loop as one kernel (`xla_options.CPU_XLA_FLAGS`).

    Args:
      buffer: the learner's buffer.
      ended: (B,) bool, each step of the block ended a trial.
      rows: (B, len(COLUMNS)) the records of those trials.
      trials: (B,) int32 index of the trial each step ran.
      every: log every `every`-th trial.
    """
    keep = ended & (trials % every == 0)
    capacity = buffer.trial.shape[0]
    slot = jnp.where(keep, buffer.count + jnp.cumsum(keep) - 1, capacity)  # dropped: past the end
    return TrialBuffer(
        rows=buffer.rows.at[slot].set(rows, mode="drop"),
        trial=buffer.trial.at[slot].set(trials, mode="drop"),
        count=buffer.count + jnp.sum(keep, dtype=jnp.int32),
    )
