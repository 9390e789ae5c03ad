"""Plain-NumPy (float64) oracle of the whole model, used only by tests and benchmarks.

It follows the paper's equations line by line and is written independently of the JAX code: no jax import,
explicit loops, np.linalg.solve for eq. 4-5, a hand-written backprop. It can replay a JAX run from the noise
and uniform draws of a JAX run (`reach_jax.engine.random_stream.step_uniforms`), or run on its own numpy RNG
(`run_reference`).

Units: joint angles [rad], joint velocities [rad/s], torques [N m], hand positions [m] in the shoulder frame
(x right, y forward), hand velocities [m/s], hand forces [N], viscous fields [N s/m], time [s]; network signals
are dimensionless; N_max and trial lengths are counted in steps of cfg.arm.dt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from reach_jax.config import (
    ArmConfig,
    ConditionConfig,
    Config,
    LearnerConfig,
    SensorConfig,
    blocks_of,
    condition,
    hyper,
)

# ---------------------------------------------------------------------------------------------------------------
# Arm (eq. 4-5, model §1)
# ---------------------------------------------------------------------------------------------------------------


def _links(cfg: ArmConfig):
    """(M2, l1, l2, s2, I1, I2) of Table 1 from the config."""
    m1, m2 = cfg.mass
    l1, l2 = cfg.length
    s2 = cfg.com_fraction * l2
    i1 = cfg.inertia_factor * m1 * l1 * l1
    i2 = cfg.inertia_factor * m2 * l2 * l2
    return m2, l1, l2, s2, i1, i2


def hand_position(theta, cfg: ArmConfig) -> np.ndarray:
    """Forward kinematics.

    Args: theta (2,) joint angles [rad].
    Returns: (2,) hand position [m].
    """
    _, l1, l2, _, _, _ = _links(cfg)
    elbow = np.array([l1 * math.cos(theta[0]), l1 * math.sin(theta[0])])
    phi = theta[0] + theta[1]
    return elbow + np.array([l2 * math.cos(phi), l2 * math.sin(phi)])


def jacobian(theta, cfg: ArmConfig) -> np.ndarray:
    """d(hand)/d(theta).

    Args: theta (2,) joint angles [rad].
    Returns: (2, 2) [m/rad], column j = d/d theta_j.
    """
    _, l1, l2, _, _, _ = _links(cfg)
    phi = theta[0] + theta[1]
    # Column 2: link 2 turning about the elbow; column 1: the whole arm turning about the shoulder.
    col2 = np.array([-l2 * math.sin(phi), l2 * math.cos(phi)])
    col1 = np.array([-l1 * math.sin(theta[0]), l1 * math.cos(theta[0])]) + col2
    return np.column_stack([col1, col2])


def hand_velocity(state, cfg: ArmConfig) -> np.ndarray:
    """Hand velocity J(theta) omega.

    Args: state (4,) [rad, rad, rad/s, rad/s].
    Returns: (2,) [m/s].
    """
    return jacobian(state[:2], cfg) @ np.asarray(state[2:], dtype=np.float64)


def inverse_kinematics(hand, cfg: ArmConfig) -> np.ndarray:
    """Joint angles with theta2 in (0, pi).

    Args: hand (2,) position [m].
    Returns: (2,) joint angles [rad].
    """
    _, l1, l2, _, _, _ = _links(cfg)
    r = math.hypot(hand[0], hand[1])
    # Law of cosines for the elbow's interior angle, then theta2 is its supplement.
    interior = math.acos(min(1.0, max(-1.0, (l1 * l1 + l2 * l2 - r * r) / (2 * l1 * l2))))
    theta2 = math.pi - interior
    # Angle at the shoulder between link 1 and the shoulder-hand line; theta2 > 0 puts the hand CCW of link 1.
    beta = math.acos(min(1.0, max(-1.0, (r * r + l1 * l1 - l2 * l2) / (2 * l1 * r))))
    theta1 = math.atan2(hand[1], hand[0]) - beta
    return np.array([theta1, theta2])


def inertia_matrix(theta, cfg: ArmConfig) -> np.ndarray:
    """Coefficients of the accelerations in eq. 4-5.

    Args: theta (2,) [rad].
    Returns: (2, 2) [kg m^2].
    """
    m2, l1, _, s2, i1, i2 = _links(cfg)
    c2 = math.cos(theta[1])
    a11 = i1 + i2 + 2 * m2 * l1 * s2 * c2 + m2 * l1**2  # eq. 4, coefficient of theta1''
    a12 = i2 + m2 * l1 * s2 * c2  # eq. 4, coefficient of theta2''
    a21 = i2 + m2 * l1 * s2 * c2  # eq. 5, coefficient of theta1''
    a22 = i2  # eq. 5, coefficient of theta2''
    return np.array([[a11, a12], [a21, a22]])


def hand_force(state, field: ConditionConfig, force, cfg: ArmConfig) -> np.ndarray:
    """External hand force F = B xdot + K (x - x0) + F_const + F_trial.

    Args: state (4,), field a ConditionConfig (viscous [N s/m], stiffness [N/m], anchor [m], constant [N]),
      force (2,) this trial's random force [N].
    Returns: (2,) [N].
    """
    b, k = (np.asarray(m, dtype=np.float64) for m in (field.viscous, field.stiffness))
    hand = hand_position(state[:2], cfg)
    spring = k @ (hand - np.asarray(field.anchor, dtype=np.float64))
    return b @ hand_velocity(state, cfg) + spring + np.asarray(field.constant) + np.asarray(force, dtype=np.float64)


def dsdt(state, tau, field, force, cfg: ArmConfig, held: bool = False) -> np.ndarray:
    """Eq. 4-5 solved for the accelerations; held on the elbow stop, eq. 4 alone with theta2'' = 0 (one link).

    Args: state (4,), tau (2,) [N m], field a ConditionConfig, force (2,) [N], held: the stop holds the elbow.
    Returns: (4,) [rad/s, rad/s^2].
    """
    m2, l1, _, s2, _, _ = _links(cfg)
    b1, b2 = cfg.joint_viscosity
    th2 = state[1]
    w1, w2 = state[2], state[3]
    # Velocity terms of eq. 4 and eq. 5, written as printed.
    v1 = -m2 * l1 * s2 * (2 * w1 + w2) * w2 * math.sin(th2) + b1 * w1
    v2 = m2 * l1 * s2 * w1**2 * math.sin(th2) + b2 * w2
    # The hand force acts on the joints through the transposed Jacobian (virtual work).
    ext = jacobian(state[:2], cfg).T @ hand_force(state, field, force, cfg)
    rhs = np.array([tau[0] + ext[0] - v1, tau[1] + ext[1] - v2])
    a = inertia_matrix(state[:2], cfg)
    if held:  # the stop supplies whatever elbow torque keeps theta2'' = 0
        return np.array([w1, 0.0, rhs[0] / a[0, 0], 0.0])
    acc = np.linalg.solve(a, rhs)
    return np.array([w1, w2, acc[0], acc[1]])


def held_on_stop(state, tau, field, force, cfg: ArmConfig) -> bool:
    """Whether the stop holds the elbow over the next step (model §1): cfg.one_link_stop, the elbow on its stop and
    not leaving it, and its free acceleration pressing it further.

    Args: as `dsdt`.
    """
    if not cfg.one_link_stop or state[1] < cfg.theta2_stop or state[3] < 0.0:
        return False
    return bool(dsdt(state, tau, field, force, cfg)[3] >= 0.0)


def rk4(state, tau, field, force, cfg: ArmConfig) -> np.ndarray:
    """Classical RK4 over cfg.dt, torque held, force re-evaluated per stage, every stage one link when held.

    Args: as `dsdt`.
    Returns: (4,) state.
    """
    h = cfg.dt
    s = np.asarray(state, dtype=np.float64)
    held = held_on_stop(s, tau, field, force, cfg)
    k1 = dsdt(s, tau, field, force, cfg, held)
    k2 = dsdt(s + (h / 2) * k1, tau, field, force, cfg, held)
    k3 = dsdt(s + (h / 2) * k2, tau, field, force, cfg, held)
    k4 = dsdt(s + h * k3, tau, field, force, cfg, held)
    return s + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)


def elbow_stop(state, cfg: ArmConfig) -> np.ndarray:
    """Hard stop at theta2 = cfg.theta2_stop (model §1 choice); with cfg.one_link_stop an impact keeps the momentum
    about the shoulder, a11 w1 + a12 w2 at the stop.

    Args: state (4,).
    Returns: (4,) state.
    """
    s = np.array(state, dtype=np.float64)
    if s[1] >= cfg.theta2_stop:
        s[1] = cfg.theta2_stop
        if s[3] > 0.0:
            if cfg.one_link_stop:  # the stop's impulse acts on the elbow alone: a11 w1' = a11 w1 + a12 w2
                a = inertia_matrix(s[:2], cfg)
                s[2] += a[0, 1] / a[0, 0] * s[3]
            s[3] = 0.0
    return s


def arm_step(state, tau, field, force, cfg: ArmConfig) -> np.ndarray:
    """RK4 step then elbow stop.

    Args: state (4,), tau (2,) [N m], field a ConditionConfig, force (2,) [N].
    Returns: (4,).
    """
    return elbow_stop(rk4(state, tau, field, force, cfg), cfg)


def is_out(state, cfg: ArmConfig) -> bool:
    """Joint-limit test of section 4.2.

    Args: state (4,) [rad, rad/s].
    Returns: True when a limit is crossed.
    """
    lo, hi = cfg.theta1_range
    return bool(state[0] < lo or state[0] > hi or state[1] < cfg.theta2_min)


def kinetic_energy(state, cfg: ArmConfig) -> float:
    """0.5 omega^T A(theta) omega.

    Args: state (4,) [rad, rad/s].
    Returns: () [J].
    """
    w = np.asarray(state[2:], dtype=np.float64)
    return float(0.5 * w @ inertia_matrix(state[:2], cfg) @ w)


# ---------------------------------------------------------------------------------------------------------------
# Visual sensor (section 4.2, model §2)
# ---------------------------------------------------------------------------------------------------------------


def field_bounds(cfg: SensorConfig):
    """Visual field corners.

    Args: cfg sensor geometry.
    Returns: ((x_min, y_min), (x_max, y_max)) [m].
    """
    side = cfg.n_cells * cfg.cell_size
    x0 = cfg.centre[0] - side / 2
    y0 = cfg.centre[1] - side / 2
    return (x0, y0), (x0 + side, y0 + side)


def _union_area(rects) -> float:
    """Area covered by axis-aligned rectangles [(x0, y0, x1, y1), ...] by a sweep over x slabs."""
    rects = [r for r in rects if r[2] > r[0] and r[3] > r[1]]
    xs = sorted({r[0] for r in rects} | {r[2] for r in rects})
    area = 0.0
    for xa, xb in zip(xs[:-1], xs[1:], strict=True):
        spans = sorted((r[1], r[3]) for r in rects if r[0] <= xa and r[2] >= xb)
        covered, top = 0.0, -math.inf
        for lo, hi in spans:
            lo = max(lo, top)
            if hi > lo:
                covered += hi - lo
                top = hi
        area += (xb - xa) * covered
    return area


def render(hand, target, cfg: SensorConfig) -> np.ndarray:
    """Cell coverage by the union of the hand and target squares.

    Args: hand (2,), target (2,) centres [m].
    Returns: (n*n,) in [0, 1], row-major from lowest y.
    """
    (x0, y0), _ = field_bounds(cfg)
    c = cfg.cell_size
    squares = [(p[0] - c / 2, p[1] - c / 2, p[0] + c / 2, p[1] + c / 2) for p in (hand, target)]
    out = np.zeros(cfg.n_cells * cfg.n_cells)
    for row in range(cfg.n_cells):
        for col in range(cfg.n_cells):
            cx0, cy0 = x0 + col * c, y0 + row * c
            cx1, cy1 = cx0 + c, cy0 + c
            clipped = [(max(a, cx0), max(b, cy0), min(d, cx1), min(e, cy1)) for a, b, d, e in squares]
            out[row * cfg.n_cells + col] = _union_area(clipped) / (c * c)
    return out


# ---------------------------------------------------------------------------------------------------------------
# Encoding (section 4.2, Fig. 3, model §3)
# ---------------------------------------------------------------------------------------------------------------


def localize(x: float, lo: float, hi: float, n: int) -> np.ndarray:
    """Triangular code by linear interpolation between the two bracketing units.

    Args: x () value, [lo, hi] range, n units.
    Returns: (n,).
    """
    spacing = (hi - lo) / (n - 1)
    units = np.zeros(n)
    if x <= lo:
        units[0] = 1.0
        return units
    if x >= hi:
        units[n - 1] = 1.0
        return units
    pos = (x - lo) / spacing
    k = min(int(math.floor(pos)), n - 2)
    frac = pos - k
    units[k] += 1.0 - frac
    units[k + 1] += frac
    return units


def encode_joints(theta, omega, cfg: Config) -> np.ndarray:
    """Coded joint state.

    Args: theta (2,) [rad], omega (2,) [rad/s].
    Returns: (40,) for the paper's sizes.
    """
    e = cfg.encoding
    parts = []
    for j in range(2):
        parts.append(localize(float(theta[j]), e.theta_ranges[j][0], e.theta_ranges[j][1], e.theta_units[j]))
    for j in range(2):
        parts.append(localize(float(omega[j]), -e.omega_range, e.omega_range, e.omega_units))
    return np.concatenate(parts)


def encode(visual, state, prev_state, prev_tau, cfg: Config) -> np.ndarray:
    """125 network inputs.

    Args: visual (25,), state (4,) and prev_state (4,) [rad, rad/s], prev_tau (2,) [N m].
    Returns: (125,).
    """
    parts = [np.asarray(visual, dtype=np.float64)]
    parts.append(encode_joints(state[:2], state[2:], cfg))
    parts.append(encode_joints(prev_state[:2], prev_state[2:], cfg))
    for j in range(2):
        tmax = cfg.arm.tau_max[j]
        parts.append(localize(float(prev_tau[j]), -tmax, tmax, cfg.encoding.tau_units))
    return np.concatenate(parts)


def input_mask(use_past: bool, cfg: Config) -> np.ndarray:
    """0/1 input mask; use_past=False withholds the one-step-before signals.

    Args: use_past ().
    Returns: (125,).
    """
    e = cfg.encoding
    n_now = cfg.sensor.n_cells**2 + sum(e.theta_units) + 2 * e.omega_units
    n_past = sum(e.theta_units) + 2 * e.omega_units + 2 * e.tau_units
    return np.array([1.0] * n_now + [1.0 if use_past else 0.0] * n_past)


def observe(state, prev_state, prev_tau, target, mask, cfg: Config) -> np.ndarray:
    """Masked input.

    Args: state, prev_state (4,), prev_tau (2,) [N m], target (2,) [m], mask (125,).
    Returns: (125,).
    """
    visual = render(hand_position(state[:2], cfg.arm), target, cfg.sensor)
    return encode(visual, state, prev_state, prev_tau, cfg) * np.asarray(mask, dtype=np.float64)


# ---------------------------------------------------------------------------------------------------------------
# Network (section 4.2, model §4)
# ---------------------------------------------------------------------------------------------------------------


def f(u):
    """Neuron output f(u) = 1 / (1 + exp(-u)) - 0.5.

    Args: u (...) net input.
    Returns: (...) in (-0.5, 0.5).
    """
    return 1.0 / (1.0 + np.exp(-u)) - 0.5


def layers_from_flax(params) -> list[tuple[np.ndarray, np.ndarray]]:
    """Explicit (W, b) per layer, float64.

    Args: params flax dict {'params': {'Dense_i': {kernel (n_in, n_out), bias (n_out,)}}}.
    """
    p = params["params"]
    out = []
    for i in range(len(p)):
        d = p[f"Dense_{i}"]
        w = np.array(d["kernel"], dtype=np.float64)
        b = np.array(d["bias"], dtype=np.float64) if "bias" in d else np.zeros(w.shape[1])
        out.append((w, b))
    return out


def layers_to_flax(layers, use_bias: bool = True) -> dict:
    """Inverse of `layers_from_flax`.

    Args: layers [(W (n_in, n_out), b (n_out,))].
    Returns: a flax-shaped dict of numpy arrays.
    """
    tree = {}
    for i, (w, b) in enumerate(layers):
        tree[f"Dense_{i}"] = {"kernel": w.copy(), "bias": b.copy()} if use_bias else {"kernel": w.copy()}
    return {"params": tree}


def forward(layers, x) -> list[np.ndarray]:
    """Forward pass.

    Args: layers [(W, b)], x (125,) input.
    Returns: the activations [x, h1 (30,), h2 (10,), out (3,)].
    """
    acts = [np.asarray(x, dtype=np.float64)]
    for w, b in layers:
        a = acts[-1]
        u = np.zeros(w.shape[1])
        for j in range(w.shape[1]):
            u[j] = b[j] + np.dot(a, w[:, j])
        acts.append(f(u))
    return acts


def sgd_step(layers, x, target, lr: float, use_bias: bool = True):
    """One SGD step on 0.5 * sum((target - out)^2), backprop by hand.

    Args: x (125,), target (3,), lr ().
    Returns: (new layers, loss ()).
    """
    acts = forward(layers, x)
    err = np.asarray(target, dtype=np.float64) - acts[-1]
    loss = 0.5 * float(np.sum(err**2))
    # dL/du at the output: -(target - out) * f'(u), with f'(u) = (0.5 + f)(0.5 - f).
    delta = -err * (0.5 + acts[-1]) * (0.5 - acts[-1])
    new = [None] * len(layers)
    for i in range(len(layers) - 1, -1, -1):
        w, b = layers[i]
        below = acts[i]
        grad_w = np.outer(below, delta)
        grad_b = delta if use_bias else np.zeros_like(b)
        # Propagate through the old weights before they change.
        delta_below = (w @ delta) * (0.5 + below) * (0.5 - below)
        new[i] = (w - lr * grad_w, b - lr * grad_b)
        delta = delta_below
    return new, loss


def init_layers(rng: np.random.Generator, cfg: Config):
    """Fresh weights: hidden U(+-hidden_init), output U(+-output_init), zero biases.

    Args: rng numpy Generator.
    Returns: [(W, b)].
    """
    n = cfg.network
    sizes = [cfg.sensor.n_cells**2 + 2 * (sum(cfg.encoding.theta_units) + 2 * cfg.encoding.omega_units)]
    sizes[0] += 2 * cfg.encoding.tau_units
    sizes += list(n.hidden) + [n.n_out]
    layers = []
    for i in range(len(sizes) - 1):
        a = n.output_init if i == len(sizes) - 2 else n.hidden_init
        layers.append((rng.uniform(-a, a, (sizes[i], sizes[i + 1])), np.zeros(sizes[i + 1])))
    return layers


def torque(m, rnd, cfg: Config) -> np.ndarray:
    """tau_i = 2 tau_max_i (m_i + rnd_i) clipped to +-tau_max_i.

    Args: m (2,) actor, rnd (2,) noise.
    Returns: (2,) [N m].
    """
    out = np.zeros(2)
    for j in range(2):
        tmax = cfg.arm.tau_max[j]
        out[j] = min(tmax, max(-tmax, 2.0 * tmax * (m[j] + rnd[j])))
    return out


# ---------------------------------------------------------------------------------------------------------------
# TS learning (eq. 1-3, model §5)
# ---------------------------------------------------------------------------------------------------------------


@dataclass
class Pending:
    """The previous step awaiting its TS update."""

    x: np.ndarray  # (125,) masked input x(t-1)
    out: np.ndarray  # (3,) [p, m1, m2] at t-1
    rnd: np.ndarray  # (2,) noise added at t-1
    valid: bool  # False: no update (first step of a run, or after a capped trial)
    terminal: bool  # the transition ended its trial at the goal or a joint limit
    reward: float  # reinforcement that ended the trial, 0 otherwise
    gain: float = 1.0  # factor on the actor's signal (the value scaling's factor to -actor_gain_power)


def ts_targets(
    pending: Pending, p_now: float, n_max: float, cfg: LearnerConfig, baseline: float = 0.0, bound: float = 0.0
) -> np.ndarray:
    """Eq. 1 (critic, floored unless terminal) and eq. 2 (actor), with the actor's optional baseline and bound.

    Args: p_now () p(t), n_max () [steps], baseline () share of P_range/N_max taken from dp (0: eq. 2), bound ()
      the actor's targets clipped to [-bound, bound] when positive (0: eq. 2).
    Returns: (3,) targets.
    """
    p_next = pending.reward if pending.terminal else p_now  # reinforcement stands in for p(t) at a trial's end
    critic = p_next - cfg.p_range / n_max  # eq. 1
    if not pending.terminal:
        critic = max(critic, cfg.critic_floor)
    p_prev = pending.out[0]
    signal = p_next - p_prev - baseline * cfg.p_range / n_max  # dp of eq. 2, less the baseline
    actor = [pending.out[1 + j] + pending.rnd[j] * pending.gain * signal for j in range(2)]  # eq. 2
    if bound > 0:
        actor = [min(bound, max(-bound, a)) for a in actor]
    return np.array([critic, actor[0], actor[1]])


def update_n_max(n_max: float, n_steps: int, lam: float) -> float:
    """Eq. 3.

    Args: n_max () previous N_max [steps], n_steps () steps of the successful trial, lam ().
    Returns: () [steps].
    """
    if n_steps > lam * n_max:
        return float(n_steps)
    return lam * n_max


def value_scale(p: float, was_full: bool, shortfall: float, t: int, h: dict) -> float:
    """() factor on the bound at a state whose critic value is p (model §5): smallest where the goal is expected.

    Args: p () the critic's value of the step's input, was_full () the curriculum has reached the whole field,
      shortfall () 1 - curriculum distance / the whole field's, t () steps taken in the trial, h the learner's
      hyperparameters.
    """
    far = min(1.0, max(0.0, (h["noise_value_hi"] - p) / (h["noise_value_hi"] - h["noise_value_lo"])))
    ratio = 1.0 if h["noise_value_after_full"] > 0 and not was_full else h["noise_value_ratio"]
    gate = h["noise_value_gate"]
    if gate > 0:  # a curriculum short of the whole field relaxes the scaling, fully at a shortfall of `gate`
        ratio += (1.0 - ratio) * min(1.0, max(0.0, shortfall / gate))
    if 0 < h["noise_value_steps"] <= t:  # a trial that runs long: the whole bound
        ratio = 1.0
    return ratio + (1.0 - ratio) * far


def actor_gain(scale: float, h: dict) -> float:
    """() factor on the actor's signal of a step explored at value-scale factor `scale`: g scale^-actor_gain_power.

    g is the constant actor-only gain `actor_signal_gain` (model §5); the critic's target does not see it.
    """
    power = h["actor_gain_power"]
    return h["actor_signal_gain"] * (scale**-power if power > 0 and scale > 0 else 1.0)


def exploration_noise(unit, bound: float, scale: float, prev, trials: int, h: dict) -> np.ndarray:
    """rnd (2,) of one step (model §5): the bound times the value scaling's factor, none on quiet trials, AR(1).

    Args: unit (2,) draws in [-1, 1), bound () the schedule's bound, scale () `value_scale`'s factor, prev (2,)
      the previous step's rnd, trials () trials ended before this one, h the learner's hyperparameters.
    """
    b = bound * scale
    every = h["quiet_every"]
    if every > 0 and (trials + 1) % every == 0:
        return np.zeros(2)  # a quiet trial: no noise at all
    rho = h["noise_corr"]
    return np.array([rho * prev[j] + math.sqrt(1.0 - rho * rho) * b * unit[j] for j in range(2)])


def ts_update(
    layers, x_now, pending: Pending, n_max: float, lr: float, cfg: Config, baseline: float = 0.0, bound: float = 0.0
):
    """Outputs at x(t) with W(t), then one TS step on x(t-1).

    Args: x_now (125,), n_max () [steps], lr (), baseline () and bound () of the actor's signal (`ts_targets`).
    Returns: (layers, out (3,), loss ()).
    """
    out_now = forward(layers, x_now)[-1]
    if not pending.valid:
        return layers, out_now, 0.0
    target = ts_targets(pending, out_now[0], n_max, cfg.learner, baseline, bound)
    new, loss = sgd_step(layers, pending.x, target, lr, cfg.network.use_bias)
    return new, out_now, loss


# ---------------------------------------------------------------------------------------------------------------
# Task: conditions, placement, goal, drift, curriculum (model §2, §5, §6)
# ---------------------------------------------------------------------------------------------------------------


class Condition(NamedTuple):
    """One learner's environment."""

    field: ConditionConfig  # the hand-force field (its name and past_inputs aside)
    input_mask: np.ndarray  # (125,) 0/1


def make_condition(name: str, cfg: Config) -> Condition:
    """Condition of the config's conditions table called `name`.

    Args: name a condition of cfg.conditions.
    Returns: a Condition.
    """
    spec = condition(cfg, name)
    return Condition(spec, input_mask(spec.past_inputs, cfg))


class Draws(NamedTuple):
    """Uniform [0, 1) numbers fixing one trial."""

    start: np.ndarray  # (2,)
    target: np.ndarray  # (K, 2) candidates
    force: np.ndarray  # (2,)
    catch: float = 1.0  # below the block's catch probability: a catch trial (1 never is one)


def touching(hand, target, cfg: Config) -> bool:
    """Hand centre inside the goal square (side 2 goal_half_width).

    Args: hand (2,), target (2,) [m].
    Returns: bool.
    """
    half = cfg.task.goal_half_width_cells * cfg.sensor.cell_size
    return bool(abs(hand[0] - target[0]) < half and abs(hand[1] - target[1]) < half)


def goal_reached(hand, hand_vel, target, cfg: Config) -> bool:
    """Touching with tangential speed below cfg.task.goal_speed.

    Args: hand (2,) [m], hand_vel (2,) [m/s], target (2,) [m].
    """
    speed = math.sqrt(hand_vel[0] ** 2 + hand_vel[1] ** 2)
    return touching(hand, target, cfg) and speed < cfg.task.goal_speed


def curriculum_bounds(cfg: Config) -> tuple[float, float]:
    """(initial and minimum, maximum) curriculum L-inf distance.

    Args: cfg.
    Returns: ((), ()) [m].
    """
    return cfg.task.curriculum_init_cells * cfg.sensor.cell_size, cfg.sensor.n_cells * cfg.sensor.cell_size


def place_trial(draws: Draws, distance: float, field: ConditionConfig, cfg: Config):
    """Start state at rest, target and the trial's random force.

    Args: draws, distance () [m], field (its per-axis random bound [N]).
    Returns: ((4,), (2,) [m], (2,) [N]).
    """
    (x0, y0), (x1, y1) = field_bounds(cfg.sensor)
    lo, hi = np.array([x0, y0]), np.array([x1, y1])
    start = lo + np.asarray(draws.start) * (hi - lo)
    box_lo = np.maximum(lo, start - distance)
    box_hi = np.minimum(hi, start + distance)
    cands = np.asarray(draws.target)
    target = None
    for k in range(cands.shape[0]):
        cand = box_lo + cands[k] * (box_hi - box_lo)
        if not touching(start, cand, cfg):
            target = cand
            break
    if target is None:  # every candidate touches: take the last
        target = box_lo + cands[-1] * (box_hi - box_lo)
    state = np.concatenate([inverse_kinematics(start, cfg.arm), np.zeros(2)])
    force = np.array([a * (2.0 * u - 1.0) for a, u in zip(field.random, draws.force, strict=True)])
    return state, target, force


def drift_target(target, hand, step_in_trial: int, cfg: Config):
    """Move the target toward the hand by drift_per_step once the trial is drift_after old.

    Args: target, hand (2,) [m], step_in_trial ().
    Returns: ((2,) [m], bool).
    """
    if not step_in_trial * cfg.arm.dt >= cfg.task.drift_after:
        return np.array(target, dtype=np.float64), False
    gap = np.asarray(hand, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    dist = math.hypot(gap[0], gap[1])
    if dist == 0.0:
        return np.array(target, dtype=np.float64), False
    if dist <= cfg.task.drift_per_step:
        return target + gap, True
    return target + gap * (cfg.task.drift_per_step / dist), True


def drift_open(failure: float, h: dict) -> bool:
    """The drift gate (model §5): open without `drift_gate`, else while the recent failure share exceeds it."""
    return h["drift_gate"] <= 0 or failure > h["drift_gate"]


def update_failure(failure: float, goal: bool, drifted: bool, h: dict) -> float:
    """The recent failure share after a trial: an exponential mean, time constant `drift_gate_trials` trials."""
    failed = 0.0 if goal and not drifted else 1.0
    return failure + (failed - failure) / h["drift_gate_trials"]


def update_curriculum(
    distance: float, goal: bool, drifted: bool, was_full: bool, cfg: Config, early: bool = False
) -> float:
    """Staircase: +step after a success without drift, 0 after a drift-aided success once the curriculum
    has been full (if cfg.task.drift_neutral_when_full) or at any time (if `early`), -step otherwise; in bounds.

    Args: distance () [m], goal, drifted, was_full, early.
    Returns: () [m].
    """
    lo, hi = curriculum_bounds(cfg)
    if goal and not drifted:
        step = cfg.task.curriculum_step
    elif goal and ((was_full and cfg.task.drift_neutral_when_full) or early):
        step = 0.0
    else:
        step = -cfg.task.curriculum_step
    return min(hi, max(lo, distance + step))


# ---------------------------------------------------------------------------------------------------------------
# Protocols (mirrors reach_jax.protocol)
# ---------------------------------------------------------------------------------------------------------------


class Block(NamedTuple):
    """One block of a protocol, with its conditions resolved."""

    end: float  # trial index at which the block ends (inf for the last)
    cond: Condition
    catch: float  # catch-trial probability
    catch_cond: Condition
    learning: bool


def make_plan(name: str, cfg: Config) -> list[Block]:
    """Blocks of the protocol (or one-block condition) called `name`.

    Args: name in cfg.protocols or cfg.conditions.
    Returns: list of Block.
    """
    blocks, total, plan = blocks_of(cfg, name), 0, []
    for i, b in enumerate(blocks):
        total += b.trials
        end = math.inf if i == len(blocks) - 1 else total
        plan.append(
            Block(end, make_condition(b.condition, cfg), b.catch, make_condition(b.catch_condition, cfg), b.learning)
        )
    return plan


def trial_condition(plan: list[Block], trial: int, catch_draw: float) -> tuple[Condition, bool]:
    """(condition, learning) of trial index `trial` given its catch draw in [0, 1)."""
    block = next(b for b in plan if trial < b.end)
    return (block.catch_cond if catch_draw < block.catch else block.cond), block.learning


# ---------------------------------------------------------------------------------------------------------------
# Learner step (mirrors reach_jax.rollout.learner_step)
# ---------------------------------------------------------------------------------------------------------------


@dataclass
class Learner:
    """What one NumPy learner carries from step to step."""

    layers: list  # [(W, b)] network weights
    arm: np.ndarray  # (4,) arm state now
    prev_arm: np.ndarray  # (4,) arm state one step before
    prev_tau: np.ndarray  # (2,) torques one step before [N m]
    target: np.ndarray  # (2,) [m]
    force: np.ndarray  # (2,) this trial's constant hand force [N]
    pending: Pending  # step awaiting its TS update
    t: int  # steps in this trial
    drifted: bool  # the target drifted in this trial
    n_max: float  # N_max [steps]
    distance: float  # curriculum distance [m]
    cond: Condition  # this trial's condition
    learning: bool = True  # this trial's block updates the weights
    pending_learning: bool = True  # the pending step's block updates the weights
    was_full: bool = False  # the distance has reached the whole field
    failure: float = 1.0  # recent share of trials that ended without a clean success (the drift gate's measure)
    trials: int = 0  # trials ended
    steps: int = 0  # steps taken


class StepRecord(NamedTuple):
    """What one NumPy step did."""

    x: np.ndarray  # (125,) input
    out: np.ndarray  # (3,) outputs before the update
    rnd: np.ndarray  # (2,) exploration noise
    tau: np.ndarray  # (2,) [N m]
    arm: np.ndarray  # (4,) arm state after the move (before any reset)
    goal: bool
    out_of_range: bool
    cap: bool
    loss: float


def learner_from_jax(state, cond: Condition) -> Learner:
    """Copy of a `reach_jax.learner_state.LearnerState` (one learner) whose trial runs in `cond`.

    Args: state with its trial's (4,) arm, (2,) target etc.; cond the oracle's copy of state.env.cond.
    Returns: a Learner.
    """
    agent, trial, counters = state.agent, state.env.trial, state.counters
    pend = agent.pending
    return Learner(
        layers=layers_from_flax(agent.params),
        arm=np.array(trial.arm, dtype=np.float64),
        prev_arm=np.array(trial.prev_arm, dtype=np.float64),
        prev_tau=np.array(trial.prev_tau, dtype=np.float64),
        target=np.array(trial.target, dtype=np.float64),
        force=np.array(trial.force, dtype=np.float64),
        pending=Pending(
            x=np.array(pend.x, dtype=np.float64),
            out=np.array(pend.out, dtype=np.float64),
            rnd=np.array(pend.rnd, dtype=np.float64),
            valid=bool(pend.valid),
            terminal=bool(pend.terminal),
            reward=float(pend.reward),
            gain=float(pend.gain),
        ),
        t=int(trial.t),
        drifted=bool(trial.drifted),
        n_max=float(agent.n_max),
        distance=float(state.env.curriculum.distance),
        cond=cond,
        learning=bool(state.env.block.learning),
        pending_learning=bool(agent.pending_learning),
        was_full=bool(state.env.curriculum.full_at >= 0),
        failure=float(state.env.curriculum.failure),
        trials=int(state.env.trials),
        steps=int(counters.steps),
    )


def learner_step(lrn: Learner, plan: list[Block], h: dict, bound: float, unit, draws: Draws, cfg: Config):
    """One step: observe, forward, TS update, explore, act, RK4, outcome, reset into the plan's next trial.

    Args: plan the learner's blocks, h its hyperparameters (names of hyper.TABLE), bound () the exploration
      schedule's bound, unit (2,) the step's noise draws in [-1, 1), draws for a new trial.
    Returns: (Learner, StepRecord).
    """
    cond = lrn.cond
    x = observe(lrn.arm, lrn.prev_arm, lrn.prev_tau, lrn.target, cond.input_mask, cfg)
    lr = h["lr"] if lrn.pending_learning else 0.0
    target_bound = h["actor_target_bound"]
    layers, out, loss = ts_update(lrn.layers, x, lrn.pending, lrn.n_max, lr, cfg, h["actor_baseline"], target_bound)
    scale = value_scale(out[0], lrn.was_full, 1.0 - lrn.distance / curriculum_bounds(cfg)[1], lrn.t, h)
    rnd = exploration_noise(unit, bound, scale, lrn.pending.rnd, lrn.trials, h)
    tau = torque(out[1:], rnd, cfg)
    moved = arm_step(lrn.arm, tau, cond.field, lrn.force, cfg.arm)
    t = lrn.t + 1

    hand = hand_position(moved[:2], cfg.arm)
    out_of_range = is_out(moved, cfg.arm)
    goal = (not out_of_range) and goal_reached(hand, hand_velocity(moved, cfg.arm), lrn.target, cfg)
    cap = (not goal) and (not out_of_range) and t >= round(cfg.task.max_trial_time / cfg.arm.dt)
    done = goal or out_of_range or cap
    lc = cfg.learner
    reward = lc.reward_goal if goal else (lc.reward_out if out_of_range else 0.0)
    terminal = goal or out_of_range
    gain = actor_gain(scale, h)
    pending = Pending(x=x, out=out, rnd=rnd, valid=not cap, terminal=terminal, reward=reward, gain=gain)

    new = replace(lrn, layers=layers, pending=pending, steps=lrn.steps + 1, pending_learning=lrn.learning)
    if goal and not (h["n_max_clean"] > 0 and lrn.drifted):  # n_max_clean: eq. 3 on clean successes only
        new.n_max = update_n_max(lrn.n_max, t, h["lam"])
    if done:
        new.failure = update_failure(lrn.failure, goal, lrn.drifted, h)
        early = h["drift_neutral_early"] > 0
        new.distance = update_curriculum(lrn.distance, goal, lrn.drifted, lrn.was_full, cfg, early)
        new.was_full = lrn.was_full or new.distance >= curriculum_bounds(cfg)[1]
        new.cond, new.learning = trial_condition(plan, lrn.trials + 1, draws.catch)
        start, target, force = place_trial(draws, new.distance, new.cond.field, cfg)
        new.arm, new.prev_arm, new.prev_tau = start, start.copy(), np.zeros(2)
        new.target, new.force, new.t, new.drifted = target, force, 0, False
        new.trials = lrn.trials + 1
    else:
        # A closed drift gate keeps the target where it is: a long trial runs on to its cap.
        gate = drift_open(lrn.failure, h)
        target, moved_target = drift_target(lrn.target, hand, t, cfg) if gate else (np.array(lrn.target), False)
        new.arm, new.prev_arm, new.prev_tau = moved, np.array(lrn.arm), tau
        new.target, new.t, new.drifted = target, t, lrn.drifted or moved_target
    return new, StepRecord(x, out, rnd, tau, moved, goal, out_of_range, cap, loss)


def draw_trial(rng: np.random.Generator, cfg: Config) -> Draws:
    """Fresh uniform draws for one trial.

    Args: rng numpy Generator.
    Returns: Draws (start (2,), target (K, 2), force (2,), catch).
    """
    return Draws(rng.random(2), rng.random((cfg.task.target_candidates, 2)), rng.random(2), rng.random())


def init_learner(rng: np.random.Generator, plan: list[Block], cfg: Config) -> Learner:
    """Fresh NumPy learner at the initial curriculum distance, in its plan's first trial.

    Args: rng numpy Generator, plan.
    Returns: a Learner.
    """
    draws = draw_trial(rng, cfg)
    cond, learning = trial_condition(plan, 0, draws.catch)
    n_in = cond.input_mask.shape[0]
    distance = curriculum_bounds(cfg)[0]
    start, target, force = place_trial(draws, distance, cond.field, cfg)
    return Learner(
        layers=init_layers(rng, cfg),
        arm=start,
        prev_arm=start.copy(),
        prev_tau=np.zeros(2),
        target=target,
        force=force,
        pending=Pending(np.zeros(n_in), np.zeros(3), np.zeros(2), False, False, 0.0),
        t=0,
        drifted=False,
        n_max=cfg.learner.n_max_init,
        distance=distance,
        cond=cond,
        learning=learning,
        pending_learning=learning,
        was_full=distance >= curriculum_bounds(cfg)[1],
        failure=cfg.task.drift_gate_start,
    )


def run_reference(n_steps: int, seed: int, cfg: Config, condition: str = "none"):
    """Self-contained NumPy learner for n_steps on its own RNG (benchmark).

    Args: n_steps (), seed (), condition name.
    Returns: (Learner, dict of outcome counts).
    """
    rng = np.random.default_rng(seed)
    plan = make_plan(condition, cfg)
    lrn = init_learner(rng, plan, cfg)
    h = {name: float(getattr(cfg.learner, name)) for name in hyper.NAMES}
    counts = {"goals": 0, "outs": 0, "caps": 0}
    for _ in range(n_steps):
        unit = rng.uniform(-1.0, 1.0, 2)
        lrn, rec = learner_step(lrn, plan, h, h["noise"], unit, draw_trial(rng, cfg), cfg)
        counts["goals"] += rec.goal
        counts["outs"] += rec.out_of_range
        counts["caps"] += rec.cap
    return lrn, counts
