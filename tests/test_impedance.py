"""Learned hand impedance: autodiff against finite differences, a controller with known gains, the field's axes."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax import evaluate
from reach_jax.agent import network
from reach_jax.config import Config, condition
from reach_jax.evaluate import episodes, frames, impedance
from reach_jax.physics import arm

CFG = Config()
VISCOUS = condition(CFG, "viscous").viscous
K_TRUE = np.array([[300.0, 40.0], [-20.0, 150.0]])  # [N/m], not symmetric on purpose
D_TRUE = np.array([[25.0, -6.0], [9.0, 12.0]])  # [N s/m]


def linear_policy(params, obs):
    """Hand-space impedance controller: F = -K (hand - start) - D hand_vel, as torques J^T F; params = (K, D)."""
    k, d = params
    force = -k @ (obs.hand - obs.start) - d @ obs.hand_vel
    return arm.jacobian(obs.arm[:2], CFG.arm).T @ force


def _state(hand, vel):
    q = arm.inverse_kinematics(jnp.asarray(hand), CFG.arm)
    qdot = jnp.linalg.solve(arm.jacobian(q, CFG.arm), jnp.asarray(vel))
    return jnp.concatenate([q, qdot])


def _gains(policy, params, state, prev, start, mask=None):
    mask = jnp.ones(125) if mask is None else mask
    target = jnp.asarray(CFG.sensor.centre)
    return impedance.hand_gains(policy, params, mask, state, prev, jnp.zeros(2), target, start, 3, CFG)


def test_linear_controller_gains_are_recovered():
    with jax.enable_x64(True):
        params = (jnp.asarray(K_TRUE), jnp.asarray(D_TRUE))
        start = jnp.array([-0.06, 0.35])
        # At the controller's set point and at rest the force is 0, so K and D come out exactly.
        state = _state(start, [0.0, 0.0])
        k, d = _gains(linear_policy, params, state, state, start)
        np.testing.assert_allclose(k, K_TRUE, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(d, D_TRUE, rtol=1e-10, atol=1e-9)
        # Away from it D is still exact (the force is linear in velocity at fixed posture).
        moving = _state([-0.055, 0.356], [0.05, -0.03])  # torques well inside tau_max
        _, d = _gains(linear_policy, params, moving, moving, start)
        np.testing.assert_allclose(d, D_TRUE, rtol=1e-10, atol=1e-9)


def _trained_like_params(seed=0):
    """A network with every layer random (the initial output layer is 0, which would make every gain 0)."""
    params = network.init_params(jax.random.PRNGKey(seed), CFG)
    layers = network.dense_layers(params)
    keys = jax.random.split(jax.random.PRNGKey(seed + 1), len(layers))
    layers = [(w + 0.8 * jax.random.normal(k, w.shape), b) for (w, b), k in zip(layers, keys, strict=True)]
    return jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), network.with_dense_layers(params, layers))


def test_network_gains_match_finite_differences():
    with jax.enable_x64(True):
        params = _trained_like_params()
        policy = episodes.network_policy(CFG)
        target, start = jnp.asarray(CFG.sensor.centre), jnp.array([-0.08, 0.33])
        mask = jnp.ones(125)
        checked = 0
        # Hands off the cell grid: on it the area-ratio sensor has a kink, where autodiff takes one side's slope.
        for hand, vel in [([-0.07, 0.34], [0.11, 0.07]), ([-0.013, 0.404], [-0.2, 0.05]), ([-0.12, 0.30], [0.03, 0.3])]:
            state = _state(hand, vel)
            prev = state - jnp.concatenate([state[2:] * CFG.arm.dt, jnp.array([0.4, -0.3])])
            k, d = _gains(policy, params, state, prev, start, mask)

            def torque(shift, state=state, prev=prev):
                obs = episodes.observation(state + shift, prev + shift, jnp.zeros(2), target, start, 3, mask, CFG)
                return policy(params, obs)

            h = 1e-7
            cols = [(torque(h * e) - torque(-h * e)) / (2 * h) for e in jnp.eye(4)]
            dtau = jnp.stack(cols, axis=1)  # (2, 4): d tau / d (q, qdot)
            jinv = jnp.linalg.inv(arm.jacobian(state[:2], CFG.arm))
            np.testing.assert_allclose(k, -jinv.T @ dtau[:, :2] @ jinv, rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(d, -jinv.T @ dtau[:, 2:] @ jinv, rtol=1e-5, atol=1e-4)
            checked += float(jnp.abs(k).max() > 1.0) + float(jnp.abs(d).max() > 0.1)
        assert checked >= 4  # the gains were not trivially zero


def test_passive_damping_is_the_joint_viscosity_in_hand_space():
    with jax.enable_x64(True):
        state = _state([-0.05, 0.37], [0.0, 0.0])
        dp = np.asarray(impedance.passive_damping(state, CFG))
        j = np.asarray(arm.jacobian(state[:2], CFG.arm))
        # The hand force that the viscosity exerts for a hand velocity v is -J^-T B J^-1 v.
        v = np.array([0.1, -0.2])
        np.testing.assert_allclose(j.T @ (dp @ v), np.diag(CFG.arm.joint_viscosity) @ np.linalg.solve(j, v))
        assert np.all(np.linalg.eigvalsh(0.5 * (dp + dp.T)) > 0)


def test_field_axes_of_the_paper_field():
    values, axes = impedance.field_axes(VISCOUS)
    np.testing.assert_allclose(values, [0.5 + np.sqrt(0.25 + 237.55), 0.5 - np.sqrt(0.25 + 237.55)], rtol=1e-12)
    assert values[0] == pytest.approx(15.92, abs=0.01) and values[1] == pytest.approx(-14.92, abs=0.01)
    b = np.asarray(VISCOUS)
    for v, e in zip(values, axes, strict=True):
        np.testing.assert_allclose(b @ e, v * e, atol=1e-12)
    angle = np.degrees(np.arctan2(axes[0, 1], axes[0, 0]))
    assert 110 < angle < 116 and np.all(axes[:, 1] >= 0)
    assert impedance.along(np.eye(2)[None] * 3.0, axes[0])[0] == pytest.approx(3.0)


def reaching_policy(params, obs):
    """Hand-space impedance controller pulling to the target: F = -K (hand - target) - D hand_vel."""
    k, d = params
    force = -k @ (obs.hand - obs.target) - d @ obs.hand_vel
    return arm.jacobian(obs.arm[:2], CFG.arm).T @ force


def test_measure_recovers_the_controller_along_its_own_movements():
    k_true, d_true = np.array([[40.0, 5.0], [-3.0, 30.0]]), np.array([[12.0, -2.0], [3.0, 8.0]])
    starts, targets = evaluate.test_pairs(CFG)
    params = (jnp.asarray(k_true[None]), jnp.asarray(d_true[None]))
    masks = jnp.ones((1, 125))
    ep, traj = jax.device_get(
        episodes.run_episodes(reaching_policy, params, masks, evaluate.test_fields(CFG), starts, targets, CFG)
    )
    gains = impedance.measure(reaching_policy, params, masks, ep, traj, starts, targets, CFG)
    stride, steps = CFG.eval.impedance_pair_stride, CFG.eval.impedance_max_steps
    assert gains["damping"].shape == (1, len(frames.test_columns(CFG)), len(starts[::stride]), steps, 2, 2)
    valid = gains["valid"]
    acted = np.arange(steps) < np.asarray(ep.steps)[:, :, ::stride, None]
    assert valid.sum() > 1000 and np.all(valid <= acted) and not acted.all()  # only states before the goal
    # Where the torque was not clipped, the damping is exact (float32 rounding); clipped torques have no slope.
    applied = np.asarray(traj.prev_tau)[:, :, ::stride, 1 : steps + 1]
    free = valid & np.all(np.abs(applied) < 0.99 * np.asarray(CFG.arm.tau_max), axis=-1)
    assert free.sum() > 0.5 * valid.sum()
    np.testing.assert_allclose(gains["damping"][free], np.broadcast_to(d_true, (free.sum(), 2, 2)), atol=0.05)
    summary = impedance.summarize(gains, [("none", 0)], ("none", "viscous"), VISCOUS)
    row = summary["per_network"][0]
    assert row["states"] == int(valid[0, 0].sum())
    np.testing.assert_allclose(row["damping_Ns_per_m"]["median"], d_true, atol=0.05)
    _, axes = impedance.field_axes(VISCOUS)
    assert row["damping_unstable"]["median"] == pytest.approx(axes[0] @ d_true @ axes[0], abs=0.05)
