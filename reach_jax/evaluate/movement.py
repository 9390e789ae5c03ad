"""Movement quality against a minimum-jerk yardstick: straightness, bell shape and speed peaks; [m], [m/s], [s].

Straightness is the largest perpendicular deviation of the hand from the straight start-target line, divided by
the start-target distance (0 for a straight path). Bell shape is the Pearson correlation of the speed samples from
the start to the goal with the minimum-jerk speed profile 30 u^2 (1 - u)^2 of the same duration (1 for a perfect
bell). Peaks are local speed maxima with a prominence of at least cfg.eval.peak_prominence of the movement's top
speed. Only successful movements are measured.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config
from reach_jax.env import task, trial_log
from reach_jax.env.environment import FAIL, SUCCESS
from reach_jax.evaluate import frames, lattice
from reach_jax.evaluate.episodes import Episode, n_steps


def minimum_jerk_speed(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk speed shape 30 u^2 (1 - u)^2 at normalized time u in [0, 1] (unit distance and duration)."""
    return 30.0 * u**2 * (1.0 - u) ** 2


def straightness(hand: np.ndarray, steps: np.ndarray, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Largest perpendicular deviation from the start-target line / start-target distance: (M,) [1].

    Args:
      hand: (M, T, 2) hand paths [m].
      steps: (M,) movement lengths [steps]; samples 0..steps count.
      starts: (M, 2) [m].
      targets: (M, 2) [m].
    """
    valid = np.arange(hand.shape[1])[None, :] <= steps[:, None]
    perp = np.abs(trial_log.perpendicular(trial_log.unit(targets - starts)[:, None], hand - starts[:, None]))
    return np.max(np.where(valid, perp, 0.0), axis=1) / np.linalg.norm(targets - starts, axis=-1)


def bell_correlation(speed: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Pearson correlation of each speed profile with the minimum-jerk profile of its duration: (M,).

    Samples k = 0..steps are compared with 30 u^2 (1 - u)^2 at u = k / steps; the distance only scales the
    template, which a correlation ignores. NaN for profiles shorter than 3 samples or without variation.

    Args:
      speed: (M, T) hand speeds [m/s].
      steps: (M,) movement lengths [steps].
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
    """Number of interior local maxima of a (T,) speed profile at least `prominence` x its top speed high.

    A peak's height is taken above the higher of its two bases (the lowest points before a higher sample on
    either side). A profile still rising when the movement ends has no peak.
    """
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


def _mean_median(x: np.ndarray) -> dict:
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return {"mean": None, "median": None}
    return {"mean": float(np.mean(x)), "median": float(np.median(x))}


def movement_quality(ep: Episode, starts: np.ndarray, targets: np.ndarray, cfg: Config) -> dict:
    """Straightness, bell-shape correlation and speed peaks over the successful movements of `ep`.

    Args:
      ep: Episode arrays with one leading axis M (numpy).
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      cfg: model config (cfg.eval.peak_prominence).
    """
    ok = np.asarray(ep.outcome) == SUCCESS
    steps = np.asarray(ep.steps)[ok]
    hand, speed = np.asarray(ep.hand)[ok], np.asarray(ep.speed)[ok]
    s = straightness(hand, steps, starts[ok], targets[ok])
    r = bell_correlation(speed, steps)
    peaks = np.array([count_peaks(sp[: n + 1], cfg.eval.peak_prominence) for sp, n in zip(speed, steps, strict=True)])
    return {
        "movements": int(ok.size),
        "successful": int(ok.sum()),
        "straightness": _mean_median(s),
        "bell_correlation": _mean_median(r),
        "speed_peaks": {**_mean_median(peaks.astype(float)), "single_peak_fraction": float(np.mean(peaks == 1))}
        if len(peaks)
        else {"mean": None, "median": None, "single_peak_fraction": None},
    }


def minimum_jerk_episodes(starts: np.ndarray, targets: np.ndarray, cfg: Config) -> Episode:
    """Straight minimum-jerk movements of cfg.eval.reference_duration, ended by the arm's goal test: leading axis M.

    Sampled every cfg.arm.dt: the human-like yardstick of `quality`.

    Args:
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      cfg: model config.
    """
    total = n_steps(cfg)
    u = np.clip(np.arange(total + 1) * cfg.arm.dt / cfg.eval.reference_duration, 0.0, 1.0)
    shape = 10 * u**3 - 15 * u**4 + 6 * u**5
    hand = starts[:, None] + (targets - starts)[:, None] * shape[None, :, None]
    dist = np.linalg.norm(targets - starts, axis=-1)
    speed = dist[:, None] * minimum_jerk_speed(u)[None] / cfg.eval.reference_duration
    vel = trial_log.unit(targets - starts)[:, None] * speed[..., None]
    goal = np.array(
        jax.vmap(jax.vmap(lambda h, v, g: task.goal_reached(h, v, g, task.geometry(cfg), cfg), in_axes=(0, 0, None)))(
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

    The yardstick is a straight minimum-jerk movement of cfg.eval.reference_duration per pair, cut by the
    same goal test, so it shows what a human-like movement scores under the same cut.

    Args:
      ep: Episode arrays with leading axes (N, C, P), numpy.
      learners: (learning condition, seed index) per network.
      starts: (P, 2) [m].
      targets: (P, 2) [m].
      cfg: model config.
    """
    cells = []
    for learning in lattice.learning_conditions(learners, cfg):
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(frames.test_columns(cfg)):
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


def _number(value, spec: str) -> str:
    return "–" if value is None else format(value, spec)  # None: no successful movement to measure


def _quality_row(name: str, cell: dict, networks: str) -> str:
    peaks = cell["speed_peaks"]
    return (
        f"| {name} | {networks} | {cell['successful']}/{cell['movements']} | "
        f"{_number(cell['straightness']['median'], '.3f')} | {_number(cell['bell_correlation']['median'], '.2f')} | "
        f"{_number(peaks['median'], 'g')} | {_number(peaks['single_peak_fraction'], '.1%')} |"
    )


def quality_markdown(q: dict, source: str) -> str:
    """The movement-quality cells and the minimum-jerk yardstick (`quality` results) as a Markdown table."""
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
    for cell in q["cells"]:
        lines.append(_quality_row(f"{cell['learning']} → {cell['test']}", cell, str(cell["networks"])))
    lines.append(_quality_row(f"minimum jerk, {ref['duration_s']:g} s", ref, "–"))
    return "\n".join(lines) + "\n"
