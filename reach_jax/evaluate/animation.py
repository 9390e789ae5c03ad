"""An animated GIF of a trained arm reaching around the four corner cells, without and with a force field.

`python -m reach_jax.evaluate RUN --animate [PATH]` writes it (default RUN/eval/reaching.gif). One network
of the run (by default the no-field network that succeeds most often without the field) makes the four
movements lower left → lower right → upper right → upper left → lower left, once in each of two test
conditions side by side (default none and the paper's field in the run's main frame), with the 5×5 sensor grid,
the goal squares, the two links and the hand's path so far. The test is the one of Table 2: no learning, no
exploration noise, no drift.

Units: positions [m] in the shoulder frame, time [s].
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import jax
import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from reach_jax.config import Config
from reach_jax.env import task
from reach_jax.env.environment import OUTCOME_NAMES, SUCCESS
from reach_jax.evaluate import episodes, figures, geometry, paper_figures
from reach_jax.evaluate.frames import PAPER_FIELD, frame_list
from reach_jax.evaluate.paper_figures import CORNER_NAMES, corner_centres
from reach_jax.store import run_dir as run_dir_io

GIF_NAME = "reaching.gif"
CYCLE = ("lower left", "lower right", "upper right", "upper left", "lower left")  # the corners visited, in order
HOLD_FRAMES = 6  # frames that show a finished movement before the next starts


def cycle_pairs(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """(starts, targets) of the four movements of CYCLE, each (4, 2) [m]."""
    centres = corner_centres(cfg)
    idx = [CORNER_NAMES.index(name) for name in CYCLE]
    return centres[idx[:-1]], centres[idx[1:]]


def pick_network(run: run_dir_io.Run, condition: str, test: str) -> int:
    """The learner of a learning condition with the most successful cycle movements in a test condition.

    On a tie, the lowest seed index: the movements show the condition's best case, and the caption says which.
    """
    candidates = [i for i, (learned, _) in enumerate(run.learners) if learned == condition]
    if not candidates:
        raise ValueError(f"the run has no learner of condition {condition!r}")
    ep, _ = movements(run, candidates, (test,))
    wins = (ep.outcome[:, 0] == SUCCESS).sum(axis=1)
    return candidates[int(np.argmax(wins))]


def arm_points(theta: np.ndarray, cfg: Config) -> np.ndarray:
    """Shoulder, elbow and hand of arm angles theta (..., 2) [rad]: (..., 3, 2) [m]."""
    l1, l2 = cfg.arm.length
    t1, t12 = theta[..., 0], theta[..., 0] + theta[..., 1]
    elbow = np.stack([l1 * np.cos(t1), l1 * np.sin(t1)], axis=-1)
    hand = elbow + np.stack([l2 * np.cos(t12), l2 * np.sin(t12)], axis=-1)
    return np.stack([np.zeros_like(elbow), elbow, hand], axis=-2)


def movements(run: run_dir_io.Run, networks: list[int], tests: tuple[str, ...]):
    """The cycle's test episodes of some networks: (Episode, Trajectory), leading axes (networks, tests, 4)."""
    cfg = run.cfg
    idx = np.asarray(networks)
    pick = jax.tree.map(lambda a: a[idx], run.batch.states.agent.params)
    mask = np.asarray(run.batch.conds.input_mask)[idx]
    fields = jax.tree.map(lambda *f: np.stack(f), *(task.make_condition(n, cfg).field for n in tests))
    starts, targets = cycle_pairs(cfg)
    ep, traj = episodes.run_episodes(episodes.network_policy(cfg), pick, mask, fields, starts, targets, cfg)
    return jax.tree.map(np.asarray, ep), jax.tree.map(np.asarray, traj)


def frame_table(steps: np.ndarray, stride: int) -> list[tuple[int, int]]:
    """(movement, step) of every frame: each movement up to the longer of its test conditions, then a hold.

    Args:
      steps: (C, M) steps each episode took.
      stride: steps between frames.
    """
    frames = []
    for m in range(steps.shape[1]):
        last = int(steps[:, m].max())
        frames += [(m, k) for k in range(0, last + 1, stride)]
        frames += [(m, last)] * HOLD_FRAMES
    return frames


def _figure(
    learned: str, tests: tuple[str, ...], title: str, targets: np.ndarray, half: float, cfg: Config
) -> tuple[Figure, list[tuple]]:
    """The animation's figure, one panel per test condition, and each panel's (goal, path, links, label) artists.

    Args:
      learned: the network's learning condition.
      tests: the test conditions, one panel each, left to right.
      title: the figure's title.
      targets: (4, 2) the cycle's targets [m].
      half: half the goal square's width [m].
      cfg: the run's config.
    """
    fig = Figure(figsize=(4.2 * len(tests), 4.4))
    axes = fig.subplots(1, len(tests))
    artists = []
    for ax, test in zip(axes, tests, strict=True):
        paper_figures.draw_field(ax, cfg, targets)
        goal = Rectangle((0, 0), 2 * half, 2 * half, facecolor="none", edgecolor="tab:green", lw=1.5, zorder=2)
        ax.add_patch(goal)
        (path,) = ax.plot([], [], color=figures.condition_color(test, cfg), lw=1.2, zorder=3)
        (links,) = ax.plot([], [], "-o", color="0.25", lw=3, ms=4, zorder=4)
        label = ax.text(0.02, 0.02, "", transform=ax.transAxes, fontsize=9)
        ax.set_title(f"learning: {learned} → test: {test}", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlim(-0.3, 0.3)
        ax.set_ylim(-0.05, 0.55)
        ax.set_xticks([])
        ax.set_yticks([])
        artists.append((goal, path, links, label))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig, artists


def _draw_frame(
    i: int,
    frames: list[tuple[int, int]],
    artists: list[tuple],
    ep: episodes.Episode,
    traj: episodes.Trajectory,
    targets: np.ndarray,
    half: float,
    cfg: Config,
) -> list:
    """Frame i of `frame_table`'s frames: each panel's goal, path so far, arm and clock; returns the changed artists.

    Args:
      i: the frame's index.
      frames: `frame_table`'s (movement, step) per frame.
      artists: `_figure`'s artists per panel.
      ep: the cycle's Episode, leading axes (tests, 4).
      traj: its Trajectory, leading axes (tests, 4).
      targets: (4, 2) the cycle's targets [m].
      half: half the goal square's width [m].
      cfg: the run's config.
    """
    m, k = frames[i]
    changed = []
    for c, (goal, path, links, label) in enumerate(artists):
        end = int(ep.steps[c, m])
        j = min(k, end)
        goal.set_xy(targets[m] - half)
        path.set_data(ep.hand[c, m, : j + 1, 0], ep.hand[c, m, : j + 1, 1])
        pts = arm_points(traj.arm[c, m, j, :2], cfg)
        links.set_data(pts[:, 0], pts[:, 1])
        status = OUTCOME_NAMES[int(ep.outcome[c, m])] if k >= end else ""
        label.set_text(f"{j * cfg.arm.dt:.2f} s {status}")
        changed += [goal, path, links, label]
    return changed


def animate(
    run_dir: Path,
    out: Path | None = None,
    network: int | None = None,
    learned: str = "none",
    tests: tuple[str, str] | None = None,
    stride: int = 2,
    dpi: int = 72,
) -> Path:
    """Write the GIF of one network's corner movements and return its path.

    Args:
      run_dir: a run directory written by `reach_jax.train`.
      out: the GIF's path; default RUN_DIR/eval/reaching.gif.
      network: the learner to show; default the learner of condition `learned` that succeeds most often in
        the first test condition (`pick_network`).
      learned: the learning condition to pick a network from.
      tests: the two test conditions, drawn left and right; default none and the run's main frame (`frames.frame_list`).
      stride: arm steps (of cfg.arm.dt) per frame; the GIF plays at real time.
      dpi: resolution of the frames.
    """
    run = run_dir_io.load(run_dir)
    (sensor, _), *more = geometry.groups(run)
    if more:
        raise ValueError(f"the run's learners see {len(more) + 1} visual fields; animate one field's run")
    run = run._replace(cfg=dataclasses.replace(run.cfg, sensor=sensor))
    cfg = run.cfg
    tests = ("none", frame_list(cfg)[0] or PAPER_FIELD) if tests is None else tests
    network = pick_network(run, learned, tests[0]) if network is None else network
    ep, traj = (jax.tree.map(lambda a: a[0], x) for x in movements(run, [network], tests))
    _, targets = cycle_pairs(cfg)
    frames = frame_table(ep.steps, stride)
    learned, seed = run.learners[network]
    wins = (ep.outcome == SUCCESS).sum(axis=1)
    title = f"{Path(run_dir).name}, network seed {seed}: {wins[0]} and {wins[1]} of {len(targets)} reached"
    half = task.goal_half_width(cfg)
    fig, artists = _figure(learned, tests, title, targets, half, cfg)
    draw = functools.partial(
        _draw_frame, frames=frames, artists=artists, ep=ep, traj=traj, targets=targets, half=half, cfg=cfg
    )
    movie = FuncAnimation(fig, draw, frames=len(frames), blit=False)
    out = Path(run_dir) / "eval" / GIF_NAME if out is None else Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    movie.save(out, writer=PillowWriter(fps=round(1.0 / (stride * cfg.arm.dt))), dpi=dpi)
    return out
