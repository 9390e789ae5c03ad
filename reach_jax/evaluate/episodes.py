"""Noise-free test episodes of any policy: one rollout from rest to a target, batched over networks, tests and pairs.

Units: arm state [rad, rad/s], torques [N m], positions [m], speeds [m/s]; time in steps of cfg.arm.dt.

An episode has no learning, no exploration noise, no random force and no target drift. The arm starts at rest
at the inverse kinematics of the start; each step the policy sees an `Obs`, its torque is clipped to
+-tau_max (the actuator limit of Table 1) and the arm moves one RK4 step in the test's field. The episode
ends in one outcome: success (`task.goal_reached`), out (`arm.is_out`, checked first) or fail (neither
within cfg.eval.max_time).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from reach_jax import env
from reach_jax.agent import network
from reach_jax.config import Config
from reach_jax.env import task
from reach_jax.env.environment import FAIL, OUT, SUCCESS
from reach_jax.physics import arm
from reach_jax.physics.fields import Field

# Outcome codes of an episode.


class Obs(NamedTuple):
    """What a policy sees at one step; scripted controllers may use more than the network does."""

    x: jax.Array  # (125,) network input, masked by the learning condition
    arm: jax.Array  # (4,) arm state [rad, rad/s]
    hand: jax.Array  # (2,) hand position [m]
    hand_vel: jax.Array  # (2,) hand velocity [m/s]
    start: jax.Array  # (2,) start position [m]
    target: jax.Array  # (2,) target position [m]
    t: jax.Array  # () steps taken so far


class Episode(NamedTuple):
    """One test episode (leading batch axes when batched)."""

    outcome: jax.Array  # () SUCCESS, OUT or FAIL
    steps: jax.Array  # () steps until the episode ended; n_steps for a fail
    hand: jax.Array  # (n_steps + 1, 2) hand path [m], held at its last point after the end
    speed: jax.Array  # (n_steps + 1,) hand tangential speed [m/s], held after the end


class Trajectory(NamedTuple):
    """The arm states an episode passed through, to replay what the policy saw (leading batch axes when batched).

    At step k the policy saw `observation(arm[k], arm[max(k - 1, 0)], prev_tau[k], ...)`; it acted at
    k = 0 .. steps - 1.
    """

    arm: jax.Array  # (n_steps + 1, 4) arm state at each step [rad, rad/s], held after the end
    prev_tau: jax.Array  # (n_steps + 1, 2) torque applied one step before [N m]; 0 at the start, held after the end


def n_steps(cfg: Config) -> int:
    """Steps of a test episode: cfg.eval.max_time / cfg.arm.dt (200)."""
    return round(cfg.eval.max_time / cfg.arm.dt)


def observation(state, prev, prev_tau, target, start, t, mask, cfg: Config) -> Obs:
    """What a policy sees at arm state `state` (4,), one step after `prev` (4,) under torque `prev_tau` (2,)."""
    return Obs(
        x=task.observe(state, prev, prev_tau, target, mask, task.geometry(cfg), cfg),
        arm=state,
        hand=arm.hand_position(state[:2], cfg.arm),
        hand_vel=arm.hand_velocity(state, cfg.arm),
        start=start,
        target=target,
        t=t,
    )


def run_episode(policy, params, mask: jax.Array, field: Field, start: jax.Array, target: jax.Array, cfg: Config):
    """One noise-free test episode from rest at `start`.

    Args:
      policy: (params, Obs) -> (2,) torque [N m].
      params: the policy's parameters.
      mask: (125,) input mask of the learning condition.
      field: the hand-force field of the test condition; no per-trial random force is drawn in a test.
      start: (2,) start hand position [m].
      target: (2,) target position [m].
      cfg: model config.

    Returns:
      (Episode, Trajectory).
    """
    tau_max = jnp.asarray(cfg.arm.tau_max)
    s0 = jnp.concatenate([arm.inverse_kinematics(start, cfg.arm), jnp.zeros(2)])
    cond = task.Condition(field=field, input_mask=mask)
    first = env.start_trial(s0, target, jnp.zeros(2))

    def body(carry, t):
        trial, done, outcome, steps = carry
        obs = observation(trial.arm, trial.prev_arm, trial.prev_tau, target, start, t, mask, cfg)
        tau = jnp.clip(policy(params, obs), -tau_max, tau_max)
        moved, result = env.step_trial(trial, tau, cond, task.geometry(cfg), cfg, drift=False)
        ended = (result.out_of_range | result.goal) & ~done
        outcome = jnp.where(ended, jnp.where(result.out_of_range, OUT, SUCCESS), outcome)
        steps = jnp.where(ended, t + 1, steps)
        # An ended episode is frozen, so its path and speed stay at their final values.
        trial = jax.tree.map(lambda a, b: jnp.where(done, a, b), trial, moved)
        new = (trial, done | result.out_of_range | result.goal, outcome, steps)
        return new, (trial.arm, trial.prev_tau)

    total = n_steps(cfg)
    init = (first, jnp.array(False), jnp.array(FAIL, jnp.int32), jnp.array(total, jnp.int32))
    (_, _, outcome, steps), (states, applied) = jax.lax.scan(body, init, jnp.arange(total, dtype=jnp.int32))
    states = jnp.concatenate([s0[None], states])
    hand = jax.vmap(lambda s: arm.hand_position(s[:2], cfg.arm))(states)
    speed = jax.vmap(lambda s: jnp.linalg.norm(arm.hand_velocity(s, cfg.arm)))(states)
    prev_tau = jnp.concatenate([jnp.zeros((1, 2)), applied])
    return Episode(outcome=outcome, steps=steps, hand=hand, speed=speed), Trajectory(arm=states, prev_tau=prev_tau)


@functools.cache
def _compiled(policy, cfg: Config):
    one = functools.partial(run_episode, policy, cfg=cfg)
    over_pairs = jax.vmap(one, in_axes=(None, None, None, 0, 0))
    over_tests = jax.vmap(over_pairs, in_axes=(None, None, 0, None, None))
    over_nets = jax.vmap(over_tests, in_axes=(0, 0, None, None, None))
    return jax.jit(over_nets)


def run_episodes(policy, params, masks, fields, starts, targets, cfg: Config) -> tuple[Episode, Trajectory]:
    """Every pair x network x test condition in one jitted, vmapped rollout.

    Args:
      policy: (params, Obs) -> (2,) torque [N m]; must be hashable (a module-level or cached function).
      params: policy parameters with a leading network axis N.
      masks: (N, 125) input masks of the networks' learning conditions.
      fields: the hand-force fields of the C test conditions, stacked (`evaluate.lattice.test_fields`).
      starts: (P, 2) start positions [m].
      targets: (P, 2) target positions [m].
      cfg: model config.

    Returns:
      (Episode, Trajectory), leading axes (N, C, P).
    """
    run = _compiled(policy, cfg)
    return run(params, jnp.asarray(masks), jax.tree.map(jnp.asarray, fields), jnp.asarray(starts), jnp.asarray(targets))


@functools.cache
def network_policy(cfg: Config):
    """The trained actor as a policy: (params, Obs) -> (2,) torque [N m], from Obs.x only, without noise."""

    def policy(params, obs: Obs) -> jax.Array:
        m = network.apply(params, obs.x, cfg)[1:]
        return network.torque(m, jnp.zeros_like(m), cfg)

    return policy
