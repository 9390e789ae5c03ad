"""Figures: each panel shows what its title claims, built from synthetic movements with known content."""

from __future__ import annotations

import io

import matplotlib.image
import numpy as np
from PIL import Image

from reach_jax import evaluate
from reach_jax.config import Config
from reach_jax.evaluate import figures, paper_figures

CFG = Config()


def corner_episodes():
    starts, targets, corner = paper_figures.corner_pairs(CFG)
    return evaluate.minimum_jerk_episodes(starts, targets, CFG), starts, targets, corner


def path_lines(ax):
    return [line for line in ax.get_lines() if line.get_marker() not in (None, "None", "")]


def test_fig4_has_six_labelled_panels_with_paths_field_and_goal_squares(tmp_path):
    ep, starts, targets, corner = corner_episodes()
    drawn = {letter: ep for letter, _, _ in paper_figures.FIG4_PANELS if letter != "f"}
    fig = paper_figures.fig4(drawn, starts, targets, corner, CFG)
    axes = fig.axes
    assert len(axes) == 6
    for ax, (letter, learning, test) in zip(axes, paper_figures.FIG4_PANELS, strict=True):
        title = ax.get_title()
        assert f"({letter})" in title and f"learning: {learning}" in title and f"test: {test}" in title
        # 4 goal squares around the corner targets and the field outline.
        assert len(ax.patches) == 5
        # The 5 x 5 cell grid: 6 vertical and 6 horizontal lines.
        grid = [line for line in ax.get_lines() if line not in path_lines(ax)]
        assert len(grid) == 2 * (CFG.sensor.n_cells + 1)
    for ax in axes[:5]:
        lines = path_lines(ax)
        assert len(lines) == 12
        ends = sorted(tuple(np.round(line.get_xydata()[0], 6)) for line in lines)
        assert ends == sorted(tuple(np.round(s, 6)) for s in starts)
        assert "12-0-0" in ax.get_title()
    assert path_lines(axes[5]) == []
    assert any("no random network" in t.get_text() for t in axes[5].texts)
    fig.savefig(tmp_path / "fig4.png")
    assert matplotlib.image.imread(tmp_path / "fig4.png").shape[2] in (3, 4)


def test_fig5_plots_speed_over_time_for_panels_a_and_d():
    ep, _, _, corner = corner_episodes()
    fig = paper_figures.fig5({"a": ep, "d": ep}, corner, CFG)
    axes = fig.axes
    assert len(axes) == 2
    assert "(a)" in axes[0].get_title() and "(d)" in axes[1].get_title()
    for ax in axes:
        lines = path_lines(ax)
        assert len(lines) == 12
        t, v = lines[0].get_xydata().T
        np.testing.assert_allclose(np.diff(t), CFG.arm.dt)
        np.testing.assert_allclose(v, ep.speed[0, : ep.steps[0] + 1])
    assert "time" in axes[0].get_xlabel() and "speed" in axes[0].get_ylabel()


def test_learning_curves_draw_one_line_per_learner_in_every_panel():
    rows = [
        {
            "learner": i,
            "condition": cond,
            "seed": 0,
            "trials": 100 * (c + 1),
            "success_rate": 0.1 * c + i,
            "out_rate": 0.0,
            "mean_trial_s": 1.0 + c,
            "distance_m": 0.064 + 0.001 * c,
            "exploration": 0.2 - 0.05 * c,
            "clean_margin": 0.2 * c - 0.5,
            "failure": 1.0 - 0.1 * c,
            "saturated_rate": 0.01 * c,
            "start_value": -0.1 + 0.05 * c,
            **{f"w{k}_norm": 10.0 / k + c for k in (1, 2, 3)},
        }
        for c in range(3)
        for i, cond in enumerate(("none", "viscous"))
    ]
    fig = figures.learning_curves(rows, CFG)
    assert [ax.get_ylabel() for ax in fig.axes] == [label for _, label in figures.LEARNING_CURVES]
    for ax, (key, _) in zip(fig.axes, figures.LEARNING_CURVES, strict=True):
        lines = path_lines(ax)
        assert len(lines) == 2
        np.testing.assert_allclose(lines[1].get_xdata(), [100, 200, 300])
        np.testing.assert_allclose(lines[1].get_ydata(), [r[key] for r in rows if r["learner"] == 1])
    assert fig.axes[-1].get_xlabel() == "trials per learner"


def test_learning_curves_without_metrics_say_so():
    fig = figures.learning_curves([], CFG)
    assert any("no finished chunk" in t.get_text() for t in fig.axes[0].texts)


def test_the_learning_curves_legend_names_each_label_once_and_only_conditions_in_a_large_batch():
    def rows(n_learners):
        return [
            {
                "learner": i,
                "condition": ("none", "viscous")[i % 2],
                "seed": i // 2 % 2,
                "trials": 100,
                "success_rate": 1.0,
            }
            for i in range(n_learners)
        ]

    small = figures.learning_curves(rows(6), CFG).legends[0]  # seeds 0 and 1 repeat, as in a sweep of 3 points
    assert sorted(t.get_text() for t in small.get_texts()) == [
        f"{c} seed {s}" for c in ("none", "viscous") for s in (0, 1)
    ]
    large = figures.learning_curves(rows(figures.MAX_LEGEND_LEARNERS + 2), CFG).legends[0]
    assert [t.get_text() for t in large.get_texts()] == ["none", "viscous"]


def test_a_figure_is_written_as_a_palette_png_that_looks_like_its_full_colour_render():
    # Fig. 4: coloured paths, gray goal squares and anti-aliased text, the kind of image every PNG here is.
    ep, starts, targets, corner = corner_episodes()
    fig = paper_figures.fig4({"a": ep, "b": ep}, starts, targets, corner, CFG)
    full = io.BytesIO()
    fig.savefig(full, format="png", dpi=figures.FIGURE_DPI)
    want = np.asarray(Image.open(full).convert("RGB"), dtype=np.int16)
    png = figures.png_bytes(fig)
    with Image.open(io.BytesIO(png)) as image:
        assert image.mode == "P" and len(image.getcolors(maxcolors=256)) <= figures.FIGURE_COLORS
        got = np.asarray(image.convert("RGB"), dtype=np.int16)
    assert got.shape == want.shape
    error = np.abs(got - want)
    # The palette keeps the picture: most pixels exact, the blends within a few levels of 255.
    assert np.mean(error) < 1.0 and np.mean(np.max(error, axis=-1) > 24) < 0.01, (error.mean(), error.max())
    assert len(png) < len(full.getvalue()) / 2
