"""Learned hand impedance: the stiffness and damping that a policy's feedback gives the hand.

Units: stiffness [N/m], damping [N s/m], hand positions [m], velocities [m/s], torques [N m], angles [rad].

At a state that a network passed through in one of its own test movements, its torque tau is differentiated by
forward-mode autodiff along joint displacements dq that move the current and the one-step-past joint angles
together (so the hand also moves on the visual sensor; the target stays), and along joint-velocity changes
dqdot that move the current and the past velocities together. With J the arm Jacobian at the state, the
hand-space gains are

    K = -J^-T (dtau/dq) J^-1        D = -J^-T (dtau/dqdot) J^-1,

so that the controller answers a hand displacement dx and a hand velocity dxdot with the force -K dx - D dxdot:
positive along a direction means restoring (K) or dissipating (D). The change of J^-T with the posture (a force
term that vanishes where the torque is 0) is not part of K: K is the feedback gain of the policy alone. A
saturated torque has zero derivative. The passive arm adds the joint viscosity of Table 1, J^-T B J^-1.

The projections that decide whether a viscous field F = B_f xdot can destabilise the arm are taken along the
eigenvectors of the field's symmetric part: along its positive eigenvalue (the "unstable" axis, about 113 deg
for the paper's field, +15.9 N s/m) the field feeds energy in, and the arm stays stable only while its
learned plus passive damping there exceeds that eigenvalue.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config
from reach_jax.evaluate import episodes
from reach_jax.physics import arm


def hand_gains(policy, params, mask, state, prev, prev_tau, target, start, t, cfg: Config):
    """Hand stiffness K (2, 2) [N/m] and damping D (2, 2) [N s/m] of a policy at one state.

    Args:
      policy: (params, Obs) -> (2,) torque [N m].
      params: the policy's parameters.
      mask: (125,) input mask of the network's learning condition.
      state: (4,) arm state [rad, rad/s].
      prev: (4,) the state one step before.
      prev_tau: (2,) the torque one step before [N m].
      target: (2,) [m].
      start: (2,) [m].
      t: () steps into the movement.
      cfg: model config.
    """
    tau_max = jnp.asarray(cfg.arm.tau_max)

    def torque(dq, dqdot):
        shift = jnp.concatenate([dq, dqdot])
        obs = episodes.observation(state + shift, prev + shift, prev_tau, target, start, t, mask, cfg)
        return jnp.clip(policy(params, obs), -tau_max, tau_max)

    zero = jnp.zeros(2, state.dtype)
    dtau_dq, dtau_dqdot = jax.jacfwd(torque, argnums=(0, 1))(zero, zero)
    jinv = arm.inverse_jacobian(state[:2], cfg.arm)
    return -jinv.T @ dtau_dq @ jinv, -jinv.T @ dtau_dqdot @ jinv


def passive_damping(state: jax.Array, cfg: Config) -> jax.Array:
    """(2, 2) hand damping [N s/m] of the arm's own joint viscosity (Table 1) at `state` (4,)."""
    jinv = arm.inverse_jacobian(state[:2], cfg.arm)
    return jinv.T @ jnp.diag(jnp.asarray(cfg.arm.joint_viscosity)) @ jinv


def field_axes(field) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (2,) [N s/m], largest first, and unit eigenvectors (2, 2) as rows, of a field's symmetric part.

    The first row is the field's "unstable" axis when its eigenvalue is positive. The sign of each vector is
    fixed so that its angle lies in [0, 180) deg.
    """
    b = np.asarray(field, dtype=np.float64)
    values, vectors = np.linalg.eigh(0.5 * (b + b.T))
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order].T
    flip = (vectors[:, 1] < 0) | ((vectors[:, 1] == 0) & (vectors[:, 0] < 0))
    return values, np.where(flip[:, None], -vectors, vectors)


def along(matrices: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """e^T M e for (..., 2, 2) matrices and a unit (2,) axis: the gain along that direction."""
    return np.einsum("i,...ij,j->...", axis, matrices, axis)


@functools.cache
def _compiled(policy, cfg: Config):
    gains = functools.partial(hand_gains, policy, cfg=cfg)
    over_steps = jax.vmap(gains, in_axes=(None, None, 0, 0, 0, None, None, 0))
    over_pairs = jax.vmap(over_steps, in_axes=(None, None, 0, 0, 0, 0, 0, None))
    over_tests = jax.vmap(over_pairs, in_axes=(None, None, 0, 0, 0, None, None, None))

    def per_network(args):
        params, mask, states, prevs, prev_taus, targets, starts, t = args
        k, d = over_tests(params, mask, states, prevs, prev_taus, targets, starts, t)
        return k, d, jax.vmap(jax.vmap(jax.vmap(lambda s: passive_damping(s, cfg))))(states)

    def run(params, masks, states, prevs, prev_taus, targets, starts, t):
        # One network at a time keeps the intermediate arrays small; the states of a network run vectorized.
        n = masks.shape[0]
        tile = lambda a: jnp.broadcast_to(a, (n, *a.shape))  # noqa: E731
        return jax.lax.map(per_network, (params, masks, states, prevs, prev_taus, tile(targets), tile(starts), tile(t)))

    return jax.jit(run)


def measure(policy, params, masks, ep: episodes.Episode, traj: episodes.Trajectory, starts, targets, cfg: Config):
    """K, D and the passive damping at the states of every network's own test movements.

    A movement contributes the states at which the policy acted (steps 0 .. steps - 1), up to
    cfg.eval.impedance_max_steps of them, for every cfg.eval.impedance_pair_stride-th (start, target) pair.
    States with sin(theta2) below cfg.eval.impedance_min_sin_elbow (a nearly straight or folded elbow, where
    J^-1 blows up) are left out.

    Args:
      policy: (params, Obs) -> (2,) torque [N m], as for `episodes.run_episodes`.
      params: policy parameters with a leading network axis N.
      masks: (N, 125) input masks.
      ep: the episodes with leading axes (N, C, P), as returned by `episodes.run_episodes`.
      traj: the episodes with leading axes (N, C, P), as returned by `episodes.run_episodes`.
      starts: (P, 2) [m].
      targets: (P, 2) [m].
      cfg: model config.

    Returns:
      dict of numpy arrays: stiffness (N, C, P', T, 2, 2), damping and passive (same shape), valid (N, C, P', T).
    """
    stride, steps = cfg.eval.impedance_pair_stride, cfg.eval.impedance_max_steps
    arm_states = np.asarray(traj.arm)[:, :, ::stride, : steps + 1]
    prev_taus = np.asarray(traj.prev_tau)[:, :, ::stride, :steps]
    states = arm_states[..., :steps, :]
    prevs = np.concatenate([arm_states[..., :1, :], arm_states[..., : steps - 1, :]], axis=-2)
    t = np.arange(steps, dtype=np.int32)
    k, d, passive = _compiled(policy, cfg)(
        params,
        jnp.asarray(masks),
        jnp.asarray(states),
        jnp.asarray(prevs),
        jnp.asarray(prev_taus),
        jnp.asarray(np.asarray(targets)[::stride]),
        jnp.asarray(np.asarray(starts)[::stride]),
        jnp.asarray(t),
    )
    acted = t < np.asarray(ep.steps)[:, :, ::stride, None]
    valid = acted & (np.sin(states[..., 1]) >= cfg.eval.impedance_min_sin_elbow)
    return {"stiffness": np.asarray(k), "damping": np.asarray(d), "passive": np.asarray(passive), "valid": valid}


def _spread(x: np.ndarray) -> dict:
    """Median and quartiles of a sample, JSON-ready (None when empty)."""
    if x.size == 0:
        return {"median": None, "q25": None, "q75": None}
    q25, med, q75 = np.percentile(x, [25, 50, 75], axis=0)
    as_list = lambda v: v.tolist() if np.ndim(v) else float(v)  # noqa: E731
    return {"median": as_list(med), "q25": as_list(q25), "q75": as_list(q75)}


def summarize(gains: dict, learners, test_names, field) -> dict:
    """Per-network medians and quartiles of K, D and their projections on the field's axes, JSON-ready.

    Args:
      gains: output of `measure`.
      learners: (learning condition, seed index) per network.
      test_names: names of the C test conditions.
      field: (2, 2) viscous field whose symmetric part gives the axes [N s/m].
    """
    values, axes = field_axes(field)
    names = ("unstable", "stable")
    rows = []
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(test_names):
            ok = gains["valid"][i, j]
            k, d, p = (gains[name][i, j][ok] for name in ("stiffness", "damping", "passive"))
            rows.append(
                {
                    "learner": i,
                    "learning": learning,
                    "seed": seed,
                    "test": test,
                    "states": int(ok.sum()),
                    "stiffness_N_per_m": _spread(k),
                    "damping_Ns_per_m": _spread(d),
                    **{f"stiffness_{n}": _spread(along(k, a)) for n, a in zip(names, axes, strict=True)},
                    **{f"damping_{n}": _spread(along(d, a)) for n, a in zip(names, axes, strict=True)},
                    **{f"passive_damping_{n}": _spread(along(p, a)) for n, a in zip(names, axes, strict=True)},
                }
            )
    return {
        "field_axes": [
            {"name": n, "eigenvalue_Ns_per_m": float(v), "direction_deg": float(np.degrees(np.arctan2(a[1], a[0])))}
            for n, v, a in zip(names, values, axes, strict=True)
        ],
        "per_network": rows,
    }
