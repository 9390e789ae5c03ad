"""Physical consistency of reach_jax.arm, checked against mechanics rather than against another code.

Runs in float64 (`jax.enable_x64`), so the bounds below are set by the numerical methods (RK4, central
differences), not by float32 rounding.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax.config import PAPER_CONDITIONS, ArmConfig, ConditionConfig
from reach_jax.physics import arm, fields

N_SAMPLES = 6


@pytest.fixture(autouse=True)
def x64():
    """Run every test in float64."""
    with jax.enable_x64(True):
        yield


def _states(seed: int, n: int = N_SAMPLES):
    """(n, 4) states: theta1 in its range, theta2 well inside (0, pi), |omega_i| in [1, 3] rad/s."""
    rng = np.random.default_rng(seed)
    speed = rng.uniform(1.0, 3.0, (n, 2)) * rng.choice([-1.0, 1.0], (n, 2))
    return np.column_stack([rng.uniform(0.0, np.pi / 2, n), rng.uniform(0.5, 2.6, n), speed])


def _energy_run(cfg: ArmConfig, duration: float):
    """Jitted (n, 4) -> (kinetic energies (n, steps + 1), max |omega| (n,)) of free RK4 motion."""
    n_steps = round(duration / cfg.dt)
    zero_tau, zero_field, zero_force = jnp.zeros(2), fields.make_field(ConditionConfig()), jnp.zeros(2)

    def one(s):
        def body(carry, _):
            nxt = arm.rk4(carry, zero_tau, zero_field, zero_force, cfg)
            return nxt, nxt

        _, path = jax.lax.scan(body, s, None, length=n_steps)
        path = jnp.concatenate([s[None], path])
        energy = jax.vmap(lambda p: arm.kinetic_energy(p, cfg))(path)
        return energy, jnp.max(jnp.abs(path[:, 2:]))

    return jax.jit(jax.vmap(one))


def test_kinetic_energy_conserved_without_damping():
    duration = 1.0  # [s], 50 steps at the paper's dt
    # RK4 alone, the free equations: some of these paths fold the elbow past 180 degrees, where the one-link stop
    # would hold it (its own tests are below).
    free = dataclasses.replace(ArmConfig(), joint_viscosity=(0.0, 0.0), one_link_stop=False)
    half = dataclasses.replace(free, dt=free.dt / 2)
    states = _states(0)
    energy, omega_max = (np.asarray(a) for a in _energy_run(free, duration)(states))
    energy_half, _ = (np.asarray(a) for a in _energy_run(half, duration)(states))
    err = np.abs(energy[:, -1] / energy[:, 0] - 1.0)
    err_half = np.abs(energy_half[:, -1] / energy_half[:, 0] - 1.0)

    # RK4 is 4th order: after time T its relative error is of order (Omega dt)^4 * Omega T, with Omega the
    # fastest rate of the motion (here the largest joint speed along the path) and a constant below 1 for a
    # smooth mechanical system. At Omega ~ 3-5 rad/s and dt = 0.02 s that is ~1e-4; a missing or mis-signed
    # Coriolis term instead changes the energy by a fixed fraction of order 1e-2 that no dt removes.
    bound = (omega_max * free.dt) ** 4 * omega_max * duration
    assert (err < bound).all(), (err, bound)
    # Conservation must come from the equations, not from luck at one dt: the drift has to vanish like a
    # high power of dt. Order 4 predicts a 16x drop when dt halves; 8x allows for pre-asymptotic behaviour.
    # (A non-conservative model drifts by the same amount at any dt, a ratio near 1.)
    assert (err / err_half > 8.0).all(), err / err_half


def test_joint_viscosity_dissipates_energy():
    """With the paper's joint viscosity and no torque, kinetic energy can only decrease."""
    energy, _ = (np.asarray(a) for a in _energy_run(ArmConfig(), 0.5)(_states(1)))
    # dE/dt = -B1 w1^2 - B2 w2^2 <= 0 exactly; RK4's per-step error (~1e-7 relative, see above) cannot
    # outweigh a dissipation of ~B w^2 dt / E ~ 1e-2 per step at these speeds.
    assert (np.diff(energy, axis=1) < 0).all()


def _virtual_work_torque(theta, force, cfg: ArmConfig, h: float = 1e-5):
    """d(F . x(theta)) / d theta by central differences [N m]."""
    out = np.zeros(2)
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        plus = np.asarray(arm.hand_position(jnp.asarray(theta + e), cfg))
        minus = np.asarray(arm.hand_position(jnp.asarray(theta - e), cfg))
        out[j] = force @ (plus - minus) / (2 * h)
    return out


def test_hand_force_enters_as_jacobian_transpose():
    cfg = ArmConfig()
    rng = np.random.default_rng(2)
    null = fields.make_field(ConditionConfig())
    deriv = jax.jit(lambda s, f: arm.dsdt(s, jnp.zeros(2), null, f, cfg))
    jt_f = jax.jit(lambda th, f: arm.jacobian(th, cfg).T @ f)
    mass = jax.jit(lambda th: arm.mass_matrix(th, cfg))
    for state in _states(3):
        force = rng.uniform(-8.0, 8.0, 2)
        want = _virtual_work_torque(state[:2], force, cfg)
        # Central differences with h = 1e-5 rad: truncation h^2/6 |F . x'''| ~ 1e-10 N m, rounding
        # eps |F . x| / h ~ 1e-10 N m, against torques of order 1 N m; 1e-8 covers both by 50x.
        np.testing.assert_allclose(np.asarray(jt_f(state[:2], force)), want, rtol=0, atol=1e-8)
        # The torque the dynamics actually receive: M(theta) times the change of acceleration the force causes.
        applied = np.asarray(mass(state[:2])) @ np.asarray(deriv(state, force) - deriv(state, jnp.zeros(2)))[2:]
        np.testing.assert_allclose(applied, want, rtol=0, atol=1e-8)


def test_viscous_field_power():
    """Power into the joints from J^T (B xdot) equals the power xdot . B xdot of the field at the hand."""
    cfg = ArmConfig()
    field = jnp.asarray(PAPER_CONDITIONS[1].viscous)
    deriv = jax.jit(
        lambda s, b: arm.dsdt(
            s, jnp.zeros(2), fields.make_field(ConditionConfig()).replace(viscous=b), jnp.zeros(2), cfg
        )
    )
    mass = jax.jit(lambda th: arm.mass_matrix(th, cfg))
    fk = jax.jit(lambda th: arm.hand_position(th, cfg))
    h = 1e-6  # [s] time step for the hand velocity by central differences along theta + omega t
    for state in _states(4):
        theta, omega = state[:2], state[2:]
        xdot = np.asarray(fk(theta + h * omega) - fk(theta - h * omega)) / (2 * h)
        hand_power = xdot @ np.asarray(field) @ xdot  # [W]
        torque = np.asarray(mass(theta)) @ np.asarray(deriv(state, field) - deriv(state, jnp.zeros((2, 2))))[2:]
        joint_power = omega @ torque
        # xdot by central differences: relative error ~ (|omega| h)^2 + eps / (|omega| h) ~ 1e-10; the power
        # (~10 W) is quadratic in xdot, so 1e-8 relative (plus 1e-9 W absolute near zero) covers it.
        assert joint_power == pytest.approx(hand_power, rel=1e-8, abs=1e-9)
        # And the model's own hand velocity is the same xdot.
        np.testing.assert_allclose(np.asarray(arm.hand_velocity(jnp.asarray(state), cfg)), xdot, rtol=1e-8, atol=1e-9)


# The elbow on its stop (model §1): the paper's "fixed at 180 degree ... as one link".
STOP = ArmConfig().theta2_stop
NULL = ConditionConfig()


def _step(state, tau, cfg: ArmConfig, field: ConditionConfig = NULL) -> np.ndarray:
    return np.asarray(arm.step(jnp.asarray(state), jnp.asarray(tau), fields.make_field(field), jnp.zeros(2), cfg))


def test_on_its_stop_the_arm_turns_as_one_link_with_the_folded_inertia():
    cfg = ArmConfig()
    m1, m2 = cfg.mass
    l1, l2 = cfg.length
    # Folded at 180 degrees link 2 lies back along link 1, its centre l1 - l2/2 from the shoulder.
    inertia = m1 * l1**2 / 3 + m2 * l2**2 / 12 + m2 * (l1 - l2 / 2) ** 2
    assert inertia == pytest.approx(0.12)  # [kg m^2], by hand for Table 1
    b1, tau1, w0 = cfg.joint_viscosity[0], 1.0, 0.5
    start, tau = np.array([0.7, STOP, w0, 0.0]), np.array([tau1, 2.0])  # the elbow torque presses into the stop
    moved = _step(start, tau, cfg)
    assert moved[1] == STOP and moved[3] == 0.0  # held: the elbow neither moves nor gains speed
    # I w' = tau1 - b1 w: w(t) = tau1/b1 + (w0 - tau1/b1) exp(-b1 t / I); theta follows by integration.
    decay = np.exp(-b1 * cfg.dt / inertia)
    w = tau1 / b1 + (w0 - tau1 / b1) * decay
    theta = 0.7 + tau1 / b1 * cfg.dt + (w0 - tau1 / b1) * inertia / b1 * (1 - decay)
    # RK4's one-step error on this linear equation: (h lambda)^5 / 5! of the decaying part, h lambda = b1 dt / I.
    err = (b1 * cfg.dt / inertia) ** 5 / 120 * abs(w0 - tau1 / b1)
    np.testing.assert_allclose(moved[[0, 2]], [theta, w], rtol=0, atol=1.5 * err)
    # The clamp of config versions 1-12 lets the elbow torque's reaction turn the shoulder too (0.82 against 0.63
    # rad/s here), as if the elbow were free.
    clamped = _step(start, tau, dataclasses.replace(cfg, one_link_stop=False))
    assert abs(clamped[2] - w) > 0.1


def test_the_stop_does_no_work_on_a_held_arm():
    # No joint friction and no shoulder torque: the folded arm spins on at constant kinetic energy while the
    # elbow torque presses it into the stop, which gives that torque back.
    cfg = dataclasses.replace(ArmConfig(), joint_viscosity=(0.0, 0.0))
    state, energies = np.array([0.3, STOP, 1.5, 0.0]), []
    for _ in range(40):
        state = _step(state, [0.0, 2.5], cfg)
        energies.append(float(arm.kinetic_energy(jnp.asarray(state), cfg)))
        assert state[1] == STOP and state[3] == 0.0
    np.testing.assert_allclose(energies, energies[0], rtol=1e-12)
    assert energies[0] == pytest.approx(0.5 * 0.12 * 1.5**2)


def test_an_impact_on_the_stop_keeps_the_momentum_about_the_shoulder_and_loses_energy():
    cfg = ArmConfig()
    past = np.array([0.4, STOP + 0.01, 0.2, 3.0])  # a free step carried the elbow past the stop, still opening
    at_stop = jnp.asarray([0.4, STOP])

    def momentum(s):  # conjugate to theta1: M11 w1 + M12 w2, at the stop
        m = np.asarray(arm.mass_matrix(at_stop, cfg))
        return m[0, 0] * s[2] + m[0, 1] * s[3]

    def energy(s):
        return float(arm.kinetic_energy(jnp.asarray([s[0], STOP, s[2], s[3]]), cfg))

    after = np.asarray(arm.elbow_stop(jnp.asarray(past), cfg))
    assert after[1] == STOP and after[3] == 0.0
    assert momentum(after) == pytest.approx(momentum(past), rel=1e-12)
    assert energy(after) < energy(past)  # an inelastic impact
    # The clamp dropped omega2's share of that momentum: the shoulder kept its speed.
    clamped = np.asarray(arm.elbow_stop(jnp.asarray(past), dataclasses.replace(cfg, one_link_stop=False)))
    assert clamped[2] == past[2] and momentum(clamped) != pytest.approx(momentum(past), rel=1e-3)


def test_an_elbow_torque_that_pulls_back_releases_the_stop():
    moved = _step([0.7, STOP, 0.5, 0.0], [1.0, -2.0], ArmConfig())
    assert moved[1] < STOP and moved[3] < 0.0
