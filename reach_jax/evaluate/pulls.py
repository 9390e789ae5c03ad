"""The after-effect of Fig. 4 as pull vectors and line deviations, pooled over seeds; lengths [m], angles [deg].

Directions are measured counter-clockwise from +x. Hand paths are time-aligned and held at their end point once
an episode ends (`episodes.Episode.hand`).
"""

from __future__ import annotations

import math

import numpy as np

from reach_jax.env import trial_log
from reach_jax.evaluate import stats
from reach_jax.evaluate.paper_figures import CORNER_NAMES


def _deg(v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(v[..., 1], v[..., 0]))


def _angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(trial_log.unit(u) * trial_log.unit(v), axis=-1), -1.0, 1.0)))


def _json_float(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _circular_mean_deg(v: np.ndarray) -> float | None:
    u = trial_log.unit(v)
    u = u[np.all(np.isfinite(u), axis=-1)]
    if len(u) == 0:
        return None
    m = u.mean(axis=0)
    return _json_float(_deg(m)) if np.linalg.norm(m) > 0 else None


def pull_vectors(path: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Largest time-aligned displacement of each path from its reference path: (M, T, 2) x2 -> (M, 2) [m]."""
    d = path - reference
    k = np.argmax(np.linalg.norm(d, axis=-1), axis=-1)
    return d[np.arange(len(d)), k]


def line_deviation(path: np.ndarray, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Signed largest perpendicular deviation from the start-target line, + to the left of travel: (M,) [m].

    Args:
      path: (M, T, 2) hand paths [m] (held at their end point after the episode ends).
      starts: (M, 2) [m].
      targets: (M, 2) [m].
    """
    side = trial_log.perpendicular(trial_log.unit(targets - starts)[:, None], path - starts[:, None])
    k = np.argmax(np.abs(side), axis=-1)
    return side[np.arange(len(side)), k]


def _measures(paths: dict, starts: np.ndarray, targets: np.ndarray, field: np.ndarray) -> dict[str, np.ndarray]:
    """Each movement's pulls in (b) and (c), the field's force, the angles between them and the line deviations.

    Args:
      paths: {"a"|"b"|"c"|"d": (M, T, 2) hand paths [m]} of one network per learning condition.
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      field: (2, 2) viscous field matrix of the test condition [N s/m].

    Returns:
      pull_b, pull_c: (M, 2) [m]; force: (M, 2), along the field's force; angle (between the pulls), b_to_force,
      c_to_force: (M,) [deg]; dev_b, dev_c: (M,) [m].
    """
    pull_b = pull_vectors(paths["b"], paths["a"])
    pull_c = pull_vectors(paths["c"], paths["d"])
    force = (targets - starts) @ np.asarray(field).T
    return {
        "pull_b": pull_b,
        "pull_c": pull_c,
        "angle": _angle_between(pull_b, pull_c),
        "force": force,
        "b_to_force": _angle_between(pull_b, force),
        "c_to_force": _angle_between(pull_c, force),
        "dev_b": line_deviation(paths["b"], starts, targets),
        "dev_c": line_deviation(paths["c"], starts, targets),
    }


def _movement_rows(m: dict, starts: np.ndarray, targets: np.ndarray, start_corner: np.ndarray) -> list[dict]:
    """aftereffect.json's "movements": each movement's start, target and corner with its `_measures` m.

    Args:
      m: `_measures` of the M movements.
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      start_corner: (M,) index into CORNER_NAMES.
    """
    return [
        {
            "start_m": [float(v) for v in starts[i]],
            "target_m": [float(v) for v in targets[i]],
            "start_corner": CORNER_NAMES[int(start_corner[i])],
            "pull_b_deg": _json_float(_deg(m["pull_b"][i])),
            "pull_b_m": float(np.linalg.norm(m["pull_b"][i])),
            "pull_c_deg": _json_float(_deg(m["pull_c"][i])),
            "pull_c_m": float(np.linalg.norm(m["pull_c"][i])),
            "angle_deg": _json_float(m["angle"][i]),
            "field_force_deg": _json_float(_deg(m["force"][i])),
            "pull_b_to_force_deg": _json_float(m["b_to_force"][i]),
            "pull_c_to_force_deg": _json_float(m["c_to_force"][i]),
            "line_deviation_b_m": float(m["dev_b"][i]),
            "line_deviation_c_m": float(m["dev_c"][i]),
        }
        for i in range(len(starts))
    ]


def _summary(m: dict) -> dict:
    """The measures over all movements of `_measures` m: mean angles and directions, fractions with the force."""
    finite = m["angle"][np.isfinite(m["angle"])]
    unit_b, unit_c = trial_log.unit(m["pull_b"]), trial_log.unit(m["pull_c"])
    return {
        "mean_angle_deg": _json_float(finite.mean()) if len(finite) else None,
        "mean_direction_deg": {"b": _circular_mean_deg(m["pull_b"]), "c": _circular_mean_deg(m["pull_c"])},
        "angle_between_mean_directions_deg": _json_float(
            _angle_between(np.nanmean(unit_b, axis=0), np.nanmean(unit_c, axis=0))
        ),
        "fraction_opposite_line_deviation": float((np.sign(m["dev_b"]) * np.sign(m["dev_c"]) < 0).mean()),
        "mean_pull_b_to_force_deg": _json_float(np.nanmean(m["b_to_force"])),
        "mean_pull_c_to_force_deg": _json_float(np.nanmean(m["c_to_force"])),
        "fraction_b_with_force": float(np.mean(m["b_to_force"] < 90.0)),
        "fraction_c_against_force": float(np.mean(m["c_to_force"] > 90.0)),
    }


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
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      start_corner: (M,) index into CORNER_NAMES.
      field: (2, 2) viscous field matrix of the test condition [N s/m].

    Returns:
      JSON-ready dict.
    """
    measures = _measures(paths, starts, targets, field)
    return {"movements": _movement_rows(measures, starts, targets, start_corner), **_summary(measures)}


def pool_aftereffect(per_seed: list[dict], level: float) -> dict:
    """The after-effect measures of several seeds together: mean fractions, and the angle with its interval.

    Args:
      per_seed: `aftereffect` results, one per seed.
      level: confidence level of the angle's t-interval.
    """
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
