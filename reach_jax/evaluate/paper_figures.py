"""Fig. 4 hand paths and Fig. 5 speed profiles (section 4.4), with the panels they show, the corner cells their
movements run between and those movements on their own (matplotlib).

Units: positions [m] in the shoulder frame (x right, y forward), speeds [m/s], times [s].
Every function returns a matplotlib Figure (not registered with pyplot, so nothing to close); the caller saves it.
"""

from __future__ import annotations

import jax
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from reach_jax.config import Config
from reach_jax.env import OUTCOME_NAMES, SUCCESS, task
from reach_jax.evaluate import episodes, lattice
from reach_jax.physics import sensor

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


def corner_episodes(params, masks, cfg: Config) -> episodes.Episode:
    """Every network's Fig. 4 movements (`corner_pairs`) under every test condition, without the lattice's 1040.

    Args:
      params: the networks' parameters, leading network axis N (`store.run_dir.load_params`).
      masks: (N, 125) input masks of their learning conditions.
      cfg: the run's config; its test columns (`frames.test_columns`) are the C tests.

    Returns:
      NumPy episodes, leading axes (N, C, 12).
    """
    starts, targets, _ = corner_pairs(cfg)
    policy, fields = episodes.network_policy(cfg), lattice.test_fields(cfg)
    return jax.device_get(episodes.run_episodes(policy, params, masks, fields, starts, targets, cfg)[0])


# Paper's Fig. 4 legend: upper left filled squares, lower left empty squares, upper right x, lower right
# filled circles; keyed by CORNER_NAMES.
CORNER_STYLE = {
    "lower left": dict(marker="s", markerfacecolor="none", color="tab:blue"),
    "lower right": dict(marker="o", color="tab:red"),
    "upper left": dict(marker="s", color="tab:green"),
    "upper right": dict(marker="x", color="tab:purple"),
}


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
