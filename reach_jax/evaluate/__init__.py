"""Table-2 test protocol, Fig. 4-5 movements, after-effect and movement quality (section 4.4, model §8-10).

`evaluate(run_dir)` (or `python -m reach_jax.evaluate RUN_DIR`) loads the newest checkpoint of a run and writes
RUN_DIR/eval/: table2.json, table2.md, fig4.png, fig5.png, aftereffect.json, quality.json and learning_curves.png.

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

import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax import adaptation, claims, fields, figures, files, hyper, impedance, sensor, stats, task
from reach_jax import run_dir as run_dir_io
from reach_jax.checkpoint import CheckpointError
from reach_jax.config import Config
from reach_jax.episodes import Episode, n_steps, network_policy, run_episodes
from reach_jax.outcomes import FAIL, SUCCESS
from reach_jax.outcomes import NAMES as OUTCOME_NAMES
from reach_jax.panels import CORNER_NAMES, FIG4_PANELS, corner_pairs

EVAL_DIR = "eval"
RESULT_FILES = ("table2", "aftereffect", "quality", "impedance", "claims")  # each written as NAME.json


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


def test_fields(cfg: Config) -> fields.Field:
    """The hand-force fields of cfg.eval.test_conditions, stacked along a leading axis."""
    return jax.tree.map(lambda *f: jnp.stack(f), *(task.make_condition(n, cfg).field for n in cfg.eval.test_conditions))


def trial_times(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> np.ndarray:
    """Reaching time per episode [s]: steps x dt for a success, cfg.eval.max_time for out and fail (model §8)."""
    return np.where(np.asarray(outcome) == SUCCESS, np.asarray(steps) * cfg.arm.dt, cfg.eval.max_time)


def count(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> dict:
    """success / out / fail counts and mean time over all given episodes (any shape)."""
    outcome = np.asarray(outcome)
    return {
        **{name: int(np.sum(outcome == code)) for code, name in enumerate(OUTCOME_NAMES)},
        "mean_time_s": float(np.mean(trial_times(outcome, steps, cfg))),
    }


def recipe_index(hypers) -> tuple[list[dict], list[int]]:
    """The distinct hyperparameter sets (recipes) of a batch, in batch order, and each learner's recipe index.

    Args:
      hypers: hyper.Hyper with a leading learner axis.

    Returns:
      (each recipe's hyperparameters that name it, `hyper.label`; each learner's recipe index).
    """
    columns = [np.asarray(getattr(hypers, n)) for n in hyper.NAMES]
    values = [tuple(float(v) for v in row) for row in zip(*columns, strict=True)]
    distinct = list(dict.fromkeys(values))
    named = [hyper.label(dict(zip(hyper.NAMES, v, strict=True))) for v in distinct]
    return named, [distinct.index(v) for v in values]


def learning_conditions(learners: list[tuple[str, int]], cfg: Config) -> list[str]:
    """The learning conditions that have networks, in the order of the config's conditions table."""
    names = {name for name, _ in learners}
    return [c.name for c in cfg.conditions if c.name in names]


def table2(outcome: np.ndarray, steps: np.ndarray, learners: list[tuple[str, int]], recipe_of, cfg: Config) -> dict:
    """Table 2 as a JSON-ready dict: counts summed over each learning condition's networks, and per network.

    Args:
      outcome: (N, C, 1040) outcome codes, networks in `learners` order, tests in cfg.eval.test_conditions order.
      steps: (N, C, 1040) episode lengths [steps].
      learners: (learning condition, seed index) per network.
      recipe_of: (N,) recipe index per network (`recipe_index`).
      cfg: model config.

    Returns:
      {"rows": sums over every network of a condition, "first_two": sums over seeds 0 and 1 per recipe,
      "per_network": one row per network and test, "pairs_per_network"}.
    """
    rows, first_two, per_network = [], [], []
    present = learning_conditions(learners, cfg)
    for learning in present:
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(cfg.eval.test_conditions):
            cell = count(outcome[nets, j], steps[nets, j], cfg)
            rows.append({"learning": learning, "test": test, "networks": len(nets), **cell})
    for k in sorted(set(recipe_of)):
        for learning in present:
            nets = [i for i, (name, s) in enumerate(learners) if name == learning and s < 2 and recipe_of[i] == k]
            for j, test in enumerate(cfg.eval.test_conditions):
                cell = count(outcome[nets, j], steps[nets, j], cfg)
                first_two.append({"learning": learning, "test": test, "recipe": k, "networks": len(nets), **cell})
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(cfg.eval.test_conditions):
            cell = count(outcome[i, j], steps[i, j], cfg)
            per_network.append(
                {"learner": i, "learning": learning, "seed": seed, "recipe": recipe_of[i], "test": test, **cell}
            )
    return {
        "rows": rows,
        "first_two": first_two,
        "pairs_per_network": int(outcome.shape[-1]),
        "per_network": per_network,
    }


def _cell(success: int, out: int, fail: int, mean_time: float) -> str:
    return f"{success}-{out}-{fail} ({mean_time:.3g} s)"


def _interval(ci: dict, scale: float = 100.0, digits: int = 1) -> str:
    if ci["low"] is None:
        return f"{ci['mean'] * scale:.{digits}f}"
    return f"{ci['mean'] * scale:.{digits}f} [{ci['low'] * scale:.{digits}f}, {ci['high'] * scale:.{digits}f}]"


def table2_markdown(table: dict, recipes: list[dict], source: str) -> str:
    """Table 2 in Markdown per recipe: mean per network with its interval, our networks 0-1 summed, the paper's."""
    level = recipes[0]["level"] if recipes else 0.95
    lines = [
        f"# Table 2 — {source}",
        "",
        f"Mean per network with its {level:.0%} t-interval over networks (on the logit scale for success and out),"
        f" {table['pairs_per_network']} (start, target) pairs per network; out and fail count as 4.0 s in the mean"
        " time. Beside it, success-out-fail (mean time) summed over our networks of seeds 0 and 1, and the paper's"
        f" sum over its {claims.PAPER_NETWORKS}"
        ' networks. "near paper": success and out within the target\'s percentage points, time within its'
        " fraction (S / O / T).",
    ]
    sums = {(r["learning"], r["test"], r["recipe"]): r for r in table["first_two"]}
    for k, recipe in enumerate(recipes):
        lines += [
            "",
            f"## Recipe {k}: {_recipe_name(recipe['hypers'])} "
            f"({recipe['networks_per_condition']} networks per condition)",
            "",
            "| learning → test | success % | out % | mean time [s] | ours, seeds 0–1 | paper | near paper |",
            "|---|---|---|---|---|---|---|",
        ]
        for cell in recipe["cells"]:
            first = sums.get((cell["learning"], cell["test"], k))
            ours01 = _cell(first["success"], first["out"], first["fail"], first["mean_time_s"]) if first else "–"
            key = (cell["learning"], cell["test"])
            paper = _cell(*claims.PAPER_TABLE2[key]) if key in claims.PAPER_TABLE2 else "–"
            near = (
                " / ".join("yes" if cell["near_paper"][n] else "no" for n in ("success", "out", "mean_time_s"))
                if cell["near_paper"]
                else "–"
            )
            lines.append(
                f"| {cell['learning']} → {cell['test']} | {_interval(cell['success'])} | {_interval(cell['out'])} | "
                f"{_interval(cell['mean_time_s'], 1.0, 2)} | {ours01} | "
                f"{paper} | {near} |"
            )
    return "\n".join(lines) + "\n"


def _recipe_name(hypers: dict) -> str:
    return ", ".join(f"{k} {v:g}" for k, v in hypers.items())


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
    For the classic sign test we also give model §9's line measure: the signed largest perpendicular
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
    for learning in learning_conditions(learners, cfg):
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(cfg.eval.test_conditions):
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


def quality_markdown(q: dict, source: str) -> str:
    """The movement-quality cells and the minimum-jerk yardstick as a Markdown table."""
    ref = q["minimum_jerk_reference"]
    lines = [
        f"# Movement quality — {source}",
        "",
        "Over the successful movements of the lattice pairs. Straightness: largest perpendicular deviation over the "
        "start–target distance. Bell: correlation of the speed profile with the minimum-jerk profile of the same "
        f"distance and duration. Peaks: speed maxima of at least {100 * q['peak_prominence']:g}% prominence.",
        "",
        "| learning → test | networks | successful | straightness (median) | bell (median) | speed peaks (median) "
        "| single-peaked |",
        "|---|---|---|---|---|---|---|",
    ]

    def num(value, spec: str) -> str:
        return "–" if value is None else format(value, spec)  # None: no successful movement to measure

    def row(name: str, cell: dict, networks: str) -> str:
        peaks = cell["speed_peaks"]
        single = peaks["single_peak_fraction"]
        return (
            f"| {name} | {networks} | {cell['successful']}/{cell['movements']} | "
            f"{num(cell['straightness']['median'], '.3f')} | {num(cell['bell_correlation']['median'], '.2f')} | "
            f"{num(peaks['median'], 'g')} | {num(single, '.1%')} |"
        )

    for cell in q["cells"]:
        lines.append(row(f"{cell['learning']} → {cell['test']}", cell, str(cell["networks"])))
    lines.append(row(f"minimum jerk, {ref['duration_s']:g} s", ref, "–"))
    return "\n".join(lines) + "\n"


def pool_aftereffect(per_seed: list[dict], level: float) -> dict:
    """The after-effect measures of several seeds together: mean fractions, and the angle with its interval."""
    if not per_seed:
        return {}

    def mean(key):
        values = [a[key] for a in per_seed if a[key] is not None]
        return float(np.mean(values)) if values else None

    return {
        "seeds": len(per_seed),
        "fraction_b_with_force": mean("fraction_b_with_force"),
        "fraction_c_against_force": mean("fraction_c_against_force"),
        "mean_pull_b_to_force_deg": mean("mean_pull_b_to_force_deg"),
        "mean_pull_c_to_force_deg": mean("mean_pull_c_to_force_deg"),
        "angle_deg": stats.mean_ci([a["mean_angle_deg"] for a in per_seed if a["mean_angle_deg"] is not None], level),
    }


def impedance_cells(summary: dict, nets: list[int], level: float) -> list[dict]:
    """Mean over networks (with its interval) of each network's median gains, per learning x test cell."""
    rows = [r for r in summary["per_network"] if r["learner"] in nets]
    names = [k for k in rows[0] if k.startswith(("stiffness_", "damping_", "passive_")) and "per_m" not in k]
    cells = []
    for learning, test in dict.fromkeys((r["learning"], r["test"]) for r in rows):
        sub = [r for r in rows if r["learning"] == learning and r["test"] == test and r["states"] > 0]
        cells.append(
            {
                "learning": learning,
                "test": test,
                **{n: stats.mean_ci([r[n]["median"] for r in sub], level) for n in names},
            }
        )
    return cells


def evaluate_run(data: run_dir_io.Run) -> dict:
    """Run the test protocol on every network of a run; JSON-ready results and the arrays for the figures."""
    cfg = data.cfg
    starts, targets = test_pairs(cfg)
    c_starts, c_targets, c_corner = corner_pairs(cfg)
    params, masks = data.batch.states.agent.params, data.batch.conds.input_mask
    policy = network_policy(cfg)
    ep, traj = jax.device_get(
        run_episodes(
            policy,
            params,
            masks,
            test_fields(cfg),
            np.concatenate([starts, c_starts]),
            np.concatenate([targets, c_targets]),
            cfg,
        )
    )
    p = len(starts)
    lattice = Episode(*(a[:, :, :p] for a in ep))
    corners = Episode(*(a[:, :, p:] for a in ep))
    lattice_traj = type(traj)(*(a[:, :, :p] for a in traj))
    recipes, recipe_of = recipe_index(data.batch.hypers)
    table = table2(lattice.outcome, lattice.steps, data.learners, recipe_of, cfg)
    for row in table["per_network"]:
        row.update(recipes[row["recipe"]])

    def net_index(learning, seed, recipe):
        for i, (name, s) in enumerate(data.learners):
            if name == learning and s == seed and recipe_of[i] == recipe:
                return i
        return None

    tests = cfg.eval.test_conditions
    panels = {}
    for letter, learning, test in FIG4_PANELS:
        i = net_index(learning, cfg.eval.figure_seed, 0)
        if i is not None and test in tests:
            panels[letter] = Episode(*(a[i, tests.index(test)] for a in corners))
    viscous = np.asarray(task.make_condition("viscous", cfg).field.viscous)  # the float32 matrix the arm felt
    per_seed = []
    for k in range(len(recipes)):
        for seed in range(cfg.train.seeds):
            i, j = net_index("none", seed, k), net_index("viscous", seed, k)
            if i is None or j is None or not {"none", "viscous"} <= set(tests):
                continue
            off, on = tests.index("none"), tests.index("viscous")
            hands = {
                "a": corners.hand[i, off],
                "b": corners.hand[i, on],
                "c": corners.hand[j, off],
                "d": corners.hand[j, on],
            }
            per_seed.append({"recipe": k, "seed": seed, **aftereffect(hands, c_starts, c_targets, c_corner, viscous)})
    main = [a for a in per_seed if a["recipe"] == 0 and a["seed"] == cfg.eval.figure_seed]
    after = (
        {**main[0], "per_seed": per_seed}
        if main
        else {"error": "needs the none and viscous learning conditions at seed cfg.eval.figure_seed"}
    )
    gains = impedance.measure(policy, params, masks, lattice, lattice_traj, starts, targets, cfg)
    imp = impedance.summarize(gains, data.learners, cfg.eval.test_conditions, viscous)
    for row in imp["per_network"]:
        row["recipe"] = recipe_of[row["learner"]]
    verdicts = decide(table, per_seed, imp, recipes, recipe_of, data.metrics, cfg)
    trials = np.asarray(data.batch.states.env.trials)
    return {
        "adaptation": adaptation.analyse(data.trials, data.learners, cfg),
        "table2": {**table, "chunk": data.chunk, "trials_per_network": [int(t) for t in trials]},
        "aftereffect": after,
        "quality": quality(lattice, data.learners, starts, targets, cfg),
        "impedance": {**imp, "recipes": recipes, "chunk": data.chunk},
        "claims": {"chunk": data.chunk, "trials_per_network": cfg.train.trials, "recipes": verdicts},
        "panels": panels,
        "corners": (c_starts, c_targets, c_corner),
        "gains": gains,
    }


def decide(
    table: dict, per_seed: list[dict], imp: dict, recipes: list[dict], recipe_of: list[int], metrics: list[dict], cfg
) -> list[dict]:
    """The claims of each recipe, from the Table-2 counts, the after-effect per seed, the impedance and the metrics.

    Args:
      table: `table2` results (its per-network counts).
      per_seed: the after-effect measures per (recipe, seed) (`aftereffect`).
      imp: `impedance.summarize` results, each per-network row with its recipe.
      recipes: each recipe's hyperparameters (`recipe_index`).
      recipe_of: (N,) recipe index per network.
      metrics: the run's metrics.jsonl rows up to the evaluated checkpoint.
      cfg: model config.
    """
    level = cfg.claims.level
    verdicts = []
    for k, hypers in enumerate(recipes):
        nets = [i for i in range(len(recipe_of)) if recipe_of[i] == k]
        cells = claims.Cells([r for r in table["per_network"] if r["recipe"] == k], table["pairs_per_network"])
        after_k = pool_aftereffect([a for a in per_seed if a["recipe"] == k], level)
        verdicts.append(
            {
                "hypers": hypers,
                "level": level,
                "networks_per_condition": cfg.train.seeds,
                "claims": claims.recipe_claims(cells, after_k, cfg),
                "aftereffect": after_k,
                "cells": claims.table_cells(cells, cfg.claims),
                "impedance": impedance_cells(imp, nets, level),
                "curriculum": claims.curriculum_stability(metrics, nets, cfg.train.trials, cfg),
            }
        )
    return verdicts


def redecide(run_dir: Path) -> dict:
    """Decide the claims again from a run's committed eval/ files, without running the test episodes again.

    For a change in how claims are decided (the statistics, the criteria's presentation): the test episodes
    round differently in float32 on another CPU, where a few of a network's 2080 movements can change outcome.
    Rewrites eval/claims.json, claims.md and table2.md; returns the new claims results.
    """
    run_dir = Path(run_dir)
    out = run_dir / EVAL_DIR
    paths = [out / f"{n}.json" for n in ("table2", "aftereffect", "impedance")]
    for path in paths:
        if not path.is_file():
            raise CheckpointError(f"{path}: missing; evaluate the run in full first")
    table, after, imp = (json.loads(path.read_text()) for path in paths)
    cfg = run_dir_io.read_config(run_dir)
    recipe_of = list(dict(sorted({r["learner"]: r["recipe"] for r in imp["per_network"]}.items())).values())
    metrics = run_dir_io.read_metrics(run_dir, table["chunk"])
    verdicts = decide(table, after.get("per_seed", []), imp, imp["recipes"], recipe_of, metrics, cfg)
    result = {"chunk": table["chunk"], "trials_per_network": cfg.train.trials, "recipes": verdicts}
    source = f"{run_dir} (chunk {table['chunk']})"
    files.atomic_write_bytes(out / "claims.json", json.dumps(result, indent=2).encode())
    files.atomic_write_bytes(out / "table2.md", table2_markdown(table, verdicts, source).encode())
    files.atomic_write_bytes(out / "claims.md", claims.claims_markdown(result, source).encode())
    return result


def write_results(run_dir: Path, data: run_dir_io.Run, results: dict, out: Path | None = None) -> Path:
    """Write every file of the evaluation into `out` (default RUN_DIR/eval/); returns that directory."""
    cfg = data.cfg
    out = Path(run_dir) / EVAL_DIR if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in RESULT_FILES:
        files.atomic_write_bytes(out / f"{name}.json", json.dumps(results[name], indent=2).encode())
    source = f"{run_dir} (chunk {data.chunk})"
    recipes = results["claims"]["recipes"]
    files.atomic_write_bytes(out / "table2.md", table2_markdown(results["table2"], recipes, source).encode())
    files.atomic_write_bytes(out / "claims.md", claims.claims_markdown(results["claims"], source).encode())
    files.atomic_write_bytes(out / "quality.md", quality_markdown(results["quality"], source).encode())
    figures.impedance(results["impedance"], results["gains"], data.learners, cfg).savefig(
        out / "impedance.png", dpi=110
    )
    figures.fig4(results["panels"], *results["corners"], cfg).savefig(out / "fig4.png", dpi=110)
    figures.fig5(results["panels"], results["corners"][2], cfg).savefig(out / "fig5.png", dpi=110)
    figures.learning_curves(data.metrics, cfg).savefig(out / "learning_curves.png", dpi=110)
    if results["adaptation"] is not None:
        files.atomic_write_bytes(out / "adaptation.json", json.dumps(results["adaptation"], indent=2).encode())
        text = adaptation.markdown(results["adaptation"], source)
        files.atomic_write_bytes(out / "adaptation.md", text.encode())
        figures.adaptation(results["adaptation"], cfg).savefig(out / "adaptation.png", dpi=110)
    return out


def evaluate(run_dir: Path, checkpoint_path: Path | None = None, out: Path | None = None) -> dict:
    """Evaluate a run at its newest (or the given) checkpoint and write every file into `out` (default RUN_DIR/eval).

    Returns the JSON-ready results, keyed by file: table2, aftereffect, quality, impedance, claims, and adaptation
    (None for a run without protocol learners and a per-trial log).
    Raises CheckpointError (one line, naming the bad file) before anything is written.
    """
    run = run_dir_io.load(run_dir, checkpoint_path)
    results = evaluate_run(run)
    write_results(run_dir, run, results, out)
    return {name: results[name] for name in (*RESULT_FILES, "adaptation")}
