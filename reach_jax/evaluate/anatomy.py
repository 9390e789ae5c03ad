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
A cell's shares are each network's fraction of its movements with the label, as a mean over networks with a
t-interval on the logit scale (`stats.rate_ci`), and the pooled composition of the cell's outs and fails.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from matplotlib.figure import Figure

from reach_jax.config import Config
from reach_jax.config.paper import PAPER_TABLE2
from reach_jax.env.environment import FAIL, OUT, SUCCESS
from reach_jax.evaluate import frames, lattice, stats
from reach_jax.evaluate.report import interval_text

OUT_LIMITS = ("theta1_low", "theta1_high", "theta2_low")  # theta1 < 0, theta1 > 90 deg, theta2 < 0 (the defaults)
FAIL_CLASSES = ("folded", "chatter", "hover", "rest_near", "rest_far", "swinging")  # in order of precedence
LABELS = ("success", *OUT_LIMITS, *FAIL_CLASSES)  # a movement's label is its index here

# How the Markdown, the figure and the claims report name the labels.
WORDS = {
    "success": "success",
    "theta1_low": "θ1 < min",
    "theta1_high": "θ1 > max",
    "theta2_low": "θ2 < min",
    "folded": "folded",
    "chatter": "chatter",
    "hover": "hover",
    "rest_near": "rest near",
    "rest_far": "rest far",
    "swinging": "swinging",
}
COLORS = {
    "success": "#4daf4a",
    "theta1_low": "#fcae91",
    "theta1_high": "#fb6a4a",
    "theta2_low": "#cb181d",
    "folded": "#54278f",
    "chatter": "#ff7f00",
    "hover": "#ffd92f",
    "rest_near": "#9ecae1",
    "rest_far": "#3182bd",
    "swinging": "#969696",
}


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
    off = np.abs(hand - target[..., None, :])
    inside = np.all(off < np.asarray(half_width)[..., None, None], axis=-1)
    hover = np.mean(inside, axis=-1) >= th.hover_share
    rest = np.mean(speed, axis=-1) < th.rest_speed
    close = np.max(off[..., -1, :], axis=-1) <= near
    order = [folded, chatter, hover, rest & close, rest]  # swinging where none holds
    return np.select(order, np.arange(len(order)), default=len(order))


def label_movements(episode, trajectory, targets: np.ndarray, th: Thresholds) -> tuple[np.ndarray, np.ndarray]:
    """Every movement's label (index into LABELS) and the step at which it ended (an out's time to go out).

    Args:
      episode: `episodes.Episode` of the lattice movements, NumPy, leading axes (N, C, P).
      trajectory: their `episodes.Trajectory`, NumPy, leading axes (N, C, P).
      targets: (P, 2) the movements' targets [m].
      th: thresholds; th.half_width and th.near per network (N,).

    Returns:
      (labels (N, C, P) int8, steps (N, C, P) int32 at which each ended: n_steps for a fail).
    """
    outcome, steps = np.asarray(episode.outcome), np.asarray(episode.steps)
    labels = np.zeros(outcome.shape, dtype=np.int8)
    for i in range(outcome.shape[0]):  # one network at a time: its windows are a few MB, all of them a few GB
        state = np.asarray(trajectory.arm[i])
        last = np.take_along_axis(state, steps[i][..., None, None], axis=-2)[..., 0, :]
        w = slice(-th.window, None)
        kind = fail_class(
            state[..., w, :],
            np.asarray(trajectory.prev_tau[i])[..., w, :],
            np.asarray(episode.hand[i])[..., w, :],
            np.asarray(episode.speed[i])[..., w],
            np.broadcast_to(targets, (*outcome.shape[1:], 2)),
            th.half_width[i],
            th.near[i],
            th,
        )
        labels[i] = np.select(
            [outcome[i] == SUCCESS, outcome[i] == OUT, outcome[i] == FAIL],
            [0, 1 + out_limit(last, th), 1 + len(OUT_LIMITS) + kind],
        )
    return labels, steps.astype(np.int32)


def per_network(labels: np.ndarray, learners: list[tuple[str, int]], recipe_of: list[int], cfg: Config) -> list[dict]:
    """Each network's count of every label in every test column.

    Args:
      labels: (N, C, P) labels (`label_movements`), tests in `frames.test_columns` order.
      learners: (learning condition, seed) per network.
      recipe_of: (N,) recipe index per network.
      cfg: model config.
    """
    rows = []
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(frames.test_columns(cfg)):
            counts = np.bincount(labels[i, j], minlength=len(LABELS))
            row = {"learner": i, "learning": learning, "seed": seed, "recipe": recipe_of[i], "test": test}
            rows.append({**row, **{name: int(n) for name, n in zip(LABELS, counts, strict=True)}})
    return rows


def _share(part: int, whole: int) -> float | None:
    return part / whole if whole else None


def cell(labels: np.ndarray, steps: np.ndarray, learning: str, test: str, dt: float, level: float) -> dict:
    """One cell's anatomy from its networks' movements.

    Args:
      labels: (n, P) labels of the cell's n networks.
      steps: (n, P) steps at which each movement ended.
      learning: the learning condition's name in the view.
      test: the test condition's name in the view.
      dt: step length [s].
      level: coverage of the intervals over networks.

    Returns:
      {"learning", "test", "networks", "movements", "counts" (summed over networks), "shares" ({label: interval of
      the fraction of a network's movements}), "of_outs" and "of_fails" ({label: fraction of the cell's outs or
      fails, pooled}), "out_time_s" (median and quartiles of the outs' times, pooled)}.
    """
    n, pairs = labels.shape
    counts = np.stack([np.bincount(row, minlength=len(LABELS)) for row in labels]) if n else np.zeros((0, len(LABELS)))
    total = {name: int(counts[:, k].sum()) for k, name in enumerate(LABELS)}
    outs, fails = sum(total[k] for k in OUT_LIMITS), sum(total[k] for k in FAIL_CLASSES)
    times = steps[(labels >= 1) & (labels <= len(OUT_LIMITS))] * dt
    quartiles = [float(q) for q in np.percentile(times, [25, 50, 75])] if times.size else [None] * 3
    return {
        "learning": learning,
        "test": test,
        "networks": n,
        "movements": n * pairs,
        "counts": total,
        "shares": {name: stats.rate_ci(counts[:, k] / pairs, level) for k, name in enumerate(LABELS)},
        "of_outs": {k: _share(total[k], outs) for k in OUT_LIMITS},
        "of_fails": {k: _share(total[k], fails) for k in FAIL_CLASSES},
        "out_time_s": {"median": quartiles[1], "q1": quartiles[0], "q3": quartiles[2], "n": int(times.size)},
    }


def _cell_order(learning_names: list[str], test_names: list[str]) -> list[tuple[str, str]]:
    """The cells of a view: the paper's in Table 2's order, then the others in learning-then-test order."""
    every = [(a, b) for a in learning_names for b in test_names]
    return [key for key in PAPER_TABLE2 if key in every] + [key for key in every if key not in PAPER_TABLE2]


def frame_cells(labels, steps, learners, recipe_of, frame: str | None, recipes: list[dict], cfg: Config) -> list[dict]:
    """One frame's anatomy: per recipe its hyperparameters and its cells, named as in the frame's view (`frames`).

    Args:
      labels: (N, C, P) labels, tests in `frames.test_columns` order.
      steps: (N, C, P) steps at which each movement ended.
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
                cells.append(cell(labels[nets, j], steps[nets, j], learning, test, cfg.arm.dt, cfg.claims.level))
        out.append({"hypers": hypers, "cells": cells})
    return out


def summarize(labels, steps, learners, recipe_of, recipes, cfg: Config) -> dict:
    """anatomy.json: the thresholds, each network's counts, and per frame (`frames`) and recipe the cells.

    Args:
      labels: (N, C, P) labels (`label_movements`), tests in `frames.test_columns` order.
      steps: (N, C, P) steps at which each movement ended.
      learners: (learning condition, seed) per network.
      recipe_of: (N,) recipe index per network.
      recipes: each recipe's hyperparameters that name it (`lattice.recipe_index`).
      cfg: model config.

    Returns:
      {"labels", "thresholds", "pairs_per_network", "per_network", "frame", "recipes", "frames"}: the first frame's
      recipes at the top, the others' under "frames" as in claims.json.
    """
    judged = {f: frame_cells(labels, steps, learners, recipe_of, f, recipes, cfg) for f in frames.frame_list(cfg)}
    first, *others = judged
    e = cfg.eval
    return {
        "labels": list(LABELS),
        "thresholds": {name: getattr(e, name) for name in vars(e) if name.startswith("anatomy_")},
        "pairs_per_network": int(labels.shape[-1]),
        "per_network": per_network(labels, learners, recipe_of, cfg),
        "frame": first,
        "recipes": judged[first],
        "frames": {f: {"recipes": judged[f]} for f in others},
    }


def by_frame(anatomy: dict) -> dict:
    """{frame: its recipes' anatomy} of an anatomy.json record (`summarize`)."""
    return {anatomy["frame"]: anatomy["recipes"], **{f: r["recipes"] for f, r in anatomy["frames"].items()}}


def _composition(shares: dict, names: tuple[str, ...]) -> str:
    """ "73% folded, 12% swinging" from pooled shares, largest first, those under half a percent left out."""
    seen = sorted(((shares[k], k) for k in names if shares[k] is not None and shares[k] >= 0.005), reverse=True)
    return ", ".join(f"{s:.0%} {WORDS[k]}" for s, k in seen)


def _headline_cell(cells: list[dict]) -> dict | None:
    """The cell a claims report's line is about: the unexpected field (none → viscous), else the most fails."""
    for c in cells:
        if (c["learning"], c["test"]) == ("none", frames.PAPER_FIELD):
            return c
    return max(cells, key=lambda c: sum(c["counts"][k] for k in FAIL_CLASSES), default=None)


def headline(cells: list[dict], frame: str | None) -> str:
    """One line for the claims report: the unexpected field's fails by class and outs by limit."""
    c = _headline_cell(cells)
    if c is None:
        return "Failure anatomy: no cell."
    name = f"{frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)}"
    fails, outs = (sum(c["counts"][k] for k in group) / c["movements"] for group in (FAIL_CLASSES, OUT_LIMITS))
    text = f"**Failure anatomy** ([anatomy.md](anatomy.md)), {name}: {fails:.1%} of movements fail"
    if fails:
        text += f" ({_composition(c['of_fails'], FAIL_CLASSES)})"
    text += f", {outs:.1%} go out"
    if outs:
        text += f" ({_composition(c['of_outs'], OUT_LIMITS)}; median {c['out_time_s']['median']:.2f} s)"
    return text + "."


def _row(c: dict, frame: str | None, names: tuple[str, ...], few: int, of: str | None) -> str:
    """A Markdown row: each label's share of movements with its interval, and its share of the group (`of`)."""
    texts = []
    for k in names:
        text = interval_text(c["shares"][k], few, 100.0)
        if of is not None and c[of].get(k) is not None:
            text += f" ({c[of][k]:.0%})"
        texts.append(text)
    head = f"| {frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)} | {c['networks']} | "
    return head + " | ".join(texts)


def markdown(anatomy: dict, source: str, few: int) -> str:
    """anatomy.json as Markdown: per frame and recipe, a table of the outs by limit and one of the fails by class.

    Args:
      anatomy: `summarize` results.
      source: the run and chunk named in the title.
      few: below this many networks a cell shows each network's value instead of an interval.
    """
    t = anatomy["thresholds"]
    lines = [
        f"# Failure anatomy — {source}",
        "",
        "Each cell: the share of a network's movements, % (mean over networks with its 95% t-interval on the logit"
        " scale), and in brackets the share of the cell's outs or fails, pooled over its networks. An out is named by"
        " the joint limit it crossed; a fail by the first class that fits its last"
        f" {t['anatomy_window']:g} s: folded (the elbow within {t['anatomy_fold_margin_deg']:g}° of its stop in"
        f" {t['anatomy_fold_share']:.0%} of the states or more), chatter (a joint's torque changes sign, above"
        f" {t['anatomy_flip_torque']:g} N m, in {t['anatomy_chatter_share']:.0%} of the steps or more), hover (the"
        f" hand inside the goal square in {t['anatomy_hover_share']:.0%} of the states or more, too fast to stop"
        f" there), rest near or far (mean hand speed below {t['anatomy_rest_speed']:g} m/s, ending within"
        f" {t['anatomy_near_cells']:g} cells of the target or not), swinging (the rest: still moving)."
        " docs/claims.md describes the classes.",
    ]
    for frame, recipes in by_frame(anatomy).items():
        for k, recipe in enumerate(recipes):
            name = ", ".join(f"{key} {v:g}" for key, v in recipe["hypers"].items())
            lines += [
                "",
                f"## {frames.heading(frame)}Recipe {k}: {name}",
                "",
                "| learning → test | networks | success % | "
                + " | ".join(f"out, {WORDS[k]} %" for k in OUT_LIMITS)
                + " | outs' median time [s] |",
                "|---|---|---|" + "---|" * len(OUT_LIMITS) + "---|",
            ]
            for c in recipe["cells"]:
                med = c["out_time_s"]["median"]
                timed = "–" if med is None else f"{med:.2f} ({c['out_time_s']['q1']:.2f}–{c['out_time_s']['q3']:.2f})"
                lines.append(_row(c, frame, ("success", *OUT_LIMITS), few, "of_outs") + f" | {timed} |")
            lines += [
                "",
                "| learning → test | networks | " + " | ".join(f"fail, {WORDS[k]} %" for k in FAIL_CLASSES) + " |",
                "|---|---|" + "---|" * len(FAIL_CLASSES),
                *(_row(c, frame, FAIL_CLASSES, few, "of_fails") + " |" for c in recipe["cells"]),
            ]
    return "\n".join(lines) + "\n"


def figure(anatomy: dict) -> Figure:
    """Stacked bars, one per cell and a panel per frame: the mean share of each label, success to swinging.

    Args:
      anatomy: `summarize` results.
    """
    panels = by_frame(anatomy)
    bars = {f: [(k, c) for k, recipe in enumerate(recipes) for c in recipe["cells"]] for f, recipes in panels.items()}
    rows = sum(len(b) for b in bars.values())
    fig = Figure(figsize=(10, 1.2 + 0.32 * rows + 0.9 * len(panels)))
    heights = [max(len(b), 1) for b in bars.values()]
    axes = fig.subplots(len(panels), 1, squeeze=False, gridspec_kw={"height_ratios": heights})[:, 0]
    recipes_shown = max(len(r) for r in panels.values()) > 1
    for ax, (frame, cells) in zip(axes, bars.items(), strict=True):
        names = [
            (f"r{k}: " if recipes_shown else "")
            + f"{frames.shown(c['learning'], frame)} → {frames.shown(c['test'], frame)}"
            for k, c in cells
        ]
        left = np.zeros(len(cells))
        for label in LABELS:
            width = np.array([100.0 * (c["shares"][label]["mean"] or 0.0) for _, c in cells])
            ax.barh(np.arange(len(cells)), width, left=left, color=COLORS[label], label=WORDS[label], height=0.75)
            for y, (x, w) in enumerate(zip(left, width, strict=True)):
                if w >= 6.0:  # a share too thin for its number is left to the legend
                    ax.text(x + w / 2, y, f"{w:.0f}", ha="center", va="center", fontsize=7)
            left += width
        ax.set_yticks(np.arange(len(cells)), names, fontsize=8)
        ax.invert_yaxis()
        ax.set_xlim(0, 100)
        ax.set_title(f"{frames.heading(frame).rstrip(', ') or 'Tests'}: where the movements end", fontsize=9)
    axes[-1].set_xlabel("share of a network's movements, % (mean over networks)")
    handles, words = axes[0].get_legend_handles_labels()
    fig.legend(handles, words, loc="lower center", ncol=len(LABELS), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return fig
