"""The physics layer: the two-link arm (eq. 4-5), the hand-force fields, the visual sensor and the input encoding."""

from reach_jax.physics.arm import (
    dsdt,
    elbow_stop,
    external_force,
    hand_position,
    hand_velocity,
    inverse_jacobian,
    inverse_kinematics,
    is_out,
    jacobian,
    kinetic_energy,
    mass_matrix,
    rk4,
    step,
    velocity_torque,
)
from reach_jax.physics.encoding import coded_support, encode, input_mask, localize, localize_support
from reach_jax.physics.fields import Field, hand_force, make_field, matvec2, trial_force
from reach_jax.physics.sensor import cell_edges, field_bounds, render

__all__ = [
    "Field",
    "cell_edges",
    "coded_support",
    "dsdt",
    "elbow_stop",
    "encode",
    "external_force",
    "field_bounds",
    "hand_force",
    "hand_position",
    "hand_velocity",
    "input_mask",
    "inverse_jacobian",
    "inverse_kinematics",
    "is_out",
    "jacobian",
    "kinetic_energy",
    "localize",
    "localize_support",
    "make_field",
    "mass_matrix",
    "matvec2",
    "render",
    "rk4",
    "step",
    "trial_force",
    "velocity_torque",
]
