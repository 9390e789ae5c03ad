"""Figures of the evaluation: Fig. 4 hand paths, Fig. 5 speed profiles, learning curves (matplotlib).

Units: positions [m] in the shoulder frame (x right, y forward), speeds [m/s], times [s], trials.
Every function returns a matplotlib Figure (not registered with pyplot, so nothing to close); the caller saves it.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from reach_jax import sensor, task
from reach_jax.config import Config
from reach_jax.outcomes import NAMES as OUTCOME_NAMES
from reach_jax.outcomes import SUCCESS
from reach_jax.panels import CORNER_NAMES, FIG4_PANELS, FIG5_PANELS

# Paper's Fig. 4 legend: upper left filled squares, lower left empty squares, upper right x, lower right
# filled circles; keyed by CORNER_NAMES.
CORNER_STYLE = {
    "lower left": dict(marker="s", markerfacecolor="none", color="tab:blue"),
    "lower right": dict(marker="o", color="tab:red"),
    "upper left": dict(marker="s", color="tab:green"),
    "upper right": dict(marker="x", color="tab:purple"),
}
# Colours of the conditions, in the order of cfg.conditions (the paper's four first), then round again.
PALETTE = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
SEED_STYLE = ("-", "--", ":", "-.")


def condition_color(name: str, cfg: Config) -> str:
    """The colour of a condition in every figure."""
    names = [c.name for c in cfg.conditions]
    return PALETTE[names.index(name) % len(PALETTE)] if name in names else "k"


def _panel_title(letter: str, learning: str, test: str) -> str:
    return f"({letter}) learning: {learning} → test: {test}"


def draw_field(ax, cfg: Config, targets: np.ndarray) -> None:
    """Visual field outline, its cell grid and the light-gray goal squares around `targets` (K, 2) [m]."""
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    for target in np.unique(targets, axis=0):
        half = task.goal_half_width(cfg)
        ax.add_patch(Rectangle(target - half, 2 * half, 2 * half, facecolor="0.85", edgecolor="0.6", lw=0.5, zorder=0))
    edges = np.linspace(0.0, 1.0, cfg.sensor.n_cells + 1)
    for e in edges:
        ax.plot([x0 + e * (x1 - x0)] * 2, [y0, y1], color="0.7", lw=0.5, zorder=1)
        ax.plot([x0, x1], [y0 + e * (y1 - y0)] * 2, color="0.7", lw=0.5, zorder=1)
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor="k", lw=1.0, zorder=1))


def _limits(ax, cfg: Config, paths: list[np.ndarray]) -> None:
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    margin = 1.5 * cfg.sensor.cell_size
    lo, hi = np.array([x0, y0]) - margin, np.array([x1, y1]) + margin
    for p in paths:
        lo, hi = np.minimum(lo, p.min(axis=0)), np.maximum(hi, p.max(axis=0))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")


def fig4(panels: dict, starts: np.ndarray, targets: np.ndarray, start_corner: np.ndarray, cfg: Config):
    """Six hand-path panels (a)-(f) between the corner-cell centres, as in the paper's Fig. 4.

    Args:
      panels: {letter: Episode over the M corner movements} for the panels with a network.
      starts: (M, 2) [m].
      targets: (M, 2) [m].
      start_corner: (M,) index into CORNER_NAMES.
      cfg: model config.
    """
    fig = Figure(figsize=(9, 13))
    axes = fig.subplots(3, 2)
    for ax, (letter, learning, test) in zip(axes.ravel(), FIG4_PANELS, strict=True):
        ax.set_title(_panel_title(letter, learning, test), fontsize=10)
        draw_field(ax, cfg, targets)
        ep = panels.get(letter)
        if ep is None:
            ax.text(0.5, 0.5, f"no {learning} network in this run", transform=ax.transAxes, ha="center")
            _limits(ax, cfg, [])
            continue
        drawn = []
        for i in range(len(starts)):
            path = ep.hand[i, : int(ep.steps[i]) + 1]
            drawn.append(path)
            style = CORNER_STYLE[CORNER_NAMES[start_corner[i]]]
            ax.plot(path[:, 0], path[:, 1], lw=0.8, markersize=2.5, zorder=3, **style)
        counts = [int(np.sum(ep.outcome == k)) for k in range(len(OUTCOME_NAMES))]
        ax.set_title(
            f"{_panel_title(letter, learning, test)}\n{'-'.join(map(str, counts))} success-out-fail", fontsize=10
        )
        _limits(ax, cfg, drawn)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    handles = [Line2D([], [], lw=0.8, **CORNER_STYLE[n]) for n in CORNER_NAMES]
    fig.legend(handles, [f"from {n}" for n in CORNER_NAMES], loc="lower center", ncol=4, fontsize=9)
    fig.suptitle(f"Fig. 4: hand paths (network seed {cfg.eval.figure_seed}); gray: goal squares")
    fig.tight_layout(rect=(0, 0.03, 1, 0.98))
    return fig


def fig5(panels: dict, start_corner: np.ndarray, cfg: Config):
    """Hand tangential speed against time for Fig. 4 panels (a) and (d), as in the paper's Fig. 5.

    Args:
      panels: {letter: Episode over the M corner movements}.
      start_corner: (M,) index into CORNER_NAMES.
      cfg: model config.
    """
    fig = Figure(figsize=(11, 4))
    axes = fig.subplots(1, len(FIG5_PANELS), sharey=True)
    info = {letter: (learning, test) for letter, learning, test in FIG4_PANELS}
    for ax, letter in zip(axes, FIG5_PANELS, strict=True):
        ax.set_title(_panel_title(letter, *info[letter]), fontsize=10)
        ep = panels.get(letter)
        if ep is None:
            ax.text(0.5, 0.5, f"no {info[letter][0]} network in this run", transform=ax.transAxes, ha="center")
        else:
            for i in range(len(start_corner)):
                n = int(ep.steps[i])
                t = np.arange(n + 1) * cfg.arm.dt
                style = CORNER_STYLE[CORNER_NAMES[start_corner[i]]]
                ls = "-" if ep.outcome[i] == SUCCESS else ":"
                ax.plot(t, ep.speed[i, : n + 1], lw=0.8, ls=ls, markersize=2.5, **style)
        ax.axhline(cfg.task.goal_speed, color="0.5", lw=0.6, ls="--")
        ax.set_xlabel("time [s]")
        ax.set_xlim(0, cfg.eval.max_time)
    axes[0].set_ylabel("hand tangential speed [m/s]")
    handles = [Line2D([], [], lw=0.8, **CORNER_STYLE[n]) for n in CORNER_NAMES]
    fig.legend(handles, [f"from {n}" for n in CORNER_NAMES], loc="lower center", ncol=4, fontsize=9)
    fig.suptitle("Fig. 5: hand speed (dashed line: goal speed; dotted curves: not reached)")
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    return fig


LEARNING_CURVES = (
    ("success_rate", "success rate"),
    ("out_rate", "out rate"),
    ("mean_trial_s", "mean trial length [s]"),
    ("distance_m", "curriculum distance [m]"),
    ("exploration", "exploration bound"),
)


def learning_curves(metrics: list[dict], cfg: Config):
    """Per-chunk metrics against trials, one line per learner.

    Args:
      metrics: rows of metrics.jsonl (keys learner, condition, seed, trials and LEARNING_CURVES fields).
      cfg: model config.
    """
    fig = Figure(figsize=(8, 13))
    axes = fig.subplots(len(LEARNING_CURVES), 1, sharex=True)
    learners = sorted({(r["learner"], r["condition"], r["seed"]) for r in metrics})
    for ax, (key, label) in zip(axes, LEARNING_CURVES, strict=True):
        for learner, cond, seed in learners:
            rows = [r for r in metrics if r["learner"] == learner and r.get(key) is not None]
            ax.plot(
                [r["trials"] for r in rows],
                [r[key] for r in rows],
                color=condition_color(cond, cfg),
                ls=SEED_STYLE[seed % len(SEED_STYLE)],
                lw=1.0,
                marker=".",  # a run with a single chunk still shows its one point
                markersize=4,
                label=f"{cond} seed {seed}",
            )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    if learners:
        axes[0].legend(fontsize=8, ncol=2)
    else:
        axes[0].text(0.5, 0.5, "no finished chunk in metrics.jsonl", transform=axes[0].transAxes, ha="center")
    axes[-1].set_xlabel("trials per learner")
    fig.suptitle(f"Learning curves ({cfg.train.trials:,} trials planned per learner)")
    fig.tight_layout()
    return fig


def _ellipse(matrix: np.ndarray, n: int = 73) -> np.ndarray:
    """(n, 2) image of the unit circle under `matrix` (2, 2): the gain's answer to a unit change in each direction."""
    phi = np.linspace(0.0, 2.0 * np.pi, n)
    return np.stack([np.cos(phi), np.sin(phi)], axis=1) @ np.asarray(matrix).T


def impedance(summary: dict, gains: dict, learners, cfg: Config):
    """Learned hand stiffness and damping ellipses per learning condition, and the damping along the field's axes.

    Drawn as Mussa-Ivaldi, Hogan & Bizzi (1985) drew human hand stiffness: each ellipse is the force
    answering a unit hand displacement (stiffness, N/m) or a unit hand velocity (damping, N s/m) in every
    direction, from a network's median gain matrix over its test-movement states. Thin: one network; thick:
    the element-wise median over a condition's networks. Right: each network's median damping along the
    field's unstable and stable axes.

    Args:
      summary: output of `impedance.summarize` (with "recipes" and per-network "recipe").
      gains: output of `impedance.measure`.
      learners: (learning condition, seed index) per network.
      cfg: model config.
    """
    tests = list(dict.fromkeys(r["test"] for r in summary["per_network"]))
    axes_info = summary["field_axes"]
    fig = Figure(figsize=(15, 5 * len(tests)))
    axes = fig.subplots(len(tests), 3, squeeze=False)
    conditions = list(dict.fromkeys(name for name, _ in learners))
    for row, test in enumerate(tests):
        rows = [r for r in summary["per_network"] if r["test"] == test and r["states"] > 0]
        for col, (key, label) in enumerate(
            (("stiffness_N_per_m", "stiffness [N/m]"), ("damping_Ns_per_m", "damping [N s/m]"))
        ):
            ax = axes[row, col]
            for cond in conditions:
                mats = [np.asarray(r[key]["median"]) for r in rows if r["learning"] == cond]
                for m in mats:
                    e = _ellipse(m)
                    ax.plot(e[:, 0], e[:, 1], color=condition_color(cond, cfg), lw=0.5, alpha=0.5)
                if mats:
                    e = _ellipse(np.median(mats, axis=0))
                    ax.plot(e[:, 0], e[:, 1], color=condition_color(cond, cfg), lw=2.2, label=cond)
            if col == 1:
                valid = gains["valid"][:, row]
                passive = np.median(gains["passive"][:, row][valid], axis=0) if valid.any() else np.zeros((2, 2))
                e = _ellipse(passive)
                ax.plot(e[:, 0], e[:, 1], color="0.4", lw=1.5, ls="--", label="passive arm")
                lim = max(np.abs(ax.get_xlim()).max(), np.abs(ax.get_ylim()).max())
                for info, color in zip(axes_info, ("tab:red", "tab:cyan"), strict=True):
                    a = np.radians(info["direction_deg"])
                    ax.plot(
                        [-lim * np.cos(a), lim * np.cos(a)],
                        [-lim * np.sin(a), lim * np.sin(a)],
                        color=color,
                        lw=0.8,
                        ls=":",
                        label=f"field {info['name']} axis ({info['eigenvalue_Ns_per_m']:+.1f})",
                    )
            ax.axhline(0, color="0.8", lw=0.5)
            ax.axvline(0, color="0.8", lw=0.5)
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title(f"test: {test} — {label}", fontsize=10)
            ax.set_xlabel(f"x component [{label.split('[')[1]}")
            ax.legend(fontsize=7, loc="upper right")
        ax = axes[row, 2]
        for k, cond in enumerate(conditions):
            for j, (name, marker) in enumerate((("unstable", "o"), ("stable", "s"))):
                vals = [r[f"damping_{name}"]["median"] for r in rows if r["learning"] == cond]
                x = k + (j - 0.5) * 0.3 + np.linspace(-0.06, 0.06, max(len(vals), 1))[: len(vals)]
                ax.scatter(
                    x,
                    vals,
                    marker=marker,
                    s=18,
                    color=condition_color(cond, cfg),
                    facecolors="none" if name == "stable" else None,
                    label=f"{name} axis" if k == 0 else None,
                )
        ax.axhline(
            axes_info[0]["eigenvalue_Ns_per_m"], color="tab:red", lw=0.8, ls=":", label="field's unstable eigenvalue"
        )
        ax.axhline(0, color="0.6", lw=0.5)
        ax.set_xticks(range(len(conditions)), conditions, fontsize=8)
        ax.set_ylabel("learned damping along the axis [N s/m]")
        ax.set_title(f"test: {test} — damping along the field's axes (per network)", fontsize=10)
        ax.legend(fontsize=7)
    fig.suptitle("Learned hand impedance at the states of each network's own test movements")
    fig.tight_layout()
    return fig


ADAPTATION_PANELS = (
    ("perp_cm", "perpendicular error\nat peak speed [cm]"),
    ("direction_deg", "initial direction\nerror [deg]"),
    ("success", "success rate"),
)


def _mean_curve(ax, group: list[dict], kind: str, key: str, label: str, **style) -> None:
    """Each network's curve thin, and at each bin the mean of the networks that logged a trial there thick."""
    xs = [np.asarray(net["curves"][kind]["trial"]) for net in group]
    ys = [np.asarray(net["curves"][kind][key]) for net in group]
    for x, y in zip(xs, ys, strict=True):
        ax.plot(x, y, lw=0.5, alpha=0.3, **style)
    bins = np.unique(np.concatenate(xs)) if xs else np.array([])
    if len(bins):
        mean = [np.mean(np.concatenate([y[x == b] for x, y in zip(xs, ys, strict=True)])) for b in bins]
        ax.plot(bins, mean, lw=1.8, label=f"{label}, mean of {len(ys)}", **style)


def adaptation(results: dict, cfg: Config):
    """Adaptation curves of each protocol: field-aligned errors against trials, catch trials and control apart.

    Args:
      results: `adaptation.analyse` output.
      cfg: the run's config.
    """
    protocols = results["protocols"]
    rows = len(ADAPTATION_PANELS) * max(len(protocols), 1)
    fig = Figure(figsize=(10, 2.6 * rows + 0.6))
    axes = np.atleast_1d(fig.subplots(rows, 1, sharex=True))
    for n, (name, p) in enumerate(protocols.items()):
        for m, (key, label) in enumerate(ADAPTATION_PANELS):
            ax = axes[n * len(ADAPTATION_PANELS) + m]
            edge = 0
            for b in p["blocks"]:
                ax.axvspan(edge, edge + b["trials"], color=condition_color(b["condition"], cfg), alpha=0.08, lw=0)
                if m == 0:
                    ax.text(edge, 1.01, f" {b['condition']}", transform=ax.get_xaxis_transform(), fontsize=8)
                edge += b["trials"]
            if p["control"]:
                _mean_curve(ax, p["controls"], "normal", key, f"control {p['control']}", color="0.45")
            _mean_curve(ax, p["networks"], "normal", key, name, color="tab:blue")
            _mean_curve(ax, p["networks"], "catch", key, f"{name}: catch trials", color="tab:red")
            if key != "success":
                ax.axhline(0.0, color="k", lw=0.6)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        top = axes[n * len(ADAPTATION_PANELS)]
        top.legend(fontsize=8, loc="upper right")
        top.set_title(
            f"{name}: errors signed + where the {p['field']} field pushes, {p['window']:,}-trial bins", pad=16
        )
    axes[-1].set_xlabel("trial")
    fig.tight_layout()
    return fig
