"""Table-2 test protocol, Fig. 4-5 movements, after-effect and movement quality (section 4.4, SPEC §8-10).

`python -m reach_jax.evaluate RUN_DIR` loads the newest checkpoint of a run and writes RUN_DIR/eval/:
table2.json, table2.md, fig4.png, fig5.png, aftereffect.json, quality.json and learning_curves.png.

Units: positions [m] in the shoulder frame, speeds [m/s], times [s], angles in the JSON files [deg]
(directions measured counter-clockwise from +x), torques [N m]. Trial lengths are steps of cfg.arm.dt.

Protocol. Every (start, target) pair x network x test condition is one episode of one jitted, vmapped
`lax.scan` over cfg.eval.max_time / cfg.arm.dt = 200 steps; there is no Python loop over pairs. There is
no learning, no exploration noise, no random force and no target drift. The arm starts at rest at the
inverse kinematics of the start. A network sees its *learning* condition's input mask (random_nopast
networks never see the past inputs); only the force field comes from the test condition. Each episode
ends in one outcome: success (`task.goal_reached`), out (`arm.is_out`, checked first) or fail (neither
within 200 steps). The mean time is taken over all pairs, with out and fail counted as cfg.eval.max_time.

The evaluator is policy-agnostic: a policy is any function (params, Obs) -> (2,) torque [N m], clipped by
the evaluator to +-tau_max (the actuator limit of Table 1). The network policy uses only Obs.x, the
masked 125-input, and applies the actor without noise: tau = network.torque(m, 0).

Why exactly 1040 pairs per network. The 8 x 8 lattice runs edge to edge over the visual field:
x_k = x_min + k W / 7, k = 0..7 (W = 0.2 m, spacing 28.6 mm), and the same in y. The hand and the target are
squares one cell (40 mm) wide, and both must be wholly on the sensor, so the points on the border of the
lattice are dropped: a square centred there sticks half out of the field. That leaves the inner 6 x 6 = 36
points and 36^2 = 1296 ordered (start, target) pairs. A pair is excluded when the hand already touches the
target, i.e. |dx| and |dy| are both below the goal half-width (one cell, 40 mm). On this lattice that is
the case exactly for lattice offsets of at most one step per axis (28.6 mm < 40 mm < 57.1 mm): per axis
6 + 2 x 5 = 16 of the 36 ordered index pairs, so 16^2 = 256 pairs, including the 36 with start = target.
1296 - 256 = 1040. (Reading the lattice as the centres of an 8 x 8 grid of W / 8 squares gives the same
inner 6 x 6 and the same 1040.) The paper says the start and the target lie on "one of the 8 x 8 = 64"
lattice points; using only the 36 points whose squares fit in the field is our reading, not its literal
text. It is the only construction we found that yields the paper's 1040: on all 64 points the touching
rule leaves 64^2 - 22^2 = 3612 ordered pairs, and no distance threshold gives 1040.

Fig. 4 movements: the start and the target are two of the centres of the four corner cells of the sensor,
all 12 ordered pairs. The after-effect and quality measures are defined in `aftereffect` and `quality`.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import arm, checkpoint, network, sensor, task, train
from reach_jax.config import CONDITIONS, TEST_CONDITIONS, Config, error_line

EXIT_USAGE = 2  # missing or corrupt run directory; nothing written
EXIT_IO = 4  # writing the results failed

EVAL_DIR = "eval"

# Outcome codes of an episode.
SUCCESS, OUT, FAIL = 0, 1, 2
OUTCOME_NAMES = ("success", "out", "fail")

# The paper's Table 2: (learning, test) -> (success, out, fail, mean time [s]), summed over 2 networks.
PAPER_TABLE2 = {
    ("none", "none"): (2071, 5, 4, 0.324),
    ("none", "viscous"): (1139, 926, 15, 2.03),
    ("viscous", "none"): (1869, 193, 18, 0.793),
    ("viscous", "viscous"): (2035, 38, 7, 0.467),
    ("random", "none"): (2038, 5, 37, 0.546),
    ("random", "viscous"): (1833, 227, 20, 0.909),
    ("random_nopast", "none"): (1887, 0, 193, 0.896),
    ("random_nopast", "viscous"): (1165, 853, 62, 2.12),
}
PAPER_NETWORKS = 2  # networks summed in each cell of the paper's Table 2

# Fig. 4 panels: (letter, learning condition, test condition).
FIG4_PANELS = (
    ("a", "none", "none"),
    ("b", "none", "viscous"),
    ("c", "viscous", "none"),
    ("d", "viscous", "viscous"),
    ("e", "random", "none"),
    ("f", "random", "viscous"),
)
FIG5_PANELS = ("a", "d")
CORNER_NAMES = ("lower left", "lower right", "upper left", "upper right")  # order of `corner_centres`


class Obs(NamedTuple):
    """What a policy sees at one step; scripted controllers may use more than the network does."""

    x: jax.Array  # (125,) network input, masked by the learning condition
    arm: jax.Array  # (4,) arm state [rad, rad/s]
    hand: jax.Array  # (2,) hand position [m]
    hand_vel: jax.Array  # (2,) hand velocity [m/s]
    start: jax.Array  # (2,) start position [m]
    target: jax.Array  # (2,) target position [m]
    t: jax.Array  # () steps taken so far


class Episode(NamedTuple):
    """One test episode (leading batch axes when batched)."""

    outcome: jax.Array  # () SUCCESS, OUT or FAIL
    steps: jax.Array  # () steps until the episode ended; n_steps for a fail
    hand: jax.Array  # (n_steps + 1, 2) hand path [m], held at its last point after the end
    speed: jax.Array  # (n_steps + 1,) hand tangential speed [m/s], held after the end


def n_steps(cfg: Config) -> int:
    """Steps of a test episode: cfg.eval.max_time / cfg.arm.dt (200)."""
    return round(cfg.eval.max_time / cfg.arm.dt)


def lattice_points(cfg: Config) -> np.ndarray:
    """Test lattice points whose one-cell square lies wholly in the visual field: (36, 2) [m], x fastest.

    Args:
      cfg: model config; cfg.eval.lattice points per side run edge to edge over the field.
    """
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    half = 0.5 * cfg.sensor.cell_size
    k = np.arange(cfg.eval.lattice) / (cfg.eval.lattice - 1)
    xs, ys = x0 + k * (x1 - x0), y0 + k * (y1 - y0)
    xs = xs[(xs - half >= x0) & (xs + half <= x1)]
    ys = ys[(ys - half >= y0) & (ys + half <= y1)]
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def test_pairs(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """Ordered (start, target) lattice pairs where the hand does not touch the target: two (1040, 2) [m]."""
    pts = lattice_points(cfg)
    starts = np.repeat(pts, len(pts), axis=0)
    targets = np.tile(pts, (len(pts), 1))
    keep = ~np.asarray(task.touching(jnp.asarray(starts), jnp.asarray(targets), cfg))
    return starts[keep], targets[keep]


def corner_centres(cfg: Config) -> np.ndarray:
    """Centres of the four corner cells, in CORNER_NAMES order: (4, 2) [m]."""
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    half = 0.5 * cfg.sensor.cell_size
    return np.array([[x0 + half, y0 + half], [x1 - half, y0 + half], [x0 + half, y1 - half], [x1 - half, y1 - half]])


def corner_pairs(cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fig. 4 movements between distinct corner-cell centres.

    Returns:
      (starts (12, 2) [m], targets (12, 2) [m], start corner index (12,) into CORNER_NAMES).
    """
    c = corner_centres(cfg)
    idx = np.array([(i, j) for i in range(len(c)) for j in range(len(c)) if i != j])
    return c[idx[:, 0]], c[idx[:, 1]], idx[:, 0]


def run_episode(policy, params, mask: jax.Array, field: jax.Array, start: jax.Array, target: jax.Array, cfg: Config):
    """One noise-free test episode from rest at `start`.

    Args:
      policy: (params, Obs) -> (2,) torque [N m].
      params: the policy's parameters.
      mask: (125,) input mask of the learning condition.
      field: (2, 2) viscous field of the test condition [N s/m].
      start: (2,) start hand position [m].
      target: (2,) target position [m].
      cfg: model config.

    Returns:
      Episode.
    """
    tau_max = jnp.asarray(cfg.arm.tau_max)
    no_force = jnp.zeros(2)
    s0 = jnp.concatenate([arm.inverse_kinematics(start, cfg.arm), jnp.zeros(2)])

    def body(carry, t):
        state, prev, prev_tau, done, outcome, steps = carry
        obs = Obs(
            x=task.observe(state, prev, prev_tau, target, mask, cfg),
            arm=state,
            hand=arm.hand_position(state[:2], cfg.arm),
            hand_vel=arm.hand_velocity(state, cfg.arm),
            start=start,
            target=target,
            t=t,
        )
        tau = jnp.clip(policy(params, obs), -tau_max, tau_max)
        moved = arm.step(state, tau, field, no_force, cfg.arm)
        hand = arm.hand_position(moved[:2], cfg.arm)
        vel = arm.hand_velocity(moved, cfg.arm)
        out = arm.is_out(moved, cfg.arm)
        goal = task.goal_reached(hand, vel, target, cfg) & ~out
        ended = (out | goal) & ~done
        outcome = jnp.where(ended, jnp.where(out, OUT, SUCCESS), outcome)
        steps = jnp.where(ended, t + 1, steps)
        # An ended episode is frozen, so its path and speed stay at their final values.
        keep = lambda a, b: jnp.where(done, a, b)  # noqa: E731
        new = (keep(state, moved), keep(prev, state), keep(prev_tau, tau), done | out | goal, outcome, steps)
        return new, (arm.hand_position(new[0][:2], cfg.arm), jnp.linalg.norm(arm.hand_velocity(new[0], cfg.arm)))

    total = n_steps(cfg)
    init = (s0, s0, jnp.zeros(2), jnp.array(False), jnp.array(FAIL, jnp.int32), jnp.array(total, jnp.int32))
    (_, _, _, _, outcome, steps), (hand, speed) = jax.lax.scan(body, init, jnp.arange(total, dtype=jnp.int32))
    hand = jnp.concatenate([arm.hand_position(s0[:2], cfg.arm)[None], hand])
    speed = jnp.concatenate([jnp.zeros(1), speed])
    return Episode(outcome=outcome, steps=steps, hand=hand, speed=speed)


@functools.cache
def _compiled(policy, cfg: Config):
    one = functools.partial(run_episode, policy, cfg=cfg)
    over_pairs = jax.vmap(one, in_axes=(None, None, None, 0, 0))
    over_tests = jax.vmap(over_pairs, in_axes=(None, None, 0, None, None))
    over_nets = jax.vmap(over_tests, in_axes=(0, 0, None, None, None))
    return jax.jit(over_nets)


def evaluate(policy, params, masks, fields, starts, targets, cfg: Config) -> Episode:
    """Every pair x network x test condition in one jitted, vmapped rollout.

    Args:
      policy: (params, Obs) -> (2,) torque [N m]; must be hashable (a module-level or cached function).
      params: policy parameters with a leading network axis N.
      masks: (N, 125) input masks of the networks' learning conditions.
      fields: (C, 2, 2) viscous fields of the test conditions [N s/m].
      starts: (P, 2) start positions [m].
      targets: (P, 2) target positions [m].
      cfg: model config.

    Returns:
      Episode with leading axes (N, C, P).
    """
    run = _compiled(policy, cfg)
    return run(params, jnp.asarray(masks), jnp.asarray(fields), jnp.asarray(starts), jnp.asarray(targets))


@functools.cache
def network_policy(cfg: Config):
    """The trained actor as a policy: (params, Obs) -> (2,) torque [N m], from Obs.x only, without noise."""

    def policy(params, obs: Obs) -> jax.Array:
        m = network.apply(params, obs.x, cfg)[1:]
        return network.torque(m, jnp.zeros_like(m), cfg)

    return policy


def test_fields(cfg: Config) -> jax.Array:
    """(C, 2, 2) viscous fields [N s/m] of TEST_CONDITIONS."""
    return jnp.stack([task.make_condition(name, cfg).field for name in TEST_CONDITIONS])


def trial_times(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> np.ndarray:
    """Reaching time per episode [s]: steps x dt for a success, cfg.eval.max_time for out and fail (SPEC §8)."""
    return np.where(np.asarray(outcome) == SUCCESS, np.asarray(steps) * cfg.arm.dt, cfg.eval.max_time)


def count(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> dict:
    """success / out / fail counts and mean time over all given episodes (any shape)."""
    outcome = np.asarray(outcome)
    return {
        **{name: int(np.sum(outcome == code)) for code, name in enumerate(OUTCOME_NAMES)},
        "mean_time_s": float(np.mean(trial_times(outcome, steps, cfg))),
    }


def table2(outcome: np.ndarray, steps: np.ndarray, learners: list[tuple[str, int]], cfg: Config) -> dict:
    """Table 2 as a JSON-ready dict: counts summed over each learning condition's networks, and per network.

    Args:
      outcome: (N, C, 1040) outcome codes, networks in `learners` order, tests in TEST_CONDITIONS order.
      steps: (N, C, 1040) episode lengths [steps].
      learners: (learning condition, seed index) per network.
      cfg: model config.
    """
    rows, per_network = [], []
    for learning in [c for c in CONDITIONS if any(c == name for name, _ in learners)]:
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(TEST_CONDITIONS):
            cell = count(outcome[nets, j], steps[nets, j], cfg)
            rows.append({"learning": learning, "test": test, "networks": len(nets), **cell})
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(TEST_CONDITIONS):
            cell = count(outcome[i, j], steps[i, j], cfg)
            per_network.append({"learner": i, "learning": learning, "seed": seed, "test": test, **cell})
    return {"rows": rows, "pairs_per_network": int(outcome.shape[-1]), "per_network": per_network}


def _cell(success: int, out: int, fail: int, mean_time: float) -> str:
    return f"{success}-{out}-{fail} ({mean_time:.3g} s)"


def table2_markdown(table: dict, source: str) -> str:
    """Table 2 in Markdown, our cells beside the paper's."""
    pairs = table["pairs_per_network"]
    cols = [f"{t}: {who}" for t in TEST_CONDITIONS for who in ("ours", "paper")]
    lines = [
        f"# Table 2: success-out-fail (mean reaching time) — {source}",
        "",
        f"Ours: summed over the networks of each learning condition, {pairs} (start, target) pairs per network.",
        f"Paper: summed over {PAPER_NETWORKS} networks x 1040 pairs. Out and fail count as 4.0 s in the mean time.",
        "",
        "| learning \\ test | networks | " + " | ".join(cols) + " |",
        "|---|---|" + "---|" * len(cols),
    ]
    by_cell = {(r["learning"], r["test"]): r for r in table["rows"]}
    for learning in [c for c in CONDITIONS if any(r["learning"] == c for r in table["rows"])]:
        cells = []
        for t in TEST_CONDITIONS:
            r = by_cell[(learning, t)]
            cells += [_cell(r["success"], r["out"], r["fail"], r["mean_time_s"]), _cell(*PAPER_TABLE2[(learning, t)])]
        n = by_cell[(learning, TEST_CONDITIONS[0])]["networks"]
        lines.append(f"| {learning} | {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.where(n > 0, n, 1.0), np.nan)


def _deg(v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(v[..., 1], v[..., 0]))


def _angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(_unit(u) * _unit(v), axis=-1), -1.0, 1.0)))


def pull_vectors(path: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Largest time-aligned displacement of each path from its reference path: (M, T, 2) x2 -> (M, 2) [m]."""
    d = path - reference
    k = np.argmax(np.linalg.norm(d, axis=-1), axis=-1)
    return d[np.arange(len(d)), k]


def line_deviation(path: np.ndarray, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Signed largest perpendicular deviation from the start-target line, + to the left of travel: (M,) [m].

    Args:
      path: (M, T, 2) hand paths [m] (held at their end point after the episode ends).
      starts, targets: (M, 2) [m].
    """
    u = _unit(targets - starts)
    rel = path - starts[:, None]
    side = u[:, None, 0] * rel[..., 1] - u[:, None, 1] * rel[..., 0]
    k = np.argmax(np.abs(side), axis=-1)
    return side[np.arange(len(side)), k]


def _json_float(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _circular_mean_deg(v: np.ndarray) -> float | None:
    u = _unit(v)
    u = u[np.all(np.isfinite(u), axis=-1)]
    if len(u) == 0:
        return None
    m = u.mean(axis=0)
    return _json_float(_deg(m)) if np.linalg.norm(m) > 0 else None


def aftereffect(
    paths: dict, starts: np.ndarray, targets: np.ndarray, start_corner: np.ndarray, field: np.ndarray
) -> dict:
    """Direction of the pull in Fig. 4 (b) and (c), and the angle between them.

    The pull of a movement in (b) (no-field network, field on) is the hand's displacement from the same
    network's path for the same movement in (a) (field off), taken at the time when it is largest; the
    paths are time-aligned and held at their end point once an episode ends. The pull in (c) (field-trained
    network, field removed) is likewise the displacement from its path in (d) (field on). Each pull is a
    2-D vector, reported as a direction [deg, counter-clockwise from +x] and a size [m]; the angle between
    the pulls of (b) and (c) of the same movement lies in [0, 180] deg. The mean angle is the mean of the
    per-movement angles; `mean_direction_deg` is the direction of each panel's mean unit pull vector.
    For the classic sign test we also give SPEC §9's line measure: the signed largest perpendicular
    deviation from the straight start-target line (+ = left of the direction of travel) in (b) and (c).
    The field's force on a movement is taken as field @ (target - start): the direction of F = B xdot on a
    straight movement, whatever its speed profile. A pull "with the force" is within 90 deg of it; the
    after-effect in (c) should point against it.

    Args:
      paths: {"a"|"b"|"c"|"d": (M, T, 2) hand paths [m]} of one network per learning condition.
      starts, targets: (M, 2) [m].
      start_corner: (M,) index into CORNER_NAMES.
      field: (2, 2) viscous field matrix of the test condition [N s/m].

    Returns:
      JSON-ready dict.
    """
    pull_b = pull_vectors(paths["b"], paths["a"])
    pull_c = pull_vectors(paths["c"], paths["d"])
    angle = _angle_between(pull_b, pull_c)
    force = (targets - starts) @ np.asarray(field).T
    b_to_force, c_to_force = _angle_between(pull_b, force), _angle_between(pull_c, force)
    dev_b = line_deviation(paths["b"], starts, targets)
    dev_c = line_deviation(paths["c"], starts, targets)
    movements = []
    for i in range(len(starts)):
        movements.append(
            {
                "start_m": [float(v) for v in starts[i]],
                "target_m": [float(v) for v in targets[i]],
                "start_corner": CORNER_NAMES[int(start_corner[i])],
                "pull_b_deg": _json_float(_deg(pull_b[i])),
                "pull_b_m": float(np.linalg.norm(pull_b[i])),
                "pull_c_deg": _json_float(_deg(pull_c[i])),
                "pull_c_m": float(np.linalg.norm(pull_c[i])),
                "angle_deg": _json_float(angle[i]),
                "field_force_deg": _json_float(_deg(force[i])),
                "pull_b_to_force_deg": _json_float(b_to_force[i]),
                "pull_c_to_force_deg": _json_float(c_to_force[i]),
                "line_deviation_b_m": float(dev_b[i]),
                "line_deviation_c_m": float(dev_c[i]),
            }
        )
    finite = angle[np.isfinite(angle)]
    opposite = np.sign(dev_b) * np.sign(dev_c) < 0
    return {
        "movements": movements,
        "mean_angle_deg": _json_float(finite.mean()) if len(finite) else None,
        "mean_direction_deg": {"b": _circular_mean_deg(pull_b), "c": _circular_mean_deg(pull_c)},
        "angle_between_mean_directions_deg": _json_float(
            _angle_between(np.nanmean(_unit(pull_b), axis=0), np.nanmean(_unit(pull_c), axis=0))
        ),
        "fraction_opposite_line_deviation": float(opposite.mean()),
        "mean_pull_b_to_force_deg": _json_float(np.nanmean(b_to_force)),
        "mean_pull_c_to_force_deg": _json_float(np.nanmean(c_to_force)),
        "fraction_b_with_force": float(np.mean(b_to_force < 90.0)),
        "fraction_c_against_force": float(np.mean(c_to_force > 90.0)),
    }


def minimum_jerk_speed(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk speed shape 30 u^2 (1 - u)^2 at normalized time u in [0, 1] (unit distance and duration)."""
    return 30.0 * u**2 * (1.0 - u) ** 2


def straightness(hand: np.ndarray, steps: np.ndarray, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Largest perpendicular deviation from the start-target line / start-target distance: (M,) [1]."""
    valid = np.arange(hand.shape[1])[None, :] <= steps[:, None]
    u = _unit(targets - starts)
    rel = hand - starts[:, None]
    perp = np.abs(u[:, None, 0] * rel[..., 1] - u[:, None, 1] * rel[..., 0])
    return np.max(np.where(valid, perp, 0.0), axis=1) / np.linalg.norm(targets - starts, axis=-1)


def bell_correlation(speed: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Pearson correlation of each speed profile with the minimum-jerk profile of its duration: (M,).

    Samples k = 0..steps are compared with 30 u^2 (1 - u)^2 at u = k / steps; the distance only scales the
    template, which a correlation ignores. NaN for profiles shorter than 3 samples or without variation.
    """
    k = np.arange(speed.shape[1])[None, :]
    valid = k <= steps[:, None]
    u = k / np.maximum(steps[:, None], 1)
    tmpl = minimum_jerk_speed(np.clip(u, 0.0, 1.0))
    n = valid.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ms = np.where(valid, speed, 0.0).sum(axis=1) / n
        mt = np.where(valid, tmpl, 0.0).sum(axis=1) / n
        ds = np.where(valid, speed - ms[:, None], 0.0)
        dt = np.where(valid, tmpl - mt[:, None], 0.0)
        r = (ds * dt).sum(axis=1) / np.sqrt((ds**2).sum(axis=1) * (dt**2).sum(axis=1))
    return np.where((n >= 3) & np.isfinite(r), r, np.nan)


def count_peaks(speed: np.ndarray, prominence: float) -> int:
    """Number of interior local maxima of a (T,) speed profile that rise at least `prominence` x its top speed
    above the higher of their two bases (the lowest points before a higher sample on either side). A profile
    still rising when the movement ends has no peak."""
    s = np.asarray(speed, dtype=float)
    if len(s) < 3 or s.max() <= 0:
        return 0
    peaks = np.flatnonzero((s[1:-1] > s[:-2]) & (s[1:-1] >= s[2:])) + 1
    n = 0
    for p in peaks:
        left = s[:p][::-1]
        higher = np.flatnonzero(left > s[p])
        left_base = left[: higher[0] if len(higher) else len(left)].min()
        right = s[p + 1 :]
        higher = np.flatnonzero(right > s[p])
        right_base = right[: higher[0] if len(higher) else len(right)].min()
        n += s[p] - max(left_base, right_base) >= prominence * s.max()
    return int(n)


def movement_quality(ep: Episode, starts: np.ndarray, targets: np.ndarray, cfg: Config) -> dict:
    """Straightness, bell-shape correlation and speed peaks over the successful movements of `ep`.

    Args:
      ep: Episode arrays with one leading axis M (numpy).
      starts, targets: (M, 2) [m].
      cfg: model config (cfg.eval.peak_prominence).
    """
    ok = np.asarray(ep.outcome) == SUCCESS
    steps = np.asarray(ep.steps)[ok]
    hand, speed = np.asarray(ep.hand)[ok], np.asarray(ep.speed)[ok]
    s = straightness(hand, steps, starts[ok], targets[ok])
    r = bell_correlation(speed, steps)
    peaks = np.array([count_peaks(sp[: n + 1], cfg.eval.peak_prominence) for sp, n in zip(speed, steps, strict=True)])

    def stats(x):
        x = x[np.isfinite(x)]
        if len(x) == 0:
            return {"mean": None, "median": None}
        return {"mean": float(np.mean(x)), "median": float(np.median(x))}

    return {
        "movements": int(ok.size),
        "successful": int(ok.sum()),
        "straightness": stats(s),
        "bell_correlation": stats(r),
        "speed_peaks": {**stats(peaks.astype(float)), "single_peak_fraction": _json_float(np.mean(peaks == 1))}
        if len(peaks)
        else {"mean": None, "median": None, "single_peak_fraction": None},
    }


def minimum_jerk_episodes(starts: np.ndarray, targets: np.ndarray, cfg: Config) -> Episode:
    """Straight minimum-jerk hand movements of cfg.eval.reference_duration, sampled every cfg.arm.dt and ended
    by the same goal test as the arm (the human-like yardstick of `quality`): Episode with leading axis M."""
    total = n_steps(cfg)
    u = np.clip(np.arange(total + 1) * cfg.arm.dt / cfg.eval.reference_duration, 0.0, 1.0)
    shape = 10 * u**3 - 15 * u**4 + 6 * u**5
    hand = starts[:, None] + (targets - starts)[:, None] * shape[None, :, None]
    dist = np.linalg.norm(targets - starts, axis=-1)
    speed = dist[:, None] * minimum_jerk_speed(u)[None] / cfg.eval.reference_duration
    vel = _unit(targets - starts)[:, None] * speed[..., None]
    goal = np.array(
        jax.vmap(jax.vmap(lambda h, v, g: task.goal_reached(h, v, g, cfg), in_axes=(0, 0, None)))(
            jnp.asarray(hand), jnp.asarray(vel), jnp.asarray(targets)
        )
    )
    goal[:, 0] = False
    reached = goal.any(axis=1)
    steps = np.where(reached, np.argmax(goal, axis=1), total)
    held = np.minimum(np.arange(total + 1)[None], steps[:, None])
    rows = np.arange(len(starts))[:, None]
    return Episode(
        outcome=np.where(reached, SUCCESS, FAIL), steps=steps, hand=hand[rows, held], speed=speed[rows, held]
    )


def quality(ep: Episode, learners, starts: np.ndarray, targets: np.ndarray, cfg: Config) -> dict:
    """Movement quality per learning x test cell over the lattice pairs, and for the minimum-jerk yardstick.

    Straightness is the largest perpendicular deviation of the hand from the straight start-target line,
    divided by the start-target distance (0 for a straight path). Bell shape is the Pearson correlation of
    the speed samples from the start to the goal with the minimum-jerk speed profile 30 u^2 (1 - u)^2 of the
    same duration (1 for a perfect bell). Peaks are local speed maxima with a prominence of at least
    cfg.eval.peak_prominence of the movement's top speed. Only successful movements are measured. The
    yardstick is a straight minimum-jerk movement of cfg.eval.reference_duration per pair, cut by the
    same goal test, so it shows what a human-like movement scores under the same cut.

    Args:
      ep: Episode arrays with leading axes (N, C, P), numpy.
      learners: (learning condition, seed index) per network.
      starts, targets: (P, 2) [m].
      cfg: model config.
    """
    cells = []
    for learning in [c for c in CONDITIONS if any(c == name for name, _ in learners)]:
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(TEST_CONDITIONS):
            sub = Episode(*(np.concatenate([np.asarray(a)[i, j] for i in nets]) for a in ep))
            reps = len(nets)
            cells.append(
                {
                    "learning": learning,
                    "test": test,
                    "networks": reps,
                    **movement_quality(sub, np.tile(starts, (reps, 1)), np.tile(targets, (reps, 1)), cfg),
                }
            )
    reference = movement_quality(minimum_jerk_episodes(starts, targets, cfg), starts, targets, cfg)
    return {
        "cells": cells,
        "minimum_jerk_reference": {"duration_s": cfg.eval.reference_duration, **reference},
        "peak_prominence": cfg.eval.peak_prominence,
    }


class RunData(NamedTuple):
    """Everything read from a run directory before anything is written."""

    cfg: Config
    batch: train.Batch
    chunk: int
    learners: list
    metrics: list


def read_metrics(run_dir: Path) -> list[dict]:
    """Rows of metrics.jsonl ([] when the run has no finished chunk); raises CheckpointError on a bad line."""
    path = Path(run_dir) / checkpoint.METRICS_FILE
    if not path.exists():
        return []
    rows = []
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise checkpoint.CheckpointError(f"{path}: unreadable ({exc})") from None
    for n, line in enumerate(text.splitlines(), 1):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            raise checkpoint.CheckpointError(f"{path}: line {n} is not valid JSON") from None
        if not isinstance(row, dict):
            raise checkpoint.CheckpointError(f"{path}: line {n} is not a JSON object")
        rows.append(row)
    return rows


def load_run(run_dir: Path) -> RunData:
    """Config, newest checkpoint and metrics of a run; raises CheckpointError naming the bad path."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise checkpoint.CheckpointError(f"{run_dir}: not a run directory (missing or not a directory)")
    cfg = train.read_config(run_dir)
    batch, chunk = train.load_batch(run_dir, cfg)
    return RunData(cfg, batch, chunk, train.learner_table(cfg.train), read_metrics(run_dir))


def evaluate_run(data: RunData) -> dict:
    """Run the test protocol on every network of a run; JSON-ready results and the arrays for the figures."""
    cfg = data.cfg
    starts, targets = test_pairs(cfg)
    c_starts, c_targets, c_corner = corner_pairs(cfg)
    ep = evaluate(
        network_policy(cfg),
        data.batch.states.params,
        data.batch.conds.input_mask,
        test_fields(cfg),
        np.concatenate([starts, c_starts]),
        np.concatenate([targets, c_targets]),
        cfg,
    )
    ep = Episode(*jax.device_get(ep))
    p = len(starts)
    lattice = Episode(*(a[:, :, :p] for a in ep))
    corners = Episode(*(a[:, :, p:] for a in ep))

    def network(learning):
        for i, (name, seed) in enumerate(data.learners):
            if name == learning and seed == cfg.eval.figure_seed:
                return i
        return None

    panels = {}
    for letter, learning, test in FIG4_PANELS:
        i = network(learning)
        if i is not None:
            j = TEST_CONDITIONS.index(test)
            panels[letter] = Episode(*(a[i, j] for a in corners))
    after = None
    if all(k in panels for k in "abcd"):
        viscous = np.asarray(task.make_condition("viscous", cfg).field)
        after = aftereffect({k: panels[k].hand for k in "abcd"}, c_starts, c_targets, c_corner, viscous)
        after = {"seed": cfg.eval.figure_seed, **after}
    trials = np.asarray(data.batch.states.trials)
    table = table2(lattice.outcome, lattice.steps, data.learners, cfg)
    # A sweep has several networks per (condition, seed); their hyperparameters tell them apart.
    hypers = jax.device_get(data.batch.hypers)
    for row in table["per_network"]:
        row.update({name: float(getattr(hypers, name)[row["learner"]]) for name in train.HYPER_GRIDS})
    return {
        "table2": {
            **table,
            "chunk": data.chunk,
            "trials_per_network": [int(t) for t in trials],
        },
        "aftereffect": after
        or {"error": "needs the none and viscous learning conditions at seed cfg.eval.figure_seed"},
        "quality": quality(lattice, data.learners, starts, targets, cfg),
        "panels": panels,
        "corners": (c_starts, c_targets, c_corner),
    }


def write_results(run_dir: Path, data: RunData, results: dict) -> Path:
    """Write every file of RUN_DIR/eval/; returns that directory."""
    from reach_jax import figures

    cfg = data.cfg
    out = Path(run_dir) / EVAL_DIR
    out.mkdir(exist_ok=True)
    for name in ("table2", "aftereffect", "quality"):
        checkpoint.atomic_write_bytes(out / f"{name}.json", json.dumps(results[name], indent=2).encode())
    md = table2_markdown(results["table2"], f"{run_dir} (chunk {data.chunk})")
    checkpoint.atomic_write_bytes(out / "table2.md", md.encode())
    figures.fig4(results["panels"], *results["corners"], cfg).savefig(out / "fig4.png", dpi=110)
    figures.fig5(results["panels"], results["corners"][2], cfg).savefig(out / "fig5.png", dpi=110)
    figures.learning_curves(data.metrics, cfg).savefig(out / "learning_curves.png", dpi=110)
    figures.close_all()
    return out


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.exit(EXIT_USAGE, error_line(self.prog, message))


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface of `python -m reach_jax.evaluate`."""
    p = _Parser(prog="python -m reach_jax.evaluate", description=__doc__.splitlines()[0])
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run directory written by reach_jax.train")
    return p


def main(argv=None) -> int:
    """CLI entry point; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        data = load_run(args.run_dir)
    except checkpoint.CheckpointError as exc:
        sys.stderr.write(error_line(parser.prog, str(exc)))
        return EXIT_USAGE
    results = evaluate_run(data)
    try:
        out = write_results(args.run_dir, data, results)
    except OSError as exc:
        sys.stderr.write(error_line(parser.prog, f"{args.run_dir / EVAL_DIR}: write failed ({exc})"))
        return EXIT_IO
    print(f"evaluation written to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
