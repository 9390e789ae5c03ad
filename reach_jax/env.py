"""The reaching environment: one arm, one target, one trial (model §1, §2, §5, §6).

gymnax-style: a frozen `EnvState` and pure functions, with the trial's condition (its field and input mask) as
the environment's parameters, passed to each call. `reset` starts a trial at rest, `observe` gives the network's
input, `step` applies a torque for one RK4 step of cfg.arm.dt and reports how the trial stands.
Training (`rollout.learner_step`) and the test episodes (`episodes.run_episode`) both step it; the NumPy oracle
(`reference`) mirrors it. Units: arm state [rad, rad/s], torques [N m], positions [m], forces [N], time in steps.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax import arm, task
from reach_jax.config import Config


@struct.dataclass
class EnvState:
    """The arm, the target and the trial under way."""

    arm: jax.Array  # (4,) arm state now
    prev_arm: jax.Array  # (4,) arm state one step before (the start state at a trial's first step)
    prev_tau: jax.Array  # (2,) torques one step before [N m] (0 at a trial's first step)
    target: jax.Array  # (2,) target position [m]
    force: jax.Array  # (2,) this trial's random hand force [N]
    t: jax.Array  # () steps taken in this trial
    drifted: jax.Array  # () bool: the target drifted in this trial


class Outcome(NamedTuple):
    """How the trial stands after a step."""

    goal: jax.Array  # () bool: the hand rests on the target (section 4.2)
    out_of_range: jax.Array  # () bool: a joint left its range
    cap: jax.Array  # () bool: neither, and the trial reached cfg.task.max_trial_time
    hand: jax.Array  # (2,) hand position [m]
    hand_vel: jax.Array  # (2,) hand velocity [m/s]


def reset(start: jax.Array, target: jax.Array, force: jax.Array) -> EnvState:
    """A trial from rest at arm state `start` (4,) toward `target` (2,) [m] with random hand force `force` (2,) [N]."""
    return EnvState(
        arm=start,
        prev_arm=start,
        prev_tau=jnp.zeros(2),
        target=target,
        force=force,
        t=jnp.array(0, jnp.int32),
        drifted=jnp.array(False),
    )


def observe(state: EnvState, cond: task.Condition, cfg: Config) -> jax.Array:
    """(125,) network input: the sensor image and the coded joints, masked by the condition's input mask."""
    return task.observe(state.arm, state.prev_arm, state.prev_tau, state.target, cond.input_mask, cfg)


def step(
    state: EnvState, tau: jax.Array, cond: task.Condition, cfg: Config, drift: bool = True
) -> tuple[EnvState, Outcome]:
    """The trial one step on under torque `tau` (2,) [N m]; the caller starts a new one when the outcome ends it.

    Args:
      state: the trial.
      tau: applied torques [N m].
      cond: the trial's condition, whose field pushes the hand.
      cfg: model config.
      drift: move the target toward the hand once the trial runs long (training); the tests have no drift.
    """
    moved = arm.step(state.arm, tau, cond.field, state.force, cfg.arm)
    t = state.t + 1
    hand = arm.hand_position(moved[:2], cfg.arm)
    out_of_range = arm.is_out(moved, cfg.arm)
    hand_vel = arm.hand_velocity(moved, cfg.arm)
    goal = task.goal_reached(hand, hand_vel, state.target, cfg) & ~out_of_range
    cap = (t >= round(cfg.task.max_trial_time / cfg.arm.dt)) & ~goal & ~out_of_range
    target, moved_target = task.drift_target(state.target, hand, t, cfg) if drift else (state.target, False)
    new = state.replace(
        arm=moved, prev_arm=state.arm, prev_tau=tau, target=target, t=t, drifted=state.drifted | moved_target
    )
    return new, Outcome(goal=goal, out_of_range=out_of_range, cap=cap, hand=hand, hand_vel=hand_vel)
