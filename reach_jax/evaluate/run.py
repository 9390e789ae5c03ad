"""Evaluating a run: the test episodes of every network, their results and the files of eval/; [m], [s], [deg].

`evaluate_run` measures (`Results`), `write_results` writes; `evaluate` does both, `redecide` decides the claims
again from the written files. The after-effect, the impedance along the field's axes and the claims are judged
once per frame of the paper's field (`frames`): each file holds the first frame's, and the others' under "frames".
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import numpy as np

from reach_jax.config import Config
from reach_jax.evaluate import (
    adaptation,
    anatomy,
    anatomy_report,
    figures,
    frames,
    geometry,
    impedance,
    lattice,
    movement,
    paper_figures,
    pulls,
)
from reach_jax.evaluate.episodes import Episode, Trajectory, network_policy, run_episodes
from reach_jax.evaluate.figure_files import Figures
from reach_jax.evaluate.judgements import EVAL_DIR, by_frame, judge, write_judgements
from reach_jax.evaluate.paper_figures import FIG4_PANELS, corner_pairs
from reach_jax.store import files
from reach_jax.store import run_dir as run_dir_io

RESULT_FILES = ("table2", "aftereffect", "quality", "impedance", "anatomy", "claims")  # each written as NAME.json


@dataclasses.dataclass(frozen=True)
class FigureData:
    """The arrays that the figures draw (`figures.fig4`, `fig5`, `impedance`), beside the JSON results."""

    panels: dict  # {frame: {Fig. 4 letter: Episode over the M corner movements}} for the panels with a network
    starts: np.ndarray  # (M, 2) corner movements' starts [m]
    targets: np.ndarray  # (M, 2) their targets [m]
    start_corner: np.ndarray  # (M,) start corner index into panels.CORNER_NAMES
    gains: dict  # `impedance.measure` output


@dataclasses.dataclass(frozen=True)
class Results:
    """An evaluation's results: `json` as written to NAME.json, `figures` for the PNG files."""

    json: dict  # RESULT_FILES' names and "adaptation" (None for a run without protocols and a per-trial log)
    figures: FigureData


def run_tests(
    policy, params, masks, lattice_ends: tuple[np.ndarray, np.ndarray], corner_ends: tuple[np.ndarray, np.ndarray], cfg
) -> tuple[Episode, Trajectory, Episode]:
    """Every network's lattice and corner movements under every test condition, as one batch of episodes.

    Args:
      policy: as for `episodes.run_episodes`, with a leading network axis N.
      params: as for `episodes.run_episodes`, with a leading network axis N.
      masks: as for `episodes.run_episodes`, with a leading network axis N.
      lattice_ends: the lattice pairs' (starts, targets), two (P, 2) [m].
      corner_ends: the Fig. 4 movements' (starts, targets), two (M, 2) [m].
      cfg: model config.

    Returns:
      (lattice episodes (N, C, P), their trajectories, corner episodes (N, C, M)), NumPy; C `frames.test_columns`.
    """
    ep, traj = jax.device_get(
        run_episodes(
            policy,
            params,
            masks,
            lattice.test_fields(cfg),  # every column of `frames.test_columns`
            np.concatenate([lattice_ends[0], corner_ends[0]]),
            np.concatenate([lattice_ends[1], corner_ends[1]]),
            cfg,
        )
    )
    p = len(lattice_ends[0])
    return (
        Episode(*(a[:, :, :p] for a in ep)),
        Trajectory(*(a[:, :, :p] for a in traj)),
        Episode(*(a[:, :, p:] for a in ep)),
    )


def network_index(learners: list[tuple[str, int]], recipe_of: list[int], learning: str, seed: int, recipe: int):
    """Index of the network with this learning condition, seed and recipe; None if the run has none."""
    for i, (name, s) in enumerate(learners):
        if name == learning and s == seed and recipe_of[i] == recipe:
            return i
    return None


def fig4_panels(corners: Episode, v: frames.View, cfg: Config) -> dict:
    """{Fig. 4 letter: Episode over the corner movements} of recipe 0's cfg.eval.figure_seed networks in view `v`."""
    panels = {}
    for letter, learning, test in FIG4_PANELS:
        i = network_index(v.learners, v.recipe_of, learning, cfg.eval.figure_seed, 0)
        if i is not None and test in v.tests:
            panels[letter] = Episode(*(a[i, v.tests.index(test)] for a in corners))
    return panels


def aftereffect_per_seed(corners: Episode, corner: tuple, v: frames.View, n_recipes: int, seeds: int) -> list[dict]:
    """`pulls.aftereffect` of every (recipe, seed) that has both a no-field and a field-trained network in view `v`.

    Args:
      corners: corner episodes (N, C, M).
      corner: (starts, targets, start corner index) of the M corner movements (`panels.corner_pairs`).
      v: the frame's view of the networks and test columns; its field's matrix gives the force [N s/m].
      n_recipes: number of recipes.
      seeds: networks per condition and recipe.
    """
    per_seed = []
    if not {"none", frames.PAPER_FIELD} <= set(v.tests):
        return per_seed
    off, on = v.tests.index("none"), v.tests.index(frames.PAPER_FIELD)
    for k in range(n_recipes):
        for seed in range(seeds):
            i = network_index(v.learners, v.recipe_of, "none", seed, k)
            j = network_index(v.learners, v.recipe_of, frames.PAPER_FIELD, seed, k)
            if i is None or j is None:
                continue
            hands = {
                "a": corners.hand[i, off],
                "b": corners.hand[i, on],
                "c": corners.hand[j, off],
                "d": corners.hand[j, on],
            }
            per_seed.append({"recipe": k, "seed": seed, **pulls.aftereffect(hands, *corner, v.field)})
    return per_seed


def evaluate_run(data: run_dir_io.Run) -> Results:
    """Run the test protocol on every network of a run: the JSON-ready results and the arrays for the figures.

    The networks are tested in the visual field they learned in; those of a run that trained several
    (`geometry.groups`) are evaluated one field at a time (`evaluate_fields`): ValueError here.
    """
    (sensor, _), *more = geometry.groups(data)
    if more:
        raise ValueError(f"the run's learners see {len(more) + 1} visual fields; evaluate_fields evaluates each")
    data = data._replace(cfg=dataclasses.replace(data.cfg, sensor=sensor))
    cfg = data.cfg
    starts, targets = lattice.test_pairs(cfg)
    corner = corner_pairs(cfg)
    params, masks = data.batch.states.agent.params, data.batch.conds.input_mask
    policy = network_policy(cfg)
    grid, grid_traj, corners = run_tests(policy, params, masks, (starts, targets), corner[:2], cfg)
    recipes, recipe_of = lattice.recipe_index(data.batch.hypers)
    table = lattice.table2(grid.outcome, grid.steps, data.learners, recipe_of, cfg)
    for row in table["per_network"]:
        row.update(recipes[row["recipe"]])
    gains = impedance.measure(policy, params, masks, grid, grid_traj, starts, targets, cfg)
    # The networks evaluated together share one visual field (`geometry.groups`), so one cell sets every goal square.
    th = anatomy.thresholds(cfg, np.full(len(data.learners), cfg.sensor.cell_size))
    labelled = anatomy.label_movements(grid, grid_traj, targets, th)
    judged, panels = {}, {}
    for frame in frames.frame_list(cfg):
        v = frames.view(frame, data.learners, recipe_of, cfg)
        imp = impedance.summarize(gains, data.learners, frames.test_columns(cfg), v.field)
        for row in imp["per_network"]:
            row["recipe"] = recipe_of[row["learner"]]
        per_seed = aftereffect_per_seed(corners, corner, v, len(recipes), cfg.train.seeds)
        judged[frame] = judge(v, table, per_seed, imp, recipes, data.metrics)
        panels[frame] = fig4_panels(corners, v, cfg)
    trials = np.asarray(data.batch.states.env.trials)
    results = {
        "table2": {**table, "chunk": data.chunk, "trials_per_network": [int(t) for t in trials]},
        "aftereffect": by_frame(judged, "aftereffect"),
        "quality": movement.quality(grid, data.learners, starts, targets, cfg),
        "impedance": {**by_frame(judged, "impedance"), "recipes": recipes, "chunk": data.chunk},
        "anatomy": {**anatomy.summarize(labelled, data.learners, recipe_of, recipes, cfg), "chunk": data.chunk},
        "claims": {"chunk": data.chunk, "trials_per_network": cfg.train.trials, **by_frame(judged, "claims")},
        "adaptation": adaptation.analyse(data.trials, data.learners, cfg),
    }
    return Results(json=results, figures=FigureData(panels, *corner, gains))


def write_results(run_dir: Path, data: run_dir_io.Run, results: Results, out: Path | None = None) -> Path:
    """Write every file of the evaluation into `out` (default RUN_DIR/eval/); returns that directory.

    A figure is drawn and written only when its data changed since the last evaluation into `out` (`Figures`).
    """
    cfg, res, fig = data.cfg, results.json, results.figures
    out = Path(run_dir) / EVAL_DIR if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in (n for n in RESULT_FILES if n != "claims"):
        files.atomic_write_bytes(out / f"{name}.json", json.dumps(res[name], indent=2).encode())
    source = f"{run_dir} (chunk {data.chunk})"
    write_judgements(out, res["table2"], res["claims"], cfg, source, res["anatomy"])
    files.atomic_write_bytes(out / "quality.md", movement.quality_markdown(res["quality"], source).encode())
    few = cfg.claims.informative_networks
    files.atomic_write_bytes(out / "anatomy.md", anatomy_report.markdown(res["anatomy"], source, few).encode())
    pngs = Figures(out)
    pngs.draw("impedance.png", figures.impedance, res["impedance"], fig.gains, data.learners, cfg)
    first = next(iter(fig.panels))
    for frame in fig.panels:  # the first frame's is fig4.png, another's fig4_FRAME.png
        name = "fig4.png" if frame == first else f"fig4_{frame}.png"
        pngs.draw(name, paper_figures.fig4, fig.panels[frame], fig.starts, fig.targets, fig.start_corner, cfg)
    pngs.draw("fig5.png", paper_figures.fig5, fig.panels[first], fig.start_corner, cfg)
    pngs.draw("learning_curves.png", figures.learning_curves, data.metrics, cfg)
    pngs.draw("anatomy.png", anatomy_report.figure, res["anatomy"])
    if res["adaptation"] is not None:
        files.atomic_write_bytes(out / "adaptation.json", json.dumps(res["adaptation"], indent=2).encode())
        files.atomic_write_bytes(out / "adaptation.md", adaptation.markdown(res["adaptation"], source).encode())
        pngs.draw("adaptation.png", figures.adaptation, res["adaptation"], cfg)
    pngs.close()
    return out


def evaluate_fields(run_dir: Path, data: run_dir_io.Run, out: Path | None = None) -> list[Results]:
    """Evaluate each visual field's learners of a run as a run of their own and write it into out/geometry_<k>/
    (`geometry.subdir`), with eval/geometries.json and .md to index them; returns each field's results in order.

    Args:
      run_dir: the run directory (named in the files).
      data: the run as `run_dir.load` gives it.
      out: the folder (default RUN_DIR/eval).
    """
    out = Path(run_dir) / EVAL_DIR if out is None else Path(out)
    parts, done = geometry.groups(data), []
    for k, (sensor, picks) in enumerate(parts):
        sub = geometry.sub_run(data, sensor, picks)
        done.append(evaluate_run(sub))
        write_results(run_dir, sub, done[-1], out / geometry.subdir(k))
    record = geometry.index_record(parts, [r.json["claims"] for r in done])
    geometry.write_index(out, record, f"{run_dir} (chunk {data.chunk})")
    return done


def evaluate(run_dir: Path, checkpoint_path: Path | None = None, out: Path | None = None) -> dict:
    """Evaluate a run at its newest (or the given) checkpoint and write every file into `out` (default RUN_DIR/eval).

    Returns the JSON-ready results, keyed by file: table2, aftereffect, quality, impedance, anatomy, claims, and
    adaptation (None for a run without protocol learners and a per-trial log). A run of several visual fields is
    evaluated one field at a time (`evaluate_fields`): then {"fields": each field's results}.
    Raises CheckpointError (one line, naming the bad file) before anything is written.
    """
    run = run_dir_io.load(run_dir, checkpoint_path)
    if len(geometry.groups(run)) > 1:
        return {"fields": [r.json for r in evaluate_fields(run_dir, run, out)]}
    results = evaluate_run(run)
    write_results(run_dir, run, results, out)
    return results.json
