"""Localized coding of joint signals and assembly of the 125 network inputs (section 4.2, model §3).

Units: angles [rad], velocities [rad/s], torques [N m]; every coded unit is in [0, 1].
Input layout (paper sizes): 25 visual cells | theta1 (8), theta2 (12), omega1 (10), omega2 (10) now |
the same 40 one step before | tau1 (10), tau2 (10) one step before. The last 60 are the "past" inputs.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config import Config, n_inputs, n_past_inputs


def _position(x: jax.Array, lo: float, hi: float, n: int) -> jax.Array:
    """x on the unit grid: 0 at the first centre, n - 1 at the last, saturated outside."""
    return (jnp.clip(x, lo, hi) - lo) / ((hi - lo) / (n - 1))


def localize(x: jax.Array, lo: float, hi: float, n: int) -> jax.Array:
    """Triangular tuning of n units evenly spaced on [lo, hi]; out-of-range values saturate.

    Args:
      x: () scalar signal.
      lo: range covered by the unit centres.
      hi: range covered by the unit centres.
      n: number of units.

    Returns:
      (n,) activations; at most two neighbours are non-zero and they sum to 1.
    """
    # Distances on the unit grid are exact for units two or more away, so those are exactly 0 and
    # `localize_support` provably covers every non-zero unit.
    return jnp.maximum(0.0, 1.0 - jnp.abs(_position(x, lo, hi, n) - jnp.arange(n)))


def localize_support(x: jax.Array, lo: float, hi: float, n: int) -> jax.Array:
    """(2,) int32 indices of the two neighbouring units that hold every non-zero of `localize(x, lo, hi, n)`."""
    first = jnp.clip(jnp.floor(_position(x, lo, hi, n)).astype(jnp.int32), 0, n - 2)
    return first + jnp.arange(2, dtype=jnp.int32)


def _joint_codes(theta: jax.Array, omega: jax.Array, cfg: Config) -> list[tuple[jax.Array, float, float, int]]:
    """(signal, lo, hi, units) of each localized joint code, in input order."""
    e = cfg.encoding
    return [
        (theta[0], *e.theta_ranges[0], e.theta_units[0]),
        (theta[1], *e.theta_ranges[1], e.theta_units[1]),
        (omega[0], -e.omega_range, e.omega_range, e.omega_units),
        (omega[1], -e.omega_range, e.omega_range, e.omega_units),
    ]


def _codes(state: jax.Array, prev_state: jax.Array, prev_tau: jax.Array, cfg: Config):
    """(signal, lo, hi, units) of every localized code after the visual cells, in input order."""
    t1, t2 = cfg.arm.tau_max
    n = cfg.encoding.tau_units
    return [
        *_joint_codes(state[:2], state[2:], cfg),
        *_joint_codes(prev_state[:2], prev_state[2:], cfg),
        (prev_tau[0], -t1, t1, n),
        (prev_tau[1], -t2, t2, n),
    ]


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
    return jnp.concatenate([visual, *(localize(*code) for code in _codes(state, prev_state, prev_tau, cfg))])


def coded_support(state: jax.Array, prev_state: jax.Array, prev_tau: jax.Array, cfg: Config) -> jax.Array:
    """Indices into `encode`'s output of the coded units that may be non-zero: two per localized code.

    Every coded unit outside them is exactly 0, so a product with the input needs only the visual cells
    and these rows (45 of 125 for the paper's sizes).

    Args:
      state: as for `encode`.
      prev_state: as for `encode`.
      prev_tau: as for `encode`.
      cfg: model config.

    Returns:
      (2 * codes,) int32 distinct indices in [visual cells, n_inputs).
    """
    offset, rows = cfg.sensor.n_cells**2, []
    for code in _codes(state, prev_state, prev_tau, cfg):
        rows.append(offset + localize_support(*code))
        offset += code[-1]
    return jnp.concatenate(rows)


def input_mask(use_past: bool, cfg: Config) -> jax.Array:
    """(125,) 0/1 mask; use_past=False zeroes the one-step-before inputs (the no-past ablation)."""
    n, n_past = n_inputs(cfg), n_past_inputs(cfg)
    return jnp.concatenate([jnp.ones(n - n_past), jnp.full(n_past, float(use_past))])
