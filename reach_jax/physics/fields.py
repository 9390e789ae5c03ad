"""Hand-force fields as data (section 4.3, model §6): one formula covers the null, viscous, curl, spring,
constant and per-trial random fields.

F = viscous @ xdot + stiffness @ (x - anchor) + constant + f, with f ~ U(-random, random) per axis, drawn once
per trial. Units: positions [m] (shoulder frame), velocities [m/s], forces [N], viscous [N s/m], stiffness [N/m].
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import ConditionConfig


@struct.dataclass
class Field:
    """One hand-force field: per-learner data, never a Python branch."""

    viscous: jax.Array  # (2, 2) B [N s/m]
    stiffness: jax.Array  # (2, 2) K [N/m]
    anchor: jax.Array  # (2,) x0 [m]
    constant: jax.Array  # (2,) [N]
    random: jax.Array  # (2,) bound of the per-trial force per axis [N]


def make_field(spec: ConditionConfig) -> Field:
    """The Field of a condition of the config."""
    return Field(*(jnp.asarray(getattr(spec, f.name), dtype=float) for f in dataclasses.fields(Field)))


def hand_force(field: Field, hand: jax.Array, hand_vel: jax.Array, trial_force: jax.Array) -> jax.Array:
    """(2,) hand force [N] at hand position (2,) [m] and velocity (2,) [m/s], with this trial's random force (2,)."""
    push = matvec2(field.viscous, hand_vel) + matvec2(field.stiffness, hand - field.anchor)
    return push + field.constant + trial_force


def matvec2(a: jax.Array, v: jax.Array) -> jax.Array:
    """(2, 2) @ (2,) as elementwise products, which XLA fuses with their neighbours instead of a separate dot.

    Without fused multiply-adds (`xla_options.NO_FMA_FLAG`) it rounds as XLA's dot does, bit for bit.
    """
    return a[:, 1] * v[1] + a[:, 0] * v[0]


def trial_force(field: Field, u: jax.Array) -> jax.Array:
    """(2,) random force of a new trial [N] from two uniform draws in [0, 1)."""
    return field.random * (2.0 * u - 1.0)
