"""The curriculum of start-target distances and the drift gate: their state, bounds and rules (model §5).

Units: distances [m], counts in trials. The distance d bounds the start-target offset in each axis (an L-inf box).
The drift gate follows the learner's recent failure share, an exponential mean of the trials that ended without
a clean success (one that needed no drift).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import Config
from reach_jax.env.task import Geometry


@struct.dataclass
class Curriculum:
    """One learner's place on the staircase."""

    distance: jax.Array  # () curriculum distance [m]
    full_at: jax.Array  # () trials ended when the distance first reached its maximum; -1 before
    failure: jax.Array  # () recent share of trials that ended without a clean success, in [0, 1]


def bounds(geom: Geometry) -> tuple[jax.Array, jax.Array]:
    """(initial and minimum, maximum) curriculum distance [m] of a learner's geometry; the maximum spans its field."""
    return geom.start_distance, geom.full_distance


def shortfall(cur: Curriculum, geom: Geometry) -> jax.Array:
    """() how far the distance falls short of the whole field, as a fraction of it: 0 at the whole field."""
    return 1.0 - cur.distance * geom.inv_full_distance


def initial(geom: Geometry, cfg: Config) -> Curriculum:
    """The staircase before the first trial: the initial distance, full from the start only if that spans the field."""
    distance, full = bounds(geom)
    full_at = jnp.where(distance >= full, 0, -1).astype(jnp.int32)
    return Curriculum(distance=distance, full_at=full_at, failure=jnp.asarray(cfg.task.drift_gate_start, float))


def drift_open(cur: Curriculum, gate: jax.Array) -> jax.Array:
    """() bool: the trial's target may drift; with hyper `drift_gate` > 0 only while the failure share exceeds it."""
    return (gate <= 0) | (cur.failure > gate)


def failure_after(failure: jax.Array, goal: jax.Array, drifted: jax.Array, rate: jax.Array) -> jax.Array:
    """The recent failure share after a trial: moved by `rate` (1 / hyper `drift_gate_trials`) toward 0 or 1."""
    failed = jnp.where(goal & ~drifted, 0.0, 1.0)
    return failure + rate * (failed - failure)


def staircase(
    distance: jax.Array,
    goal: jax.Array,
    drifted: jax.Array,
    was_full: jax.Array,
    geom: Geometry,
    cfg: Config,
    early: jax.Array = False,
) -> jax.Array:
    """Distance after a trial: grow after a success without drift, shrink after an out or a cap.

    A drift-aided success also shrinks it, except once the curriculum has been full and
    cfg.task.drift_neutral_when_full is set, or at any time when `early` is (hyper `drift_neutral_early`): then it
    leaves the distance unchanged. A learner that needs the drift for some trials (a strong random force, little
    exploration noise) keeps the whole field.

    Args:
      distance: () curriculum distance [m].
      goal: () bool, the trial reached the goal.
      drifted: () bool, the target drifted during the trial.
      was_full: () bool, the distance has reached the whole field at some earlier trial.
      geom: the learner's geometry, which bounds the distance.
      cfg: model config.
      early: () bool, a drift-aided success is neutral before the first full field too.
    """
    lo, hi = bounds(geom)
    neutral = goal & drifted & ((was_full & cfg.task.drift_neutral_when_full) | early)
    step = jnp.where(goal & ~drifted, cfg.task.curriculum_step, jnp.where(neutral, 0.0, -cfg.task.curriculum_step))
    return jnp.clip(distance + step, lo, hi)


def after_step(
    cur: Curriculum,
    ended: jax.Array,
    goal: jax.Array,
    drifted: jax.Array,
    trials: jax.Array,
    geom: Geometry,
    cfg: Config,
    early,
    rate: jax.Array,
) -> Curriculum:
    """The staircase after a step: moved if the step ended a trial, with the trial count when it first got full,
    and the failure share.

    Args:
      cur: the staircase before the step.
      ended: () bool, the step ended a trial.
      goal: () bool, at the goal.
      drifted: () bool, the ended trial's target drifted.
      trials: () int32 trials ended before this step.
      geom: the learner's geometry, which bounds the distance.
      cfg: model config.
      early: () bool, hyper `drift_neutral_early`.
      rate: () weight of the ended trial in the failure share (`failure_after`).
    """
    was_full = cur.full_at >= 0
    distance = jnp.where(ended, staircase(cur.distance, goal, drifted, was_full, geom, cfg, early), cur.distance)
    first_full = ~was_full & (distance >= bounds(geom)[1])
    failure = jnp.where(ended, failure_after(cur.failure, goal, drifted, rate), cur.failure)
    return Curriculum(distance=distance, full_at=jnp.where(first_full, trials + ended, cur.full_at), failure=failure)
