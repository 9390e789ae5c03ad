"""The jitted JAX model against the plain-NumPy oracle (reach_jax.testing.reference), in float64.

Everything runs inside `jax.enable_x64(True)`, so float32 rounding cannot hide a mistake: the two sides differ
only by float64 rounding (eps = 2.2e-16) in a different order of operations. A wrong term, sign, index or
rule shows up at 1e-6 or more, far above every tolerance used here.
"""

from __future__ import annotations

import dataclasses
import itertools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import default_hyper

from reach_jax import env
from reach_jax.agent import exploration, learner, network
from reach_jax.config import ConditionConfig, Config, NetworkConfig, TaskConfig, compat, condition, from_partial
from reach_jax.engine import random_stream, rollout
from reach_jax.engine.chunk import make_trace
from reach_jax.engine.learner_state import init_learner
from reach_jax.env import curriculum, protocol, task
from reach_jax.physics import arm, encoding, fields, sensor
from reach_jax.testing import reference

CFG = Config()
N_SAMPLES = 8  # random draws per comparison: enough to hit every branch, few enough to stay fast

# Single-function tolerance: a handful of float64 operations (at most a 2x2 solve with condition number < 1e2,
# or a 125-term dot product) accumulate well under 1e3 eps ~ 2e-13 relative error.
RTOL = 1e-12
ATOL = 1e-12


@pytest.fixture(autouse=True)
def x64():
    """Run every test in float64."""
    with jax.enable_x64(True):
        yield


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)


def _random_states(rng, n):
    """(n, 4) arm states spread over the joint ranges and beyond in velocity [rad, rad/s]."""
    theta1 = rng.uniform(0.0, np.pi / 2, n)
    theta2 = rng.uniform(0.05, np.pi - 0.05, n)
    omega = rng.uniform(-4.0, 4.0, (n, 2))
    return np.column_stack([theta1, theta2, omega])


def _float64_params(params):
    return jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), params)


# ---------------------------------------------------------------------------------------------------------------
# Arm
# ---------------------------------------------------------------------------------------------------------------

VISCOUS = condition(CFG, "viscous").viscous
# Every term of the hand-force field (fields.hand_force), alone and together, with a per-trial random force.
FORCE_CASES = {
    "none": (ConditionConfig(), np.zeros(2)),
    "viscous": (ConditionConfig(viscous=VISCOUS), np.zeros(2)),
    "curl": (ConditionConfig(viscous=((0.0, 13.0), (-13.0, 0.0))), np.zeros(2)),
    "spring": (ConditionConfig(stiffness=((-60.0, 10.0), (10.0, -40.0)), anchor=(-0.05, 0.37)), np.zeros(2)),
    "constant": (ConditionConfig(constant=(5.0, -7.0)), np.zeros(2)),
    "random": (ConditionConfig(), np.array([-8.0, 3.0])),
    "all": (
        ConditionConfig(
            viscous=VISCOUS, stiffness=((-30.0, 0.0), (0.0, -30.0)), anchor=(0.0, 0.4), constant=(2.0, 1.0)
        ),
        np.array([-8.0, 3.0]),
    ),
}


# Compiled once for all force cases: the field and the force are arguments, not constants.
_DSDT = jax.jit(jax.vmap(lambda s, t, b, f: arm.dsdt(s, t, b, f, CFG.arm), in_axes=(0, 0, None, None)))
_RK4 = jax.jit(jax.vmap(lambda s, t, b, f: arm.rk4(s, t, b, f, CFG.arm), in_axes=(0, 0, None, None)))


@pytest.mark.parametrize("case", sorted(FORCE_CASES))
def test_dsdt_and_rk4_match_oracle(case):
    field, force = FORCE_CASES[case]
    rng = _rng(1)
    states = _random_states(rng, N_SAMPLES)
    taus = rng.uniform(-1.0, 1.0, (N_SAMPLES, 2)) * np.array(CFG.arm.tau_max)
    got_d = np.asarray(_DSDT(states, taus, fields.make_field(field), force))
    got_s = np.asarray(_RK4(states, taus, fields.make_field(field), force))
    want_d = np.array([reference.dsdt(s, t, field, force, CFG.arm) for s, t in zip(states, taus, strict=True)])
    want_s = np.array([reference.rk4(s, t, field, force, CFG.arm) for s, t in zip(states, taus, strict=True)])
    # Accelerations reach ~1e2 rad/s^2, so the absolute floor scales with them (RTOL argument above).
    np.testing.assert_allclose(got_d, want_d, rtol=RTOL, atol=ATOL * np.abs(want_d).max())
    # One RK4 step is four dsdt calls combined linearly: the same relative budget holds.
    np.testing.assert_allclose(got_s, want_s, rtol=RTOL, atol=ATOL * np.abs(want_s).max())
    # The external force must matter when present (guards against a field silently ignored on both sides).
    if case != "none":
        plain = np.array(
            [reference.dsdt(s, t, ConditionConfig(), np.zeros(2), CFG.arm) for s, t in zip(states, taus, strict=True)]
        )
        assert np.abs(plain - want_d).max() > 1e-3


_ENV_STEP = jax.jit(lambda s, tau, c: env.step_trial(s, tau, c, task.geometry(CFG), CFG))


@pytest.mark.parametrize("case", sorted(FORCE_CASES))
def test_environment_trial_matches_oracle(case):
    """env.start_trial, observe_trial and step_trial for 80 steps of random torques: the same arm, input, outcomes."""
    spec, force = FORCE_CASES[case]
    rng = _rng(5)
    cond = task.Condition(field=fields.make_field(spec), input_mask=encoding.input_mask(True, CFG))
    start = np.concatenate([reference.inverse_kinematics(np.array([-0.09, 0.34]), CFG.arm), np.zeros(2)])
    target = np.array([-0.01, 0.41])
    trial = env.start_trial(jnp.asarray(start), jnp.asarray(target), jnp.asarray(force))
    state, prev, prev_tau, ref_target = start, start, np.zeros(2), target
    mask = reference.input_mask(True, CFG)
    seen_drift = False
    for t in range(1, 81):
        want_x = reference.observe(state, prev, prev_tau, ref_target, mask, CFG)
        got_x = env.observe_trial(trial, cond, task.geometry(CFG), CFG)
        np.testing.assert_allclose(np.asarray(got_x), want_x, rtol=0, atol=1e-9)
        tau = rng.uniform(-0.5, 0.5, 2) * np.array(CFG.arm.tau_max)
        trial, outcome = _ENV_STEP(trial, jnp.asarray(tau), cond)
        moved = reference.arm_step(state, tau, spec, force, CFG.arm)
        hand = reference.hand_position(moved[:2], CFG.arm)
        out = reference.is_out(moved, CFG.arm)
        goal = (not out) and reference.goal_reached(hand, reference.hand_velocity(moved, CFG.arm), ref_target, CFG)
        cap = not goal and not out and t >= round(CFG.task.max_trial_time / CFG.arm.dt)
        new_target, drifted = reference.drift_target(ref_target, hand, t, CFG)
        # States carry float64 rounding from step to step; 1e-9 leaves room for 80 steps, not for a model change.
        np.testing.assert_allclose(np.asarray(trial.arm), moved, rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(trial.target), new_target, rtol=0, atol=1e-9)
        assert (bool(outcome.goal), bool(outcome.out_of_range), bool(outcome.cap)) == (goal, out, cap)
        assert int(trial.t) == t and bool(trial.drifted) == (seen_drift or drifted)
        seen_drift = seen_drift or drifted
        if out:
            break
        state, prev, prev_tau, ref_target = moved, state, tau, new_target


def test_kinematics_match_oracle():
    rng = _rng(2)
    thetas = _random_states(rng, N_SAMPLES)[:, :2]
    fk = jax.jit(jax.vmap(lambda th: arm.hand_position(th, CFG.arm)))
    jac = jax.jit(jax.vmap(lambda th: arm.jacobian(th, CFG.arm)))
    ik = jax.jit(jax.vmap(lambda h: arm.inverse_kinematics(h, CFG.arm)))
    hands = np.array([reference.hand_position(th, CFG.arm) for th in thetas])
    # Positions are ~0.3 m and angles ~1 rad: float64 trig is exact to a few eps.
    np.testing.assert_allclose(np.asarray(fk(thetas)), hands, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(
        np.asarray(jac(thetas)), np.array([reference.jacobian(th, CFG.arm) for th in thetas]), rtol=RTOL, atol=ATOL
    )
    # J^-1 in closed form against a LAPACK inverse of the oracle's J; theta2 >= 0.05 rad keeps det J away from 0.
    inv = jax.jit(jax.vmap(lambda th: arm.inverse_jacobian(th, CFG.arm)))
    want_inv = np.array([np.linalg.inv(reference.jacobian(th, CFG.arm)) for th in thetas])
    np.testing.assert_allclose(np.asarray(inv(thetas)), want_inv, rtol=1e-10, atol=1e-10 * np.abs(want_inv).max())
    # IK goes through arccos, whose derivative grows near a straight or folded arm; theta2 is kept >= 0.05 rad
    # from both, which bounds the amplification of eps to ~1/sin(0.05) = 20, still far below 1e-10.
    got_ik = np.asarray(ik(hands))
    np.testing.assert_allclose(got_ik, np.array([reference.inverse_kinematics(h, CFG.arm) for h in hands]), atol=1e-10)
    np.testing.assert_allclose(got_ik, thetas, atol=1e-10)  # IK inverts FK on the theta2 in (0, pi) branch


@pytest.mark.parametrize("one_link", [True, False])
def test_elbow_stop_and_limits_match_oracle(one_link):
    cfg = dataclasses.replace(CFG.arm, one_link_stop=one_link)
    stop = cfg.theta2_stop
    states = np.array(
        [
            [0.5, stop + 0.01, 0.3, 2.0],  # past the stop, moving outward: clamped, omega2 -> 0
            [0.5, stop + 0.01, 0.3, -1.0],  # past the stop, moving back: clamped, omega2 kept
            [0.5, stop - 0.01, 0.3, 2.0],  # inside: untouched
            [-0.01, 1.0, 0.0, 0.0],  # theta1 below its range: out
            [np.pi / 2 + 0.01, 1.0, 0.0, 0.0],  # theta1 above its range: out
            [0.5, -0.01, 0.0, 0.0],  # theta2 below 0: out
            [0.0, 0.0, 0.0, 0.0],  # exactly on the limits: not out
            [np.pi / 2, 1.0, 0.0, 0.0],
        ]
    )
    stop_j = jax.jit(jax.vmap(lambda s: arm.elbow_stop(s, cfg)))
    out_j = jax.jit(jax.vmap(lambda s: arm.is_out(s, cfg)))
    want = np.array([reference.elbow_stop(s, cfg) for s in states])
    # The clamp is pure selections, exact; the one link's impact moves omega2's momentum to omega1.
    np.testing.assert_allclose(np.asarray(stop_j(states)), want, rtol=0 if not one_link else RTOL, atol=0)
    np.testing.assert_array_equal(np.asarray(out_j(states)), [reference.is_out(s, cfg) for s in states])
    assert want[0, 1] == stop and want[0, 3] == 0.0 and want[1, 3] == -1.0  # the oracle itself obeys model §1
    assert (want[0, 2] != 0.3) == one_link and want[1, 2] == 0.3

    # Full steps into, on and off the stop: an impact, a step held on it (the elbow torque presses), a release.
    null = ConditionConfig()
    step_j = jax.jit(lambda s, t: arm.step(s, t, fields.make_field(null), jnp.zeros(2), cfg))
    cases = [
        ([0.6, stop - 0.02, 0.0, 3.0], [0.0, cfg.tau_max[1]]),
        ([0.6, stop, 0.4, 0.0], [1.0, cfg.tau_max[1]]),
        ([0.6, stop, 0.4, 0.0], [1.0, -cfg.tau_max[1]]),
    ]
    for start, tau in cases:
        start, tau = np.array(start), np.array(tau)
        want_step = reference.arm_step(start, tau, null, np.zeros(2), cfg)
        np.testing.assert_allclose(np.asarray(step_j(start, tau)), want_step, rtol=RTOL, atol=ATOL)
    assert reference.arm_step(*map(np.array, cases[0]), null, np.zeros(2), cfg)[1] == stop  # really hits the stop
    held = reference.held_on_stop(np.array(cases[1][0]), np.array(cases[1][1]), null, np.zeros(2), cfg)
    assert held == one_link  # the oracle holds it only under the one-link rule


# ---------------------------------------------------------------------------------------------------------------
# Sensor
# ---------------------------------------------------------------------------------------------------------------


def _sensor_cases(rng):
    (x0, y0), (x1, y1) = reference.field_bounds(CFG.sensor)
    c = CFG.sensor.cell_size
    lo, hi = np.array([x0 - c, y0 - c]), np.array([x1 + c, y1 + c])
    cases = []
    for _ in range(N_SAMPLES):  # anywhere, including partly or wholly outside the field
        cases.append((rng.uniform(lo, hi), rng.uniform(lo, hi)))
    for _ in range(N_SAMPLES):  # overlapping squares
        h = rng.uniform(lo, hi)
        cases.append((h, h + rng.uniform(-c, c, 2)))
    corner = np.array([x0, y0])
    cases.append((corner, corner + 0.3 * c))  # overlapping and partly outside at a corner
    cases.append((corner + 0.5 * c, corner + 0.5 * c))  # identical squares exactly on a cell
    return cases


def test_sensor_matches_oracle():
    render = jax.jit(jax.vmap(lambda h, t: sensor.render(h, t, sensor.placement(CFG.sensor), CFG.sensor.n_cells)))
    cases = _sensor_cases(_rng(3))
    hands = np.array([h for h, _ in cases])
    targets = np.array([t for _, t in cases])
    got = np.asarray(render(hands, targets))
    want = np.array([reference.render(h, t, CFG.sensor) for h, t in cases])
    # Areas are products of ~0.04 m edges divided by the cell area: a few eps of relative error each.
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
    assert (want > 0).any(axis=1).sum() >= N_SAMPLES  # most cases actually light up cells
    assert want.min() >= 0.0 and want.max() <= 1.0 + 1e-12


def test_sensor_total_area():
    """Independent of both codes: inside the field, disjoint squares cover 2 cells' worth, identical squares 1."""
    render = jax.jit(lambda h, t: sensor.render(h, t, sensor.placement(CFG.sensor), CFG.sensor.n_cells))
    (x0, y0), _ = reference.field_bounds(CFG.sensor)
    c = CFG.sensor.cell_size
    hand = np.array([x0 + 1.3 * c, y0 + 1.7 * c])
    far = np.array([x0 + 3.6 * c, y0 + 3.2 * c])
    near = hand + np.array([0.25 * c, -0.5 * c])  # overlap area (0.75 c)(0.5 c)
    for img in (np.asarray(render(hand, far)), reference.render(hand, far, CFG.sensor)):
        assert img.sum() == pytest.approx(2.0, abs=1e-12)
    for img in (np.asarray(render(hand, hand)), reference.render(hand, hand, CFG.sensor)):
        assert img.sum() == pytest.approx(1.0, abs=1e-12)
    for img in (np.asarray(render(hand, near)), reference.render(hand, near, CFG.sensor)):
        assert img.sum() == pytest.approx(2.0 - 0.75 * 0.5, abs=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# Encoding
# ---------------------------------------------------------------------------------------------------------------


def test_localize_matches_oracle():
    lo, hi, n = 0.0, np.pi, 12
    spacing = (hi - lo) / (n - 1)
    xs = np.concatenate(
        [
            np.linspace(lo - 1.0, hi + 1.0, 37),  # out of range on both sides
            lo + spacing * np.arange(n),  # exactly on the centres
            [lo, hi, lo - 1e-9, hi + 1e-9],
        ]
    )
    loc = jax.jit(jax.vmap(lambda x: encoding.localize(x, lo, hi, n)))
    got = np.asarray(loc(xs))
    want = np.array([reference.localize(x, lo, hi, n) for x in xs])
    # Two subtractions and a division per unit: a few eps.
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(want.sum(axis=1), 1.0, atol=1e-12)  # activations sum to 1 (model §3)
    assert ((want > 0).sum(axis=1) <= 2).all()


def test_encode_and_mask_match_oracle():
    rng = _rng(4)
    enc = jax.jit(jax.vmap(lambda v, s, p, t: encoding.encode(v, s, p, t, CFG)))
    visual = rng.uniform(0.0, 1.0, (N_SAMPLES, CFG.sensor.n_cells**2))
    states, prev, taus = _joint_signals(rng, N_SAMPLES)
    got = np.asarray(enc(visual, states, prev, taus))
    want = np.array([reference.encode(*a, CFG) for a in zip(visual, states, prev, taus, strict=True)])
    assert got.shape == (N_SAMPLES, 125)
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
    for use_past in (True, False):
        mask = reference.input_mask(use_past, CFG)
        np.testing.assert_array_equal(np.asarray(encoding.input_mask(use_past, CFG)), mask)
    assert reference.input_mask(False, CFG).sum() == 125 - 60


def _joint_signals(rng, n):
    """Angles, velocities and torques spread to 1.5x beyond their coded ranges, so saturation is exercised."""
    scale = np.array([np.pi / 2, np.pi, np.pi, np.pi]) * 1.5
    states = rng.uniform(-1.0, 1.0, (n, 4)) * scale
    prev = rng.uniform(-1.0, 1.0, (n, 4)) * scale
    taus = rng.uniform(-1.5, 1.5, (n, 2)) * np.array(CFG.arm.tau_max)
    return states, prev, taus


def test_coded_support_holds_every_nonzero_unit():
    states, prev, taus = _joint_signals(_rng(21), N_SAMPLES)
    e = CFG.encoding
    # Centre values and range ends, where a unit is exactly 1 and its neighbours exactly 0.
    states[:5, 0] = np.linspace(*e.theta_ranges[0], 5)
    prev[:5, 2] = np.linspace(-e.omega_range, e.omega_range, 5)
    visual = np.zeros((N_SAMPLES, CFG.sensor.n_cells**2))
    x = np.asarray(jax.vmap(lambda v, s, p, t: encoding.encode(v, s, p, t, CFG))(visual, states, prev, taus))
    rows = np.asarray(jax.vmap(lambda s, p, t: encoding.coded_support(s, p, t, CFG))(states, prev, taus))
    n_codes = 10  # theta1, theta2, omega1, omega2 now and one step before, tau1, tau2
    assert rows.shape == (N_SAMPLES, 2 * n_codes)
    for xi, ri in zip(x, rows, strict=True):
        assert len(set(ri)) == len(ri) and ri.min() >= CFG.sensor.n_cells**2 and ri.max() < 125
        outside = np.delete(xi, ri)
        assert np.all(outside == 0.0)  # exactly zero, so skipping those rows changes nothing
        assert xi[ri].sum() == pytest.approx(n_codes)  # each code's two units sum to 1


# ---------------------------------------------------------------------------------------------------------------
# Network and TS update
# ---------------------------------------------------------------------------------------------------------------

NET_CFG = dataclasses.replace(CFG, network=dataclasses.replace(NetworkConfig(), output_init=0.5))


def _random_params(seed: int):
    """float64 params with non-zero output weights and biases, so that every leaf matters."""
    params = _float64_params(network.init_params(jax.random.PRNGKey(seed), NET_CFG))
    rng = _rng(seed)
    return jax.tree.map(lambda a: a + rng.uniform(-0.3, 0.3, a.shape), params)


def test_network_matches_oracle():
    params = _random_params(5)
    xs = _rng(6).uniform(0.0, 1.0, (N_SAMPLES, 125))
    got = np.asarray(jax.jit(lambda p, x: network.apply(p, x, NET_CFG))(params, xs))
    layers = reference.layers_from_flax(params)
    want = np.array([reference.forward(layers, x)[-1] for x in xs])
    # 125-term dot products of O(1) terms through three sigmoids (slope <= 1/4): ~1e2 eps.
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
    assert np.abs(want).max() > 1e-2 and np.abs(want).max() < 0.5


def test_oracle_backprop_matches_finite_differences():
    """The oracle's hand-written backprop is itself right: its SGD step equals -lr * numerical gradient."""
    layers = reference.layers_from_flax(_random_params(7))
    rng = _rng(8)
    x, target, lr = rng.uniform(0, 1, 125), rng.uniform(-0.4, 0.4, 3), 1.0
    new, _ = reference.sgd_step(layers, x, target, lr)

    def loss(ls):
        return 0.5 * np.sum((target - reference.forward(ls, x)[-1]) ** 2)

    h = 1e-6
    for i, (w, b) in enumerate(layers):
        for name, arr, idx in (("W", w, (int(rng.integers(w.shape[0])), int(rng.integers(w.shape[1])))), ("b", b, 0)):
            plus = [(ww.copy(), bb.copy()) for ww, bb in layers]
            minus = [(ww.copy(), bb.copy()) for ww, bb in layers]
            (plus[i][0] if name == "W" else plus[i][1])[idx] += h
            (minus[i][0] if name == "W" else minus[i][1])[idx] -= h
            numeric = (loss(plus) - loss(minus)) / (2 * h)
            step = (new[i][0] if name == "W" else new[i][1])[idx] - arr[idx]
            # Central differences: O(h^2) ~ 1e-12 truncation plus eps * loss / h ~ 1e-10 rounding.
            assert step == pytest.approx(-lr * numeric, abs=1e-8)


def _pendings(rng, n_in):
    base = dict(x=rng.uniform(0, 1, n_in), out=rng.uniform(-0.4, 0.4, 3), rnd=rng.uniform(-0.2, 0.2, 2))
    lc = CFG.learner
    return {
        "regular": dict(base, valid=True, terminal=False, reward=0.0),
        "goal": dict(base, valid=True, terminal=True, reward=lc.reward_goal),
        "out": dict(base, valid=True, terminal=True, reward=lc.reward_out),
        "invalid": dict(base, valid=False, terminal=False, reward=0.0),
    }


_TS_UPDATE = jax.jit(lambda p, x, pe, nm, lr: learner.ts_update(p, x, pe, nm, lr, NET_CFG))  # compiled once


@pytest.mark.parametrize("n_max", [100.0, 1.0])  # 1.0 drives p(t) - P_range / N_max below the critic floor
@pytest.mark.parametrize("kind", ["regular", "goal", "out", "invalid"])
def test_ts_update_matches_oracle(kind, n_max):
    params = _random_params(9)
    rng = _rng(10)
    pend = _pendings(rng, 125)[kind]
    x_now = rng.uniform(0, 1, 125)
    lr = 0.7
    jax_pend = learner.Pending(**{k: jnp.asarray(v) for k, v in pend.items()})
    new_params, out_now, loss = _TS_UPDATE(params, x_now, jax_pend, jnp.asarray(n_max), jnp.asarray(lr))

    ref_pend = reference.Pending(**pend)
    layers, ref_out, ref_loss = reference.ts_update(
        reference.layers_from_flax(params), x_now, ref_pend, n_max, lr, NET_CFG
    )
    # Forward, targets, one backprop and an SGD step with lr < 1: each weight is a short chain of ~1e2 ops.
    chex.assert_trees_all_close(
        jax.tree.map(np.asarray, new_params), reference.layers_to_flax(layers), rtol=RTOL, atol=ATOL
    )
    np.testing.assert_allclose(np.asarray(out_now), ref_out, rtol=RTOL, atol=ATOL)
    assert float(loss) == pytest.approx(ref_loss, rel=RTOL, abs=ATOL)

    moved = max(
        float(np.abs(np.asarray(a) - b).max())
        for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(new_params), strict=True)
    )
    if kind == "invalid":
        assert moved == 0.0
    else:
        assert moved > 1e-4  # the update really changed the weights

    # The targets themselves, including which rule applied.
    tgt = np.asarray(learner.ts_targets(jax_pend, jnp.asarray(ref_out[0]), jnp.asarray(n_max), CFG.learner))
    ref_tgt = reference.ts_targets(ref_pend, ref_out[0], n_max, CFG.learner)
    np.testing.assert_allclose(tgt, ref_tgt, rtol=RTOL, atol=ATOL)
    if kind in ("regular", "invalid") and n_max == 1.0:
        assert ref_tgt[0] == CFG.learner.critic_floor  # the floor guard was exercised
    if kind in ("goal", "out"):
        assert ref_tgt[0] == pytest.approx(pend["reward"] - CFG.learner.p_range / n_max)


_TS_STEP = jax.jit(lambda p, x, pe, nm, lr: learner.ts_step(p, x, pe, nm, lr, NET_CFG))  # the training hot path


@pytest.mark.parametrize("carried", [False, True])
@pytest.mark.parametrize("kind", ["regular", "goal", "out", "invalid"])
def test_hand_written_ts_step_equals_autodiff_and_optax(kind, carried):
    """The fast path (hand-written backprop, carried layer-1 pre-activation) equals flax autodiff + optax SGD."""
    params = _random_params(11)
    rng = _rng(12)
    pend = {k: jnp.asarray(v) for k, v in _pendings(rng, 125)[kind].items()}
    x_now, lr, n_max = jnp.asarray(rng.uniform(0, 1, 125)), jnp.asarray(0.7), jnp.asarray(30.0)
    (w1, b1), *_ = network.dense_layers(params)
    u1 = pend["x"] @ w1 + b1 if carried else None
    new, out, loss, u1_next = _TS_STEP(params, x_now, learner.Pending(**pend, u1=u1), n_max, lr)
    want_new, want_out, want_loss = _TS_UPDATE(params, x_now, learner.Pending(**pend), n_max, lr)
    # Same arithmetic in another order: ~1e2 float64 operations per weight.
    chex.assert_trees_all_close(new, want_new, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(np.asarray(out), np.asarray(want_out), rtol=RTOL, atol=ATOL)
    assert float(loss) == pytest.approx(float(want_loss), rel=RTOL, abs=ATOL)
    # The carried pre-activation is x(t)'s under the *updated* weights (rank-1 correction of the old one).
    (w1_new, b1_new), *_ = network.dense_layers(new)
    np.testing.assert_allclose(np.asarray(u1_next), np.asarray(x_now @ w1_new + b1_new), rtol=RTOL, atol=ATOL)


def test_the_actor_target_bound_clips_eq_2s_actor_targets_in_every_path():
    """hyper actor_target_bound: the targets of the fast path, the autodiff path and the oracle, clipped alike."""
    params, rng = _random_params(15), _rng(16)
    pend = {k: jnp.asarray(v) for k, v in _pendings(rng, 125)["regular"].items()}
    pend["out"] = jnp.asarray([0.1, 0.49, -0.49])  # saturated: eq. 2's targets lie past 0.45
    pend["rnd"] = jnp.asarray([0.2, -0.2])
    x_now, lr, n_max, bound = jnp.asarray(rng.uniform(0, 1, 125)), jnp.asarray(0.7), jnp.asarray(30.0), 0.45
    p_now = jnp.asarray(0.4)  # dp = 0.3: the actor targets move by 0.06 away from 0
    free = np.asarray(learner.ts_targets(learner.Pending(**pend), p_now, n_max, CFG.learner))
    clipped = np.asarray(learner.ts_targets(learner.Pending(**pend), p_now, n_max, CFG.learner, 0.0, bound))
    assert np.all(np.abs(free[1:]) > bound) and np.array_equal(clipped[1:], [bound, -bound])
    assert clipped[0] == free[0]  # the critic's target is eq. 1's, whatever the bound
    ref_pend = reference.Pending(**{k: np.asarray(v) for k, v in pend.items()})
    ref = reference.ts_targets(ref_pend, float(p_now), float(n_max), CFG.learner, 0.0, bound)
    np.testing.assert_allclose(clipped, ref, rtol=RTOL, atol=ATOL)
    step = jax.jit(lambda b: learner.ts_step(params, x_now, learner.Pending(**pend), n_max, lr, NET_CFG, None, 0.0, b))
    update = jax.jit(lambda b: learner.ts_update(params, x_now, learner.Pending(**pend), n_max, lr, NET_CFG, 0.0, b))
    fast, slow = step(jnp.asarray(bound)), update(jnp.asarray(bound))
    chex.assert_trees_all_close(fast[0], slow[0], rtol=RTOL, atol=ATOL)
    layers, _, ref_loss = reference.ts_update(
        reference.layers_from_flax(params), np.asarray(x_now), ref_pend, float(n_max), float(lr), NET_CFG, 0.0, bound
    )
    chex.assert_trees_all_close(
        jax.tree.map(np.asarray, fast[0]), reference.layers_to_flax(layers), rtol=RTOL, atol=ATOL
    )
    assert float(fast[2]) == pytest.approx(ref_loss, rel=RTOL, abs=ATOL)
    assert float(fast[2]) != pytest.approx(float(step(jnp.asarray(0.0))[2]), rel=1e-6)  # the bound changed the step


_TS_STEP_SPARSE = jax.jit(lambda p, x, pe, nm, lr, r: learner.ts_step(p, x, pe, nm, lr, NET_CFG, r))


@pytest.mark.parametrize("kind", ["regular", "goal", "invalid"])
def test_sparse_layer1_ts_step_equals_dense(kind):
    """Reading and writing only the visual and coded-support rows of W1 equals the dense step on real inputs."""
    params = _random_params(13)
    rng = _rng(14)
    states, prev, taus = _joint_signals(rng, 3)
    visual = rng.uniform(0.0, 1.0, (3, CFG.sensor.n_cells**2))
    xs = [encoding.encode(visual[i], states[i], prev[i], taus[i], CFG) for i in range(2)]
    rows = [encoding.coded_support(states[i], prev[i], taus[i], CFG) for i in range(2)]
    pend = {k: jnp.asarray(v) for k, v in _pendings(rng, 125)[kind].items()}
    pend["x"] = xs[0]
    n_max, lr = jnp.asarray(30.0), jnp.asarray(0.7)
    (w1, b1), *_ = network.dense_layers(params)
    u1 = xs[0] @ w1 + b1
    dense = _TS_STEP(params, xs[1], learner.Pending(**pend, u1=u1), n_max, lr)
    sparse = _TS_STEP_SPARSE(params, xs[1], learner.Pending(**pend, u1=u1), n_max, lr, rows[1])
    # Only the order of the additions differs.
    chex.assert_trees_all_close(sparse, dense, rtol=RTOL, atol=ATOL)
    rows_touched = np.flatnonzero(np.any(np.asarray(network.dense_layers(sparse[0])[0][0] != w1), axis=1))
    assert set(rows_touched) <= set(range(CFG.sensor.n_cells**2)) | set(np.asarray(rows[0]))


def test_n_max_and_curriculum_match_oracle():
    lam = CFG.learner.lam
    upd = jax.jit(lambda n, k: learner.update_n_max(n, k, jnp.asarray(lam)))
    for n_max, n_steps in [(100.0, 150), (100.0, 99), (100.0, 100), (10.0, 3)]:
        got = float(upd(jnp.asarray(n_max), jnp.asarray(n_steps, jnp.int32)))
        assert got == pytest.approx(reference.update_n_max(n_max, n_steps, lam), rel=1e-15)
    cur = jax.jit(lambda d, g, dr, full, early: curriculum.staircase(d, g, dr, full, task.geometry(CFG), CFG, early))
    lo, hi = reference.curriculum_bounds(CFG)
    for d in (lo, 0.5 * (lo + hi), hi):
        for goal, drifted, full, early in itertools.product((True, False), repeat=4):
            flags = (goal, drifted, full, early)
            assert float(cur(jnp.asarray(d), *map(jnp.asarray, flags))) == pytest.approx(
                reference.update_curriculum(d, goal, drifted, full, CFG, early), abs=1e-15
            )
    # A drift-aided success: neutral once the field was full, or at any time with `early`; else it shrinks.
    mid = 0.5 * (lo + hi)
    assert reference.update_curriculum(mid, True, True, False, CFG) < mid
    assert reference.update_curriculum(mid, True, True, False, CFG, early=True) == mid


def test_trial_placement_and_drift_match_oracle():
    rng = _rng(11)
    place = jax.jit(lambda d, dist, field: task.place_trial(d, dist, field, task.geometry(CFG), CFG))
    random, null = ConditionConfig(random=(8.0, 3.0)), ConditionConfig()
    drift = jax.jit(lambda tg, h, t: task.drift_target(tg, h, t, CFG))
    lo, hi = reference.curriculum_bounds(CFG)
    for dist in (lo, 0.5 * (lo + hi), hi):
        draws = reference.Draws(rng.random(2), rng.random((CFG.task.target_candidates, 2)), rng.random(2))
        jd = task.TrialDraws(*(jnp.asarray(a) for a in draws))
        s, tg, f = place(jd, jnp.asarray(dist), fields.make_field(random))
        rs, rtg, rf = reference.place_trial(draws, dist, random, CFG)
        # Affine maps of the draws and an IK (1e-10 bound as in test_kinematics_match_oracle).
        np.testing.assert_allclose(np.asarray(s), rs, atol=1e-10)
        np.testing.assert_allclose(np.asarray(tg), rtg, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(np.asarray(f), rf, rtol=RTOL, atol=ATOL)
    # All candidates touch the start: the last one is taken.
    draws = reference.Draws(np.full(2, 0.5), np.full((CFG.task.target_candidates, 2), 0.5), np.zeros(2))
    draws = draws._replace(target=draws.target + 0.01 * np.arange(CFG.task.target_candidates)[:, None])
    _, tg, _ = place(task.TrialDraws(*(jnp.asarray(a) for a in draws)), jnp.asarray(lo), fields.make_field(null))
    _, rtg, _ = reference.place_trial(draws, lo, null, CFG)
    np.testing.assert_allclose(np.asarray(tg), rtg, rtol=RTOL, atol=ATOL)

    hand, target = np.array([-0.05, 0.37]), np.array([0.0, 0.40])
    before = round(CFG.task.drift_after / CFG.arm.dt) - 1
    for t, tgt in ((before, target), (before + 1, target), (before + 1, hand + 1e-4)):
        got, moved = drift(jnp.asarray(tgt), jnp.asarray(hand), jnp.asarray(t, jnp.int32))
        want, want_moved = reference.drift_target(tgt, hand, t, CFG)
        np.testing.assert_allclose(np.asarray(got), want, rtol=RTOL, atol=ATOL)
        assert bool(moved) == want_moved


def test_drift_gate_and_failure_share_match_oracle():
    rate = 1.0 / 300
    h = {"drift_gate": 0.0, "drift_gate_trials": 300}
    after = jax.jit(lambda f, g, d: curriculum.failure_after(f, g, d, jnp.asarray(rate)))
    for failure, goal, drifted in itertools.product((0.0, 0.3, 1.0), (True, False), (True, False)):
        got = float(after(jnp.asarray(failure), jnp.asarray(goal), jnp.asarray(drifted)))
        assert got == pytest.approx(reference.update_failure(failure, goal, drifted, h), abs=1e-15)
    # Only a success without drift lowers the share.
    assert reference.update_failure(0.3, True, False, h) < 0.3 < reference.update_failure(0.3, True, True, h)
    start = curriculum.initial(task.geometry(CFG), CFG)
    is_open = jax.jit(lambda f, g: curriculum.drift_open(start.replace(failure=f), g))
    for failure, gate in itertools.product((0.0, 0.2, 0.5, 1.0), (0.0, 0.2, 0.7, 1.0)):
        want = reference.drift_open(failure, {**h, "drift_gate": gate})
        assert bool(is_open(jnp.asarray(failure), jnp.asarray(gate))) == want
        assert want == (gate == 0.0 or failure > gate)


def _still_arm_trial(gate: float, failure: float):
    """Per step of cap + 1 (goal, cap, the trial drifted before, the curriculum after) of an arm at rest 5 cm from
    its target under torque 0, from failure share `failure`."""
    plan = protocol.make_plan("none", CFG)
    draws = task.draw_trial(jax.random.PRNGKey(0), CFG)
    state = env.reset(draws, plan, CFG)
    hand = np.array([-0.05, 0.37])
    start = np.concatenate([reference.inverse_kinematics(hand, CFG.arm), np.zeros(2)])
    trial = env.start_trial(jnp.asarray(start), jnp.asarray(hand + [0.05, 0.0]), jnp.zeros(2))
    state = state.replace(trial=trial, curriculum=state.curriculum.replace(failure=jnp.asarray(failure)))
    params = env.EnvParams(plan, jnp.asarray(False), jnp.asarray(gate), jnp.asarray(1.0 / 300))
    cap = round(CFG.task.max_trial_time / CFG.arm.dt)

    def body(s, _):
        new, outcome = env.step(s, jnp.zeros(2), draws, params, CFG)
        return new, (outcome.goal, outcome.cap, s.trial.drifted, new.curriculum)

    _, per_step = jax.jit(lambda s: jax.lax.scan(body, s, None, length=cap + 1))(state)
    return jax.tree.map(np.asarray, per_step)


@pytest.mark.parametrize("gate", [0.0, 0.1, 0.5])
def test_a_closed_drift_gate_runs_a_long_trial_to_its_cap(gate):
    """Failure share 0.2: gate 0 (off) and 0.1 let the target drift to the resting hand, 0.5 keeps it away."""
    goal, capped, drifted, cur = _still_arm_trial(gate, 0.2)
    cap = round(CFG.task.max_trial_time / CFG.arm.dt)
    first_end = int(np.argmax(goal | capped))
    lo = reference.curriculum_bounds(CFG)[0]
    if gate == 0.5:
        assert first_end == cap - 1 and capped[first_end] and not drifted.any()  # the cap, without drift
    else:
        onset = round(CFG.task.drift_after / CFG.arm.dt)
        assert onset < first_end < cap - 1 and goal[first_end] and drifted[first_end]  # a drift-aided goal
    # Either way a failure for the curriculum (at its floor the distance stays) and for the gate's share.
    assert cur.distance[first_end] == pytest.approx(lo)
    assert cur.failure[first_end - 1] == 0.2 and cur.failure[first_end] == pytest.approx(0.2 + (1.0 - 0.2) / 300)


def _n_max_after_success(drifted: bool, clean: float) -> float:
    """N_max after a learner at rest on its target ends a 61-step trial at the goal (noise 0, actor at 0)."""
    plan = protocol.make_plan("none", CFG)
    state = init_learner(jax.random.PRNGKey(0), plan, CFG)
    params = _float64_params(state.agent.params)
    hand = arm.hand_position(state.env.trial.arm[:2], CFG.arm)
    trial = state.env.trial.replace(target=hand, t=jnp.asarray(60, jnp.int32), drifted=jnp.asarray(drifted))
    state = state.replace(env=state.env.replace(trial=trial), agent=state.agent.replace(params=params))
    h = default_hyper(CFG)._replace(noise=jnp.asarray(0.0), n_max_clean=jnp.asarray(clean))
    u = random_stream.step_uniforms(state.key, 0, 1, CFG)[0]
    new, info = jax.jit(lambda s, h: rollout.learner_step(s, u, plan, h, CFG))(state, h)
    assert bool(info.goal)
    return float(new.agent.n_max)


def test_n_max_from_clean_successes_skips_a_drift_aided_one():
    decayed = reference.update_n_max(CFG.learner.n_max_init, 61, CFG.learner.lam)  # 61 < lam N_max: lam N_max
    assert _n_max_after_success(drifted=True, clean=0.0) == pytest.approx(decayed)  # eq. 3 on every success
    assert _n_max_after_success(drifted=True, clean=1.0) == CFG.learner.n_max_init  # a drift-aided one: unchanged
    assert _n_max_after_success(drifted=False, clean=1.0) == pytest.approx(decayed)  # a clean one counts


def test_actor_signal_gain_halves_the_actors_step_and_leaves_the_critics():
    """g = 0.5: the output layer's actor columns move half as far, its critic column as far; the oracle agrees."""
    params = _random_params(15)
    rng = _rng(16)
    pend = _pendings(rng, 125)["regular"]
    pend["out"] = np.asarray(network.apply(params, jnp.asarray(pend["x"]), NET_CFG))  # acted with these weights
    x_now, n_max, lr = rng.uniform(0, 1, 125), 30.0, 0.7
    h = default_hyper(CFG)
    steps = {}
    for g in (1.0, 0.5):
        gain = exploration.actor_gain(h._replace(actor_signal_gain=jnp.asarray(g)), jnp.asarray(1.0))
        jax_pend = learner.Pending(**{k: jnp.asarray(v) for k, v in pend.items()}, gain=gain)
        new, _, _, _ = _TS_STEP(params, jnp.asarray(x_now), jax_pend, jnp.asarray(n_max), jnp.asarray(lr))
        ref_gain = reference.actor_gain(1.0, {**h._asdict(), "actor_signal_gain": g, "actor_gain_power": 0.0})
        layers, _, _ = reference.ts_update(
            reference.layers_from_flax(params), x_now, reference.Pending(**pend, gain=ref_gain), n_max, lr, NET_CFG
        )
        chex.assert_trees_all_close(
            jax.tree.map(np.asarray, new), reference.layers_to_flax(layers), rtol=RTOL, atol=ATOL
        )
        steps[g] = np.asarray(network.dense_layers(new)[-1][0] - network.dense_layers(params)[-1][0])
    assert np.abs(steps[1.0]).min() > 1e-6  # every output weight moved
    # Steps are differences of O(1) weights: each carries ~1e-16 of rounding.
    np.testing.assert_allclose(steps[0.5][:, 0], steps[1.0][:, 0], rtol=0, atol=1e-14)  # the critic's step
    np.testing.assert_allclose(steps[0.5][:, 1:], 0.5 * steps[1.0][:, 1:], rtol=0, atol=1e-14)  # the actor's, halved


# ---------------------------------------------------------------------------------------------------------------
# 200-step learner rollout under the same noise
# ---------------------------------------------------------------------------------------------------------------

ROLLOUT_STEPS = 200
# A 1.2 s cap (60 steps) so that trials end at the cap, at the goal and at a limit within 200 steps, and the
# target drifts (after 1 s) in the capped trials. Seeds 2 and 3 together exercise all three ways to end a trial.
# The protocol switches blocks, turns learning off for a block and draws catch trials in two of them; the "mixed"
# condition has the viscous field and a random per-trial force at once, with every input kept (the spring and
# constant terms are checked step by step in test_dsdt_and_rk4_match_oracle; with them no trial reaches the goal).
ROLLOUT_CFG = from_partial(
    {
        "task": {"max_trial_time": 1.2},
        "conditions": {"mixed": {"viscous": [list(r) for r in VISCOUS], "random": [8.0, 8.0]}},
        "protocols": {
            "replay": [
                {"trials": 2, "condition": "mixed"},
                {"trials": 2, "condition": "none", "learning": False, "catch": 0.5, "catch_condition": "mixed"},
                {"trials": 96, "condition": "mixed", "catch": 0.4, "catch_condition": "none"},
            ]
        },
        "train": {"trials": 100, "conditions": [], "protocols": ["replay"]},
    }
)
ROLLOUT_SEEDS = (2, 3)


# Every exploration form on at once (model §5): the bound scaled by the critic's value and gated by the
# curriculum, AR(1) noise, quiet trials, the actor's baseline and its gain. The value range covers the critic's
# outputs of these young networks (about -0.1 to 0.1), so the scaling acts; the gate's width exceeds the
# curriculum's shortfall of about 0.68 here, so the gate relaxes it only in part, and wholly from step 10 of a
# trial on; quiet_every 2 makes every other trial noise-free.
EXPLORATION_FORMS = {
    "noise_value_ratio": 0.25,
    "noise_value_hi": 0.05,
    "noise_value_lo": -0.05,
    "noise_value_gate": 1.0,
    "noise_value_steps": 10,
    "noise_corr": 0.8,
    "actor_baseline": 1.0,
    "actor_gain_power": 2.0,
    "quiet_every": 2,
    "drift_neutral_early": 1.0,
}


# The levers of the drift and the actor's step (model §5): a drift gate whose failure share moves fast (time
# constant 2 trials) from a start below the gate's 0.6, so that it is closed in the first trial, opens after
# failures and closes again after a clean success; N_max from clean successes only; the actor's signal at half its
# size; the actor's targets within +-0.003 (its outputs reach about 0.004 in these 200 steps). An early, fast
# drift (from 0.4 s, 4 mm a step) makes drift-aided successes within 200 steps; on the clipped pick's other values
# (the default of versions 12-13), seeds 6 and 7 then also end trials at each of the goal, a limit and the cap.
LEVERS = {
    **compat.CHANGED_DEFAULTS[14]["learner"],
    "drift_gate": 0.6,
    "drift_gate_trials": 2,
    "n_max_clean": 1.0,
    "actor_signal_gain": 0.5,
    "actor_target_bound": 0.003,
}
LEVERS_TASK = {"drift_gate_start": 0.5, "drift_after": 0.4, "drift_per_step": 0.004}


# Eq. 2 with white noise, every form off: the recipe before config version 9 (its task values are ROLLOUT_CFG's).
EQ2_WHITE = compat.CHANGED_DEFAULTS[9]["learner"]


@pytest.mark.parametrize(
    ("forms", "task_forms", "seeds"),
    [(EQ2_WHITE, {}, ROLLOUT_SEEDS), (EXPLORATION_FORMS, {}, (1, 2)), (LEVERS, LEVERS_TASK, (6, 7))],
    ids=["eq2-white-noise", "exploration-forms", "drift-and-actor-levers"],
)
def test_rollout_replays_in_oracle(forms, task_forms, seeds):
    learner_cfg = dataclasses.replace(ROLLOUT_CFG.learner, **forms)
    cfg = dataclasses.replace(
        ROLLOUT_CFG, learner=learner_cfg, task=dataclasses.replace(ROLLOUT_CFG.task, **task_forms)
    )
    plan = protocol.make_plan("replay", cfg)
    ref_plan = reference.make_plan("replay", cfg)
    hyper = default_hyper(cfg)
    h = {name: float(v) for name, v in hyper._asdict().items()}
    trace = make_trace(cfg, ROLLOUT_STEPS)  # compiled once, run for each seed
    seen = {"goal": 0, "out": 0, "cap": 0, "drift": 0, "catch": 0, "frozen": 0, "on the elbow stop": 0}
    gated = {"closed past the drift onset": 0, "drift-aided goal": 0}
    onset = round(cfg.task.drift_after / cfg.arm.dt)
    for seed in seeds:
        state = init_learner(jax.random.PRNGKey(seed), plan, cfg)
        state = state.replace(agent=state.agent.replace(params=_float64_params(state.agent.params)))
        final, infos = trace(state, plan, hyper)
        infos = jax.tree.map(np.asarray, infos)
        if forms.get("actor_target_bound", 0) > 0:  # the bound binds: without it the same steps learn otherwise
            unbound = trace(state, plan, hyper._replace(actor_target_bound=jnp.zeros_like(hyper.actor_target_bound)))
            assert not np.array_equal(np.asarray(unbound[1].out), infos.out)
        units = 2.0 * np.asarray(random_stream.step_uniforms(state.key, 0, ROLLOUT_STEPS, cfg))[:, :2] - 1.0

        lrn = reference.learner_from_jax(state, ref_plan[0].cond)  # the first block has no catch trials
        recs = []
        for i in range(ROLLOUT_STEPS):
            draws = reference.Draws(*(a[i] for a in infos.draws))
            was_drifted, trials, t, open_ = lrn.drifted, lrn.trials, lrn.t, reference.drift_open(lrn.failure, h)
            lrn, rec = reference.learner_step(lrn, ref_plan, h, cfg.learner.noise, units[i], draws, cfg)
            gated["closed past the drift onset"] += (not open_) and t + 1 == onset
            gated["drift-aided goal"] += rec.goal and was_drifted
            seen["quiet"] = seen.get("quiet", 0) + (not np.any(lrn.pending.rnd))
            seen["drift"] += (not was_drifted) and lrn.drifted
            if lrn.trials > trials:
                block = next(b for b in ref_plan if lrn.trials < b.end)
                seen["catch"] += lrn.cond is block.catch_cond and block.catch > 0
                seen["frozen"] += not lrn.learning
            recs.append(rec)

        # Trial outcomes are discrete: they must agree exactly, step by step.
        for name, field in (("goal", "goal"), ("out", "out_of_range"), ("cap", "cap")):
            want = np.array([getattr(r, field) for r in recs])
            np.testing.assert_array_equal(getattr(infos, field), want, err_msg=name)
            seen[name] += int(want.sum())
        seen["on the elbow stop"] += int(np.sum(infos.arm[:, 1] >= cfg.arm.theta2_stop))  # held there as one link
        # Continuous paths: per-step float64 discrepancies (~1e-15) are carried by the arm and the learning
        # over 200 steps; the damped arm grows them by far less than 1e5 in 4 s, so 1e-9 is a safe bound,
        # while any modelling difference moves them by 1e-6 or more within one step.
        np.testing.assert_allclose(infos.arm, np.array([r.arm for r in recs]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(infos.tau, np.array([r.tau for r in recs]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(infos.rnd, np.array([r.rnd for r in recs]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(infos.x, np.array([r.x for r in recs]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(infos.out, np.array([r.out for r in recs]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(infos.loss, np.array([r.loss for r in recs]), rtol=0, atol=1e-9)
        chex.assert_trees_all_close(
            jax.tree.map(np.asarray, final.agent.params), reference.layers_to_flax(lrn.layers), rtol=0, atol=1e-9
        )
        trial = final.env.trial
        np.testing.assert_allclose(np.asarray(trial.arm), lrn.arm, rtol=0, atol=1e-9)
        np.testing.assert_allclose(np.asarray(trial.target), lrn.target, rtol=0, atol=1e-9)
        assert float(final.agent.n_max) == pytest.approx(lrn.n_max, abs=1e-9)
        assert float(final.env.curriculum.distance) == pytest.approx(lrn.distance, abs=1e-12)
        assert float(final.env.curriculum.failure) == pytest.approx(lrn.failure, abs=1e-12)
        assert int(final.env.trials) == lrn.trials and int(trial.t) == lrn.t and bool(trial.drifted) == lrn.drifted

    # The reset path (and each way of ending a trial, and the drift) was exercised; quiet steps only where asked.
    quiet = seen.pop("quiet")
    assert all(v > 0 for v in seen.values()), seen
    assert (quiet > 0) == (forms.get("quiet_every", 0) > 0), quiet
    # With the levers on, the gate closed in a trial that ran past the drift onset, and a drift-aided success
    # (which N_max then skipped) was replayed.
    assert all(v > 0 for v in gated.values()) == (forms is LEVERS), gated


def test_run_reference_runs():
    """The self-contained NumPy learner runs, ends trials and keeps its state finite."""
    cfg = dataclasses.replace(CFG, task=dataclasses.replace(TaskConfig(), max_trial_time=0.4))
    lrn, counts = reference.run_reference(60, seed=0, cfg=cfg, condition="random")
    assert lrn.steps == 60
    assert sum(counts.values()) == lrn.trials > 0
    assert all(np.isfinite(w).all() and np.isfinite(b).all() for w, b in lrn.layers)
