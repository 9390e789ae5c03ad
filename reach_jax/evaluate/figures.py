"""Figures of a run's training and measures: learning curves, impedance ellipses, adaptation curves (matplotlib).

Units: trials, seconds, stiffness [N/m] and damping [N s/m] in hand space.
Every function returns a matplotlib Figure (not registered with pyplot, so nothing to close); the caller saves it.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from reach_jax.config import Config

# Colours of the conditions, in the order of cfg.conditions (the paper's four first), then round again.
PALETTE = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
SEED_STYLE = ("-", "--", ":", "-.")
MAX_LEGEND_LEARNERS = 16  # past this many learners the learning curves' legend names the conditions only
LEGEND_COLUMNS = 4
FIGURE_DPI = 110  # the PNGs' resolution
# A PNG's palette: a plot's few colours and their anti-aliased blends fit in 256, at a third of an RGBA PNG's bytes
# (committed evaluations are most of what a run adds to the repository).
FIGURE_COLORS = 256


def png_bytes(fig: Figure, dpi: int = FIGURE_DPI, colors: int = FIGURE_COLORS) -> bytes:
    """A figure as an 8-bit palette PNG: rendered opaque at `dpi`, then reduced to an adaptive `colors`-colour palette.

    Args:
      fig: a figure on an opaque background (every figure here: matplotlib's white).
      dpi: dots per inch.
      colors: palette size, at most 256.
    """
    rendered = io.BytesIO()
    fig.savefig(rendered, format="png", dpi=dpi)
    with Image.open(rendered) as image:
        palette = image.convert("RGB").quantize(colors=colors, method=Image.Quantize.MEDIANCUT)
    out = io.BytesIO()
    palette.save(out, format="PNG", optimize=True)
    return out.getvalue()


def condition_color(name: str, cfg: Config) -> str:
    """The colour of a condition in every figure."""
    names = [c.name for c in cfg.conditions]
    return PALETTE[names.index(name) % len(PALETTE)] if name in names else "k"


LEARNING_CURVES = (
    ("success_rate", "success rate"),
    ("out_rate", "out rate"),
    ("mean_trial_s", "mean trial length [s]"),
    ("distance_m", "curriculum distance [m]"),
    ("exploration", "exploration bound"),
    ("clean_margin", "clean margin"),  # the mechanism's measures (model §5)
    ("failure", "failure share (drift gate)"),
    ("saturated_rate", "saturated actor outputs"),
    ("start_value", "critic at trial start"),
    ("w1_norm", "layer 1 weight norm"),
    ("w2_norm", "layer 2 weight norm"),
    ("w3_norm", "layer 3 weight norm"),
)


def learning_curves(metrics: list[dict], cfg: Config):
    """Per-chunk metrics against trials, one line per learner, under a legend of each learner's condition and seed
    (of the conditions alone past MAX_LEGEND_LEARNERS learners).

    Args:
      metrics: rows of metrics.jsonl (keys learner, condition, seed, trials and LEARNING_CURVES fields).
      cfg: model config.
    """
    height = 2.2 * len(LEARNING_CURVES)  # [in]
    fig = Figure(figsize=(8, height))
    axes = fig.subplots(len(LEARNING_CURVES), 1, sharex=True)
    learners = sorted({(r["learner"], r["condition"], r["seed"]) for r in metrics})
    by_seed = len(learners) <= MAX_LEGEND_LEARNERS
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
                label=f"{cond} seed {seed}" if by_seed else cond,
            )
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    top = 1.0 - 0.75 / height  # below the title
    if learners:
        # One entry per label (a sweep repeats each seed's label once per recipe), above the panels.
        entries: dict = {}
        handles, names = axes[0].get_legend_handles_labels()
        for handle, name in zip(handles, names, strict=True):
            entries.setdefault(name, handle)
        fig.legend(
            list(entries.values()),
            list(entries),
            loc="upper center",
            bbox_to_anchor=(0.5, top),
            ncol=LEGEND_COLUMNS,
            fontsize=8,
        )
        top -= (0.1 + 0.17 * -(-len(entries) // LEGEND_COLUMNS)) / height
    else:
        axes[0].text(0.5, 0.5, "no finished chunk in metrics.jsonl", transform=axes[0].transAxes, ha="center")
    axes[-1].set_xlabel("trials per learner")
    fig.suptitle(f"Learning curves ({cfg.train.trials:,} trials planned per learner)")
    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    return fig


def _ellipse(matrix: np.ndarray, n: int = 73) -> np.ndarray:
    """(n, 2) image of the unit circle under `matrix` (2, 2): the gain's answer to a unit change in each direction."""
    phi = np.linspace(0.0, 2.0 * np.pi, n)
    return np.stack([np.cos(phi), np.sin(phi)], axis=1) @ np.asarray(matrix).T


def _gain_ellipses(ax, rows: list[dict], key: str, conditions: list[str], cfg: Config) -> None:
    """Per condition, each network's median gain ellipse thin and the element-wise median over its networks thick.

    Args:
      rows: `impedance.summarize`'s per-network rows of one test condition.
      key: the gain, "stiffness_N_per_m" or "damping_Ns_per_m".
      conditions: the learning conditions, in the legend's order.
      cfg: model config.
    """
    for cond in conditions:
        mats = [np.asarray(r[key]["median"]) for r in rows if r["learning"] == cond]
        for m in mats:
            e = _ellipse(m)
            ax.plot(e[:, 0], e[:, 1], color=condition_color(cond, cfg), lw=0.5, alpha=0.5)
        if mats:
            e = _ellipse(np.median(mats, axis=0))
            ax.plot(e[:, 0], e[:, 1], color=condition_color(cond, cfg), lw=2.2, label=cond)


def _damping_references(ax, passive: np.ndarray, axes_info: list[dict]) -> None:
    """The passive arm's damping ellipse, dashed, and the field's axes dotted across the panel's extent so far.

    Args:
      passive: (2, 2) the passive arm's damping [N s/m].
      axes_info: `impedance.summarize`'s "field_axes": name, direction [deg] and eigenvalue [N s/m] of each.
    """
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


def _axis_damping(ax, rows: list[dict], conditions: list[str], unstable: float, test: str, cfg: Config) -> None:
    """Each network's median damping along the field's unstable and stable axes, one column per condition.

    Args:
      rows: `impedance.summarize`'s per-network rows of test condition `test`.
      conditions: the learning conditions, left to right.
      unstable: the field's unstable eigenvalue [N s/m].
      test: the test condition.
      cfg: model config.
    """
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
    ax.axhline(unstable, color="tab:red", lw=0.8, ls=":", label="field's unstable eigenvalue")
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set_xticks(range(len(conditions)), conditions, fontsize=8)
    ax.set_ylabel("learned damping along the axis [N s/m]")
    ax.set_title(f"test: {test} — damping along the field's axes (per network)", fontsize=10)
    ax.legend(fontsize=7)


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
            _gain_ellipses(ax, rows, key, conditions, cfg)
            if col == 1:
                valid = gains["valid"][:, row]
                passive = np.median(gains["passive"][:, row][valid], axis=0) if valid.any() else np.zeros((2, 2))
                _damping_references(ax, passive, axes_info)
            ax.axhline(0, color="0.8", lw=0.5)
            ax.axvline(0, color="0.8", lw=0.5)
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title(f"test: {test} — {label}", fontsize=10)
            ax.set_xlabel(f"x component [{label.split('[')[1]}")
            ax.legend(fontsize=7, loc="upper right")
        _axis_damping(axes[row, 2], rows, conditions, axes_info[0]["eigenvalue_Ns_per_m"], test, cfg)
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
