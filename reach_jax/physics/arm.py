"""Two-link planar arm: eq. 4-5 of the paper, RK4 integration, joint limits.

Units: joint angles [rad], joint velocities [rad/s], torques [N m], hand position [m] in the shoulder
frame (x right, y forward), hand velocity [m/s], hand force [N], time [s].
The arm state is a (4,) array [theta1, theta2, omega1, omega2]; theta1 is measured from +x, theta2 is the
elbow angle relative to link 1. All functions act on one arm; vmap them for many.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config import ArmConfig
from reach_jax.physics import fields


def _link_constants(cfg: ArmConfig):
    m1, m2 = cfg.mass
    l1, l2 = cfg.length
    s2 = cfg.com_fraction * l2
    i1 = cfg.inertia_factor * m1 * l1**2
    i2 = cfg.inertia_factor * m2 * l2**2
    return m2, l1, s2, i1, i2


def mass_matrix(theta: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Inertia matrix of eq. 4-5.

    Args:
      theta: (2,) joint angles [rad].
      cfg: arm constants.

    Returns:
      (2, 2) inertia matrix [kg m^2].
    """
    m2, l1, s2, i1, i2 = _link_constants(cfg)
    c2 = jnp.cos(theta[1])
    m12 = i2 + m2 * l1 * s2 * c2
    m11 = i1 + i2 + 2 * m2 * l1 * s2 * c2 + m2 * l1**2
    return jnp.array([[m11, m12], [m12, i2]])


def velocity_torque(theta: jax.Array, omega: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Coriolis, centripetal and joint-viscosity terms of eq. 4-5, (2,) [N m]."""
    m2, l1, s2, _, _ = _link_constants(cfg)
    h = m2 * l1 * s2 * jnp.sin(theta[1])
    b1, b2 = cfg.joint_viscosity
    return jnp.array(
        [
            -h * (2 * omega[0] + omega[1]) * omega[1] + b1 * omega[0],
            h * omega[0] ** 2 + b2 * omega[1],
        ]
    )


def hand_position(theta: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Forward kinematics: (2,) joint angles [rad] -> (2,) hand position [m]."""
    l1, l2 = cfg.length
    t12 = theta[0] + theta[1]
    return jnp.array(
        [
            l1 * jnp.cos(theta[0]) + l2 * jnp.cos(t12),
            l1 * jnp.sin(theta[0]) + l2 * jnp.sin(t12),
        ]
    )


def jacobian(theta: jax.Array, cfg: ArmConfig) -> jax.Array:
    """d(hand position)/d(theta): (2,) joint angles [rad] -> (2, 2) [m/rad]."""
    l1, l2 = cfg.length
    t12 = theta[0] + theta[1]
    s1, c1 = jnp.sin(theta[0]), jnp.cos(theta[0])
    s12, c12 = jnp.sin(t12), jnp.cos(t12)
    return jnp.array([[-l1 * s1 - l2 * s12, -l2 * s12], [l1 * c1 + l2 * c12, l2 * c12]])


def inverse_jacobian(theta: jax.Array, cfg: ArmConfig) -> jax.Array:
    """J^-1: (2,) joint angles [rad] -> (2, 2) [rad/m], in closed form (adjugate over det J = l1 l2 sin theta2).

    Closed form rather than a LAPACK solve: XLA:CPU runs batched LAPACK calls on its intra-op pool and waits
    there for them, which with vmap over many states deadlocked the pool on 2 cores (every worker waiting).
    """
    j = jacobian(theta, cfg)
    det = j[0, 0] * j[1, 1] - j[0, 1] * j[1, 0]
    return jnp.array([[j[1, 1], -j[0, 1]], [-j[1, 0], j[0, 0]]]) / det


def hand_velocity(state: jax.Array, cfg: ArmConfig) -> jax.Array:
    """(4,) arm state -> (2,) hand velocity [m/s]."""
    return fields.matvec2(jacobian(state[:2], cfg), state[2:])


def inverse_kinematics(hand: jax.Array, cfg: ArmConfig) -> jax.Array:
    """(2,) hand position [m] -> (2,) joint angles [rad] with theta2 in (0, pi) (model §2)."""
    l1, l2 = cfg.length
    r2 = hand[0] ** 2 + hand[1] ** 2
    c2 = jnp.clip((r2 - l1**2 - l2**2) / (2 * l1 * l2), -1.0, 1.0)
    theta2 = jnp.arccos(c2)
    theta1 = jnp.arctan2(hand[1], hand[0]) - jnp.arctan2(l2 * jnp.sin(theta2), l1 + l2 * c2)
    return jnp.array([theta1, theta2])


def external_force(state: jax.Array, field: fields.Field, force: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Hand force of the field at this arm state, (2,) [N] (`fields.hand_force`).

    Args:
      state: (4,) arm state.
      field: the hand-force field.
      force: (2,) this trial's random force [N].
      cfg: arm constants.
    """
    return fields.hand_force(field, hand_position(state[:2], cfg), hand_velocity(state, cfg), force)


def _rhs_and_mass(state: jax.Array, tau: jax.Array, field: fields.Field, force: jax.Array, cfg: ArmConfig):
    """Eq. 4-5 as M(theta) theta'' = rhs: ((2,) rhs [N m], (2, 2) M [kg m^2])."""
    theta, omega = state[:2], state[2:]
    hand_force = external_force(state, field, force, cfg)
    rhs = tau + fields.matvec2(jacobian(theta, cfg).T, hand_force) - velocity_torque(theta, omega, cfg)
    return rhs, mass_matrix(theta, cfg)


def _accelerations(rhs: jax.Array, m: jax.Array, held) -> jax.Array:
    """(2,) joint accelerations: M^-1 rhs, or with the elbow `held` on its stop eq. 4 alone, (rhs1 / M11, 0).

    Held, M is taken as [[M11, 0], [0, 1]] and rhs2 as 0, so that one formula serves both.
    """
    m01, m10 = jnp.where(held, 0.0, m[0, 1]), jnp.where(held, 0.0, m[1, 0])
    m11, r1 = jnp.where(held, 1.0, m[1, 1]), jnp.where(held, 0.0, rhs[1])
    det = m[0, 0] * m11 - m01 * m10
    return jnp.array([m11 * rhs[0] - m01 * r1, m[0, 0] * r1 - m10 * rhs[0]]) / det


def dsdt(state, tau, field: fields.Field, force, cfg: ArmConfig, held=False) -> jax.Array:
    """Time derivative of the (4,) arm state under (2,) motor torques [N m] and the hand force.

    With `held` (() bool) the elbow sits on its stop and the arm turns as one link about the shoulder (model §1):
    theta2 stays, and eq. 4 with theta2'' = 0 gives theta1'' = rhs1 / M11; the stop takes eq. 5's reaction.
    """
    rhs, m = _rhs_and_mass(state, tau, field, force, cfg)
    return jnp.concatenate([state[2:], _accelerations(rhs, m, held)])


def pressed(state: jax.Array, free_acc: jax.Array, cfg: ArmConfig) -> jax.Array:
    """() bool: cfg.one_link_stop, and the elbow on its stop, not leaving it, with its free acceleration (the second
    of `free_acc` (2,)) pressing it further: the stop then holds it for the step (model §1)."""
    on_stop = (state[1] >= cfg.theta2_stop) & (state[3] >= 0.0) & (free_acc[1] >= 0.0)
    return jnp.logical_and(cfg.one_link_stop, on_stop)


def rk4(state: jax.Array, tau: jax.Array, field: fields.Field, force: jax.Array, cfg: ArmConfig) -> jax.Array:
    """One classical RK4 step of length cfg.dt; torque held, field evaluated in every stage.

    A step that starts with the elbow pressed into its stop (`pressed`) takes every stage as one link.
    """
    dt = cfg.dt
    rhs, m = _rhs_and_mass(state, tau, field, force, cfg)
    free = _accelerations(rhs, m, False)
    held = pressed(state, free, cfg)
    k1 = jnp.concatenate([state[2:], jnp.where(held, _accelerations(rhs, m, True), free)])
    k2 = dsdt(state + 0.5 * dt * k1, tau, field, force, cfg, held)
    k3 = dsdt(state + 0.5 * dt * k2, tau, field, force, cfg, held)
    k4 = dsdt(state + dt * k3, tau, field, force, cfg, held)
    return state + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def _stop_share(cfg: ArmConfig) -> float:
    """M12 / M11 at the stop (theta2 = cfg.theta2_stop): the share of omega2 that an impact passes to omega1."""
    # Computed at each trace, not cached: a value cached under jax.enable_x64 would carry float64 rounding into
    # a later float32 program.
    with jax.ensure_compile_time_eval():  # a constant of the compiled step, not a cosine in every step
        m = mass_matrix(jnp.array([0.0, cfg.theta2_stop]), cfg)
        return float(m[0, 1] / m[0, 0])


def elbow_stop(state: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Hard stop at theta2 = cfg.theta2_stop: clamp the angle, zero any outward velocity (model §1).

    With cfg.one_link_stop the impact keeps the momentum about the shoulder, M11 omega1 + M12 omega2 at the stop,
    which the stop's impulse on the elbow cannot change: omega1 takes what omega2 loses.
    """
    past = state[1] >= cfg.theta2_stop
    theta2 = jnp.where(past, cfg.theta2_stop, state[1])
    omega2 = jnp.where(past, jnp.minimum(state[3], 0.0), state[3])
    kept = state[2] + _stop_share(cfg) * (state[3] - omega2)
    omega1 = jnp.where(jnp.logical_and(cfg.one_link_stop, past), kept, state[2])
    # Rebuilt rather than written in place: an indexed write is a scatter, which keeps XLA:CPU from compiling
    # the step loop as one kernel (`xla_options.CPU_XLA_FLAGS`).
    return jnp.stack([state[0], theta2, omega1, omega2])


def is_out(state: jax.Array, cfg: ArmConfig) -> jax.Array:
    """True when a joint limit of section 4.2 is crossed: theta1 outside its range or theta2 < min."""
    lo, hi = cfg.theta1_range
    return (state[0] < lo) | (state[0] > hi) | (state[1] < cfg.theta2_min)


def step(state: jax.Array, tau: jax.Array, field: fields.Field, force: jax.Array, cfg: ArmConfig) -> jax.Array:
    """RK4 step followed by the elbow stop: the arm's full transition over cfg.dt."""
    return elbow_stop(rk4(state, tau, field, force, cfg), cfg)


def kinetic_energy(state: jax.Array, cfg: ArmConfig) -> jax.Array:
    """Kinetic energy 0.5 omega^T M omega [J] of a (4,) arm state."""
    omega = state[2:]
    return 0.5 * omega @ mass_matrix(state[:2], cfg) @ omega
