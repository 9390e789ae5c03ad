"""The failure anatomy of the test movements: each out's joint limit and time, each fail's class, their shares per cell.

Units: angles [rad] (the config's fold margin [deg]), positions [m], speeds [m/s], torques [N m], times [s]; a
movement's steps are of cfg.arm.dt.

Every lattice movement gets one label (`LABELS`). A success is a success. An out is named by the joint limit its
last state crossed, checked in the order theta1 < its lower limit, theta1 > its upper limit, theta2 < its minimum,
and timed by its steps. A fail (no success and no out in the 4 s) is classed from its last cfg.eval.anatomy_window
seconds, the first class that fits in the order of `FAIL_CLASSES`:
  folded    the elbow lies on its stop (within anatomy_fold_margin_deg of theta2_stop) in at least
            anatomy_fold_share of the window's states;
  chatter   a joint's torque changes sign from one step to the next, above anatomy_flip_torque on both sides, in at
            least anatomy_chatter_share of the window's steps;
  hover     the hand lies inside the goal square in at least anatomy_hover_share of the window's states (a fail
            there is one whose speed stayed above the goal speed);
  rest_near the hand's mean speed over the window is below anatomy_rest_speed and it ends within
            anatomy_near_cells cells (L-inf) of the target;
  rest_far  at rest, farther away;
  swinging  none of these: the hand still moves at the end.
Beside its class, a fail whose hand stayed in the goal square by the hover rule is marked (`in_goal`). A cell's
shares are each network's fraction of its movements with the label, as a mean over networks with a t-interval on
the logit scale (`stats.rate_ci`), and the pooled composition of the cell's outs and fails. `anatomy_report`
writes them in words and draws them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from reach_jax.config import Config
from reach_jax.config.paper import PAPER_TABLE2
from reach_jax.env.environment import FAIL, OUT, SUCCESS
from reach_jax.evaluate import frames, lattice, stats

OUT_LIMITS = ("theta1_low", "theta1_high", "theta2_low")  # theta1 < 0, theta1 > 90 deg, theta2 < 0 (the defaults)
FAIL_CLASSES = ("folded", "chatter", "hover", "rest_near", "rest_far", "swinging")  # in order of precedence
LABELS = ("success", *OUT_LIMITS, *FAIL_CLASSES)  # a movement's label is its index here


class Thresholds(NamedTuple):
    """What decides a label: the config's thresholds, and the task's geometry per network (it may differ)."""

    window: int  # a fail's class is read from its last `window` states [steps]
    theta1_range: tuple[float, float]  # out below or above it [rad]
    theta2_min: float  # out below it [rad]
    on_stop: float  # theta2 at or above it lies on the elbow stop [rad]
    fold_share: float  # share of the window's states on the stop that makes a fail folded
    flip_torque: float  # a sign flip counts when |torque| exceeds this before and after it [N m]
    chatter_share: float  # share of the window's steps with a flip that makes a fail chatter
    hover_share: float  # share of the window's states in the goal square that makes a fail hover
    rest_speed: float  # mean hand speed over the window below it: at rest [m/s]
    half_width: np.ndarray  # (N,) goal square's half side per network [m]
    near: np.ndarray  # (N,) at rest within this L-inf distance of the target: near [m]


class Labelled(NamedTuple):
    """The movements' labels (leading axes (N, C, P) as the episodes', or a cell's (n, P))."""

    label: np.ndarray  # int8 index into LABELS
    steps: np.ndarray  # int32 steps at which each movement ended: an out's time to go out, n_steps for a fail
    in_goal: np.ndarray  # bool: a fail whose hand stayed in the goal square (`in_goal`), whatever its class


def thresholds(cfg: Config, cell_size: np.ndarray) -> Thresholds:
    """The labels' thresholds from the config, with each network's sensor cell size setting its goal square.

    Args:
      cfg: model config (cfg.eval.anatomy_*, the joint limits, the goal's half width in cells).
      cell_size: (N,) each network's visual cell side [m].
    """
    e, cell = cfg.eval, np.asarray(cell_size, dtype=np.float64)
    steps = round(e.anatomy_window / cfg.arm.dt)
    return Thresholds(
        window=min(max(steps, 2), round(e.max_time / cfg.arm.dt)),  # two states at least: one step to flip
        theta1_range=tuple(cfg.arm.theta1_range),
        theta2_min=cfg.arm.theta2_min,
        on_stop=cfg.arm.theta2_stop - math.radians(e.anatomy_fold_margin_deg),
        fold_share=e.anatomy_fold_share,
        flip_torque=e.anatomy_flip_torque,
        chatter_share=e.anatomy_chatter_share,
        hover_share=e.anatomy_hover_share,
        rest_speed=e.anatomy_rest_speed,
        half_width=cfg.task.goal_half_width_cells * cell,
        near=e.anatomy_near_cells * cell,
    )


def out_limit(last: np.ndarray, th: Thresholds) -> np.ndarray:
    """Index into OUT_LIMITS of the limit that an out's last state crossed, the first in their order.

    Args:
      last: (..., 4) arm state [rad, rad/s] at the step the movement went out.
      th: thresholds.
    """
    lo, hi = th.theta1_range
    return np.where(last[..., 0] < lo, 0, np.where(last[..., 0] > hi, 1, 2))


def fail_class(arm, tau, hand, speed, target, half_width, near, th: Thresholds) -> np.ndarray:
    """Index into FAIL_CLASSES of each movement, read from its window (`th.window` last states), as a fail.

    Args:
      arm: (..., W, 4) arm states of the window [rad, rad/s].
      tau: (..., W, 2) torques applied one step before each of them [N m].
      hand: (..., W, 2) hand positions [m].
      speed: (..., W) hand speeds [m/s].
      target: (..., 2) target positions [m].
      half_width: (...) goal square's half side [m], broadcast against the leading axes.
      near: (...) the L-inf distance to the target within which a hand at rest is near [m], broadcast likewise.
      th: the other thresholds.
    """
    folded = np.mean(arm[..., 1] >= th.on_stop, axis=-1) >= th.fold_share
    big = np.abs(tau) > th.flip_torque
    flips = (tau[..., 1:, :] * tau[..., :-1, :] < 0) & big[..., 1:, :] & big[..., :-1, :]
    chatter = np.mean(np.any(flips, axis=-1), axis=-1) >= th.chatter_share
    hover = in_goal(hand, target, half_width, th)
    rest = np.mean(speed, axis=-1) < th.rest_speed
    close = np.max(np.abs(hand[..., -1, :] - target), axis=-1) <= near
    order = [folded, chatter, hover, rest & close, rest]  # swinging where none holds
    return np.select(order, np.arange(len(order)), default=len(order))


def in_goal(hand: np.ndarray, target: np.ndarray, half_width, th: Thresholds) -> np.ndarray:
    """True where the hand lies inside the goal square in at least th.hover_share of a window's states.

    Args:
      hand: (..., W, 2) hand positions [m].
      target: (..., 2) target positions [m].
      half_width: (...) goal square's half side [m], broadcast against the leading axes.
      th: thresholds.
    """
    off = np.abs(hand - target[..., None, :])
    return np.mean(np.all(off < np.asarray(half_width)[..., None, None], axis=-1), axis=-1) >= th.hover_share


def label_movements(episode, trajectory, targets: np.ndarray, th: Thresholds) -> Labelled:
    """Every movement's label, the step at which it ended and, for a fail, whether its hand stayed in the goal square.

    Args:
      episode: `episodes.Episode` of the lattice movements, NumPy, leading axes (N, C, P).
      trajectory: their `episodes.Trajectory`, NumPy, leading axes (N, C, P).
      targets: (P, 2) the movements' targets [m].
      th: thresholds; th.half_width and th.near per network (N,).

    Returns:
      `Labelled`, leading axes (N, C, P).
    """
    outcome, steps = np.asarray(episode.outcome), np.asarray(episode.steps)
    labels, goal = np.zeros(outcome.shape, dtype=np.int8), np.zeros(outcome.shape, dtype=bool)
    for i in range(outcome.shape[0]):  # one network at a time: its windows are a few MB, all of them a few GB
        state = np.asarray(trajectory.arm[i])
        last = np.take_along_axis(state, steps[i][..., None, None], axis=-2)[..., 0, :]
        w = slice(-th.window, None)
        hand, target = np.asarray(episode.hand[i])[..., w, :], np.broadcast_to(targets, (*outcome.shape[1:], 2))
        tau, speed = np.asarray(trajectory.prev_tau[i])[..., w, :], np.asarray(episode.speed[i])[..., w]
        kind = fail_class(state[..., w, :], tau, hand, speed, target, th.half_width[i], th.near[i], th)
        labels[i] = np.select(
            [outcome[i] == SUCCESS, outcome[i] == OUT, outcome[i] == FAIL],
            [0, 1 + out_limit(last, th), 1 + len(OUT_LIMITS) + kind],
        )
        goal[i] = (outcome[i] == FAIL) & in_goal(hand, target, th.half_width[i], th)
    return Labelled(labels, steps.astype(np.int32), goal)


def per_network(m: Labelled, learners: list[tuple[str, int]], recipe_of: list[int], cfg: Config) -> list[dict]:
    """Each network's count of every label in every test column, and of its fails in the goal square.

    Args:
      m: the labels (`label_movements`), tests in `frames.test_columns` order.
      learners: (learning condition, seed) per network.
      recipe_of: (N,) recipe index per network.
      cfg: model config.
    """
    rows = []
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(frames.test_columns(cfg)):
            counts = np.bincount(m.label[i, j], minlength=len(LABELS))
            row = {"learner": i, "learning": learning, "seed": seed, "recipe": recipe_of[i], "test": test}
            counted = {name: int(n) for name, n in zip(LABELS, counts, strict=True)}
            rows.append({**row, **counted, "fails_in_goal": int(m.in_goal[i, j].sum())})
    return rows


def _share(part: int, whole: int) -> float | None:
    return part / whole if whole else None


def cell(m: Labelled, learning: str, test: str, dt: float, level: float) -> dict:
    """One cell's anatomy from its networks' movements.

    Args:
      m: the labels of the cell's n networks' P movements each, (n, P) arrays.
      learning: the learning condition's name in the view.
      test: the test condition's name in the view.
      dt: step length [s].
      level: coverage of the intervals over networks.

    Returns:
      {"learning", "test", "networks", "movements", "counts" (summed over networks), "shares" ({label: interval of
      the fraction of a network's movements}), "of_outs" and "of_fails" ({label: fraction of the cell's outs or
      fails, pooled}), "fails_in_goal" (the fraction of its fails in the goal square, pooled), "out_time_s" (median
      and quartiles of the outs' times, pooled)}.
    """
    labels, (n, pairs) = m.label, m.label.shape
    counts = np.stack([np.bincount(row, minlength=len(LABELS)) for row in labels]) if n else np.zeros((0, len(LABELS)))
    total = {name: int(counts[:, k].sum()) for k, name in enumerate(LABELS)}
    outs, fails = sum(total[k] for k in OUT_LIMITS), sum(total[k] for k in FAIL_CLASSES)
    times = m.steps[(labels >= 1) & (labels <= len(OUT_LIMITS))] * dt
    # Rounded to the microsecond: steps x dt leaves float noise (0.5800000000000001) in the JSON.
    quartiles = [round(float(q), 6) for q in np.percentile(times, [25, 50, 75])] if times.size else [None] * 3
    return {
        "learning": learning,
        "test": test,
        "networks": n,
        "movements": n * pairs,
        "counts": total,
        "shares": {name: stats.rate_ci(counts[:, k] / pairs, level) for k, name in enumerate(LABELS)},
        "of_outs": {k: _share(total[k], outs) for k in OUT_LIMITS},
        "of_fails": {k: _share(total[k], fails) for k in FAIL_CLASSES},
        "fails_in_goal": _share(int(m.in_goal.sum()), fails),
        "out_time_s": {"median": quartiles[1], "q1": quartiles[0], "q3": quartiles[2], "n": int(times.size)},
    }


def _cell_order(learning_names: list[str], test_names: list[str]) -> list[tuple[str, str]]:
    """The cells of a view: the paper's in Table 2's order, then the others in learning-then-test order."""
    every = [(a, b) for a in learning_names for b in test_names]
    return [key for key in PAPER_TABLE2 if key in every] + [key for key in every if key not in PAPER_TABLE2]


def frame_cells(m: Labelled, learners, recipe_of, frame: str | None, recipes: list[dict], cfg: Config) -> list[dict]:
    """One frame's anatomy: per recipe its hyperparameters and its cells, named as in the frame's view (`frames`).

    Args:
      m: the labels, (N, C, P) arrays, tests in `frames.test_columns` order.
      learners: (learning condition, seed) per network.
      recipe_of: (N,) recipe index per network.
      frame: the condition that stands for the paper's field, None for a run without frames.
      recipes: each recipe's hyperparameters that name it.
      cfg: model config.
    """
    v = frames.view(frame, learners, recipe_of, cfg)
    named = (frames.rename(n, frame, cfg) for n in lattice.learning_conditions(learners, cfg))
    keys = _cell_order([n for n in named if n is not None], [t for t in v.tests if t is not None])
    out = []
    for k, hypers in enumerate(recipes):
        cells = []
        for learning, test in keys:
            nets = [i for i, (name, _) in enumerate(v.learners) if name == learning and v.recipe_of[i] == k]
            if nets:
                j = v.tests.index(test)
                mine = Labelled(*(a[nets, j] for a in m))
                cells.append(cell(mine, learning, test, cfg.arm.dt, cfg.claims.level))
        out.append({"hypers": hypers, "cells": cells})
    return out


def summarize(m: Labelled, learners, recipe_of, recipes, cfg: Config) -> dict:
    """anatomy.json: the thresholds, each network's counts, and per frame (`frames`) and recipe the cells.

    Args:
      m: the labels (`label_movements`), (N, C, P) arrays, tests in `frames.test_columns` order.
      learners: (learning condition, seed) per network.
      recipe_of: (N,) recipe index per network.
      recipes: each recipe's hyperparameters that name it (`lattice.recipe_index`).
      cfg: model config.

    Returns:
      {"labels", "limits_deg" (each out's limit), "thresholds", "level" (the intervals' coverage),
      "pairs_per_network", "per_network", "frame", "recipes", "frames"}: the first frame's recipes at the top, the
      others' under "frames" as in claims.json.
    """
    judged = {f: frame_cells(m, learners, recipe_of, f, recipes, cfg) for f in frames.frame_list(cfg)}
    first, *others = judged
    e = cfg.eval
    return {
        "labels": list(LABELS),
        "limits_deg": dict(
            zip(OUT_LIMITS, map(math.degrees, (*cfg.arm.theta1_range, cfg.arm.theta2_min)), strict=True)
        ),
        "thresholds": {name: getattr(e, name) for name in vars(e) if name.startswith("anatomy_")},
        "level": cfg.claims.level,
        "pairs_per_network": int(m.label.shape[-1]),
        "per_network": per_network(m, learners, recipe_of, cfg),
        "frame": first,
        "recipes": judged[first],
        "frames": {f: {"recipes": judged[f]} for f in others},
    }


def by_frame(anatomy: dict) -> dict:
    """{frame: its recipes' anatomy} of an anatomy.json record (`summarize`)."""
    return {anatomy["frame"]: anatomy["recipes"], **{f: r["recipes"] for f, r in anatomy["frames"].items()}}
