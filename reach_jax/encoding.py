"""Localized coding of joint signals and assembly of the 125 network inputs (section 4.2, SPEC §3).

Units: angles [rad], velocities [rad/s], torques [N m]; every coded unit is in [0, 1].
Input layout (paper sizes): 25 visual cells | theta1 (8), theta2 (12), omega1 (10), omega2 (10) now |
the same 40 one step before | tau1 (10), tau2 (10) one step before. The last 60 are the "past" inputs.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config import Config, n_inputs, n_past_inputs


def localize(x: jax.Array, lo: float, hi: float, n: int) -> jax.Array:
    """Triangular tuning of n units evenly spaced on [lo, hi]; out-of-range values saturate.

    Args:
      x: () scalar signal.
      lo, hi: range covered by the unit centres.
      n: number of units.

    Returns:
      (n,) activations; at most two neighbours are non-zero and they sum to 1.
    """
    spacing = (hi - lo) / (n - 1)
    centres = lo + spacing * jnp.arange(n)
    return jnp.maximum(0.0, 1.0 - jnp.abs(jnp.clip(x, lo, hi) - centres) / spacing)


def encode_joints(theta: jax.Array, omega: jax.Array, cfg: Config) -> jax.Array:
    """(2,) angles [rad] and (2,) velocities [rad/s] -> (40,) coded joint state for the paper's sizes."""
    e = cfg.encoding
    return jnp.concatenate(
        [
            localize(theta[0], *e.theta_ranges[0], e.theta_units[0]),
            localize(theta[1], *e.theta_ranges[1], e.theta_units[1]),
            localize(omega[0], -e.omega_range, e.omega_range, e.omega_units),
            localize(omega[1], -e.omega_range, e.omega_range, e.omega_units),
        ]
    )


def encode(
    visual: jax.Array,
    state: jax.Array,
    prev_state: jax.Array,
    prev_tau: jax.Array,
    cfg: Config,
) -> jax.Array:
    """Assemble the network input.

    Args:
      visual: (25,) sensor cells in [0, 1].
      state: (4,) arm state now [rad, rad/s].
      prev_state: (4,) arm state one step before.
      prev_tau: (2,) motor torques one step before [N m].
      cfg: model config.

    Returns:
      (125,) input vector in [0, 1].
    """
    t1, t2 = cfg.arm.tau_max
    n = cfg.encoding.tau_units
    return jnp.concatenate(
        [
            visual,
            encode_joints(state[:2], state[2:], cfg),
            encode_joints(prev_state[:2], prev_state[2:], cfg),
            localize(prev_tau[0], -t1, t1, n),
            localize(prev_tau[1], -t2, t2, n),
        ]
    )


def input_mask(use_past: bool, cfg: Config) -> jax.Array:
    """(125,) 0/1 mask; use_past=False zeroes the one-step-before inputs (the no-past ablation)."""
    n, n_past = n_inputs(cfg), n_past_inputs(cfg)
    return jnp.concatenate([jnp.ones(n - n_past), jnp.full(n_past, float(use_past))])
