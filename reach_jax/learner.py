"""TS actor-critic learning: targets of eq. 1-2, N_max of eq. 3, and one backprop update (SPEC §5).

Units: critic and actor values are network outputs in (-0.5, 0.5); N_max and trial lengths are steps.
The update for the transition x(t-1) -> x(t) runs at step t, once p(t) is known. A trial's last
transition is updated at the first step of the next trial, so every step does exactly one backprop.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from reach_jax import network
from reach_jax.config import Config, LearnerConfig


class Pending(NamedTuple):
    """The previous step, waiting for its TS update."""

    x: jax.Array  # (125,) masked input at t-1
    out: jax.Array  # (3,) outputs [p, m1, m2] at t-1, as used to act
    rnd: jax.Array  # (2,) exploration noise added at t-1
    valid: jax.Array  # () bool: False at the first step of a run or after a capped trial
    terminal: jax.Array  # () bool: the transition ended its trial at the goal or a limit
    reward: jax.Array  # () reinforcement that ended the trial, 0 otherwise


def empty_pending(n_in: int) -> Pending:
    """A Pending that triggers no update."""
    return Pending(
        x=jnp.zeros(n_in),
        out=jnp.zeros(3),
        rnd=jnp.zeros(2),
        valid=jnp.array(False),
        terminal=jnp.array(False),
        reward=jnp.array(0.0),
    )


def ts_targets(pending: Pending, p_now: jax.Array, n_max: jax.Array, cfg: LearnerConfig) -> jax.Array:
    """Training signal (3,) for the input x(t-1), from eq. 1 (critic) and eq. 2 (actor).

    At a trial's end the reinforcement stands in for p(t). Non-terminal critic targets are floored at
    cfg.critic_floor, so long trials cannot push the critic below the penalty (anti-collapse guard).
    """
    p_next = jnp.where(pending.terminal, pending.reward, p_now)
    critic = p_next - cfg.p_range / n_max
    critic = jnp.where(pending.terminal, critic, jnp.maximum(critic, cfg.critic_floor))
    actor = pending.out[1:] + pending.rnd * (p_next - pending.out[0])
    return jnp.concatenate([critic[None], actor])


def update_n_max(n_max: jax.Array, n_steps: jax.Array, lam: jax.Array) -> jax.Array:
    """Eq. 3 after a trial that reached the goal in n_steps."""
    return jnp.where(n_steps > lam * n_max, n_steps.astype(n_max.dtype), lam * n_max)


def optimizer(lr: jax.Array) -> optax.GradientTransformation:
    """Plain SGD on squared error, as in error backpropagation."""
    return optax.sgd(lr)


def ts_update(params, x_now: jax.Array, pending: Pending, n_max: jax.Array, lr: jax.Array, cfg: Config):
    """Forward x(t), then one TS backprop step on x(t-1), in a single fused pass.

    Args:
      params: network parameters W(t).
      x_now: (125,) input x(t).
      pending: the step t-1.
      n_max: () N_max [steps].
      lr: () learning rate.
      cfg: model config.

    Returns:
      (params W(t+1), outputs (3,) at x(t) computed with W(t), squared-error loss ()).
    """

    def loss_fn(p):
        out = network.apply(p, jnp.stack([x_now, pending.x]), cfg)
        target = jax.lax.stop_gradient(ts_targets(pending, out[0, 0], n_max, cfg.learner))
        err = target - out[1]
        return 0.5 * jnp.where(pending.valid, jnp.sum(err**2), 0.0), out[0]

    (loss, out_now), grads = jax.value_and_grad(loss_fn, has_aux=True)(params)
    tx = optimizer(lr)
    updates, _ = tx.update(grads, tx.init(params), params)
    return optax.apply_updates(params, updates), out_now, loss
