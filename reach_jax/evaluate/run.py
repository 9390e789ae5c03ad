"""Evaluating a run: the test episodes of every network, their results and the files of eval/; [m], [s], [deg].

`evaluate_run` measures (`Results`), `write_results` writes; `evaluate` does both, `redecide` decides the claims
again from the written files.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import jax
import numpy as np

from reach_jax.config import Config
from reach_jax.env import task
from reach_jax.evaluate import adaptation, figures, impedance, lattice, movement, paper_figures, pulls, report, verdicts
from reach_jax.evaluate.episodes import Episode, Trajectory, network_policy, run_episodes
from reach_jax.evaluate.paper_figures import FIG4_PANELS, corner_pairs
from reach_jax.store import files
from reach_jax.store import run_dir as run_dir_io
from reach_jax.store.checkpoint import CheckpointError

EVAL_DIR = "eval"
RESULT_FILES = ("table2", "aftereffect", "quality", "impedance", "claims")  # each written as NAME.json
# {PNG name: digest of the data it draws}, so that a figure whose data has not changed is neither drawn nor written
FIGURE_DIGESTS = "figures.json"


@dataclasses.dataclass(frozen=True)
class FigureData:
    """The arrays that the figures draw (`figures.fig4`, `fig5`, `impedance`), beside the JSON results."""

    panels: dict  # {Fig. 4 letter: Episode over the M corner movements} for the panels with a network
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
      (lattice episodes (N, C, P), their trajectories, corner episodes (N, C, M)), NumPy.
    """
    ep, traj = jax.device_get(
        run_episodes(
            policy,
            params,
            masks,
            lattice.test_fields(cfg),
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


def fig4_panels(corners: Episode, learners, recipe_of: list[int], cfg: Config) -> dict:
    """{Fig. 4 letter: Episode over the corner movements} of recipe 0's cfg.eval.figure_seed networks."""
    tests = cfg.eval.test_conditions
    panels = {}
    for letter, learning, test in FIG4_PANELS:
        i = network_index(learners, recipe_of, learning, cfg.eval.figure_seed, 0)
        if i is not None and test in tests:
            panels[letter] = Episode(*(a[i, tests.index(test)] for a in corners))
    return panels


def aftereffect_per_seed(
    corners: Episode, corner: tuple, learners, recipe_of: list[int], n_recipes: int, field: np.ndarray, cfg: Config
) -> list[dict]:
    """`pulls.aftereffect` of every (recipe, seed) that has both a no-field and a viscous-field network.

    Args:
      corners: corner episodes (N, C, M).
      corner: (starts, targets, start corner index) of the M corner movements (`panels.corner_pairs`).
      learners: (learning condition, seed index) per network.
      recipe_of: (N,) recipe index per network.
      n_recipes: number of recipes.
      field: (2, 2) viscous field matrix [N s/m].
      cfg: model config.
    """
    tests = cfg.eval.test_conditions
    per_seed = []
    for k in range(n_recipes):
        for seed in range(cfg.train.seeds):
            i = network_index(learners, recipe_of, "none", seed, k)
            j = network_index(learners, recipe_of, "viscous", seed, k)
            if i is None or j is None or not {"none", "viscous"} <= set(tests):
                continue
            off, on = tests.index("none"), tests.index("viscous")
            hands = {
                "a": corners.hand[i, off],
                "b": corners.hand[i, on],
                "c": corners.hand[j, off],
                "d": corners.hand[j, on],
            }
            per_seed.append({"recipe": k, "seed": seed, **pulls.aftereffect(hands, *corner, field)})
    return per_seed


def aftereffect_result(per_seed: list[dict], cfg: Config) -> dict:
    """aftereffect.json: recipe 0's figure seed, with every (recipe, seed) beside it."""
    main = [a for a in per_seed if a["recipe"] == 0 and a["seed"] == cfg.eval.figure_seed]
    if main:
        return {**main[0], "per_seed": per_seed}
    return {"error": "needs the none and viscous learning conditions at seed cfg.eval.figure_seed"}


def evaluate_run(data: run_dir_io.Run) -> Results:
    """Run the test protocol on every network of a run: the JSON-ready results and the arrays for the figures."""
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
    viscous = np.asarray(task.make_condition("viscous", cfg).field.viscous)  # the float32 matrix the arm felt
    per_seed = aftereffect_per_seed(corners, corner, data.learners, recipe_of, len(recipes), viscous, cfg)
    gains = impedance.measure(policy, params, masks, grid, grid_traj, starts, targets, cfg)
    imp = impedance.summarize(gains, data.learners, cfg.eval.test_conditions, viscous)
    for row in imp["per_network"]:
        row["recipe"] = recipe_of[row["learner"]]
    decided = verdicts.decide(table, per_seed, imp, recipes, recipe_of, data.metrics, cfg)
    trials = np.asarray(data.batch.states.env.trials)
    results = {
        "table2": {**table, "chunk": data.chunk, "trials_per_network": [int(t) for t in trials]},
        "aftereffect": aftereffect_result(per_seed, cfg),
        "quality": movement.quality(grid, data.learners, starts, targets, cfg),
        "impedance": {**imp, "recipes": recipes, "chunk": data.chunk},
        "claims": {"chunk": data.chunk, "trials_per_network": cfg.train.trials, "recipes": decided},
        "adaptation": adaptation.analyse(data.trials, data.learners, cfg),
    }
    panels = fig4_panels(corners, data.learners, recipe_of, cfg)
    return Results(json=results, figures=FigureData(panels, *corner, gains))


def redecide(run_dir: Path) -> dict:
    """Decide the claims again from a run's committed eval/ files, without running the test episodes again.

    For a change in how claims are decided (the statistics, the criteria's presentation): the test episodes
    round differently in float32 on another CPU, where a few of a network's 2080 movements can change outcome.
    Rewrites eval/claims.json, claims.md and table2.md; returns the new claims results.
    """
    run_dir = Path(run_dir)
    out = run_dir / EVAL_DIR
    paths = [out / f"{n}.json" for n in ("table2", "aftereffect", "impedance")]
    for path in paths:
        if not path.is_file():
            raise CheckpointError(f"{path}: missing; evaluate the run in full first")
    table, after, imp = (json.loads(path.read_text()) for path in paths)
    cfg = run_dir_io.read_config(run_dir)
    recipe_of = list(dict(sorted({r["learner"]: r["recipe"] for r in imp["per_network"]}.items())).values())
    metrics = run_dir_io.read_metrics(run_dir, table["chunk"])
    decided = verdicts.decide(table, after.get("per_seed", []), imp, imp["recipes"], recipe_of, metrics, cfg)
    result = {"chunk": table["chunk"], "trials_per_network": cfg.train.trials, "recipes": decided}
    source = f"{run_dir} (chunk {table['chunk']})"
    files.atomic_write_bytes(out / "claims.json", json.dumps(result, indent=2).encode())
    files.atomic_write_bytes(out / "table2.md", lattice.table2_markdown(table, decided, source).encode())
    files.atomic_write_bytes(out / "claims.md", report.claims_markdown(result, source).encode())
    return result


def _canonical(x):
    """x as JSON data for a digest: an array as its dtype, shape and the SHA-256 of its bytes, a dataclass (the
    config) as its fields, a tuple (NamedTuples included) as a list."""
    if isinstance(x, np.ndarray | np.generic | jax.Array):
        a = np.ascontiguousarray(x)
        return {"dtype": a.dtype.str, "shape": a.shape, "sha256": hashlib.sha256(a.tobytes()).hexdigest()}
    if dataclasses.is_dataclass(x):
        return _canonical(dataclasses.asdict(x))
    if isinstance(x, dict):
        return {str(k): _canonical(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_canonical(v) for v in x]
    return x


def data_digest(*data) -> str:
    """SHA-256 of the data a figure draws (arrays, JSON-like values, the config), equal exactly when the data are."""
    return hashlib.sha256(json.dumps(_canonical(data), sort_keys=True).encode()).hexdigest()


class Figures:
    """Writes the PNGs of an evaluation into a folder, each drawn only when the data it draws have changed.

    FIGURE_DIGESTS in the folder keeps each PNG's data digest; a PNG whose digest matches keeps its bytes and mtime.
    """

    def __init__(self, out: Path):
        self.out, self.path = out, out / FIGURE_DIGESTS
        try:
            self.stored = json.loads(self.path.read_text())
        except (OSError, json.JSONDecodeError):
            self.stored = {}  # none yet, or unreadable: every figure is drawn
        self.digests: dict[str, str] = {}

    def draw(self, name: str, plot, *data) -> None:
        """Write plot(*data) (a matplotlib Figure) as `name`, unless the PNG there drew the same data."""
        digest = self.digests[name] = data_digest(*data)
        if self.stored.get(name) == digest and (self.out / name).is_file():
            return
        files.atomic_write_bytes(self.out / name, figures.png_bytes(plot(*data)))

    def close(self) -> None:
        """Write FIGURE_DIGESTS, if it changed."""
        if self.digests != self.stored:
            files.atomic_write_bytes(self.path, json.dumps(self.digests, indent=2, sort_keys=True).encode())


def write_results(run_dir: Path, data: run_dir_io.Run, results: Results, out: Path | None = None) -> Path:
    """Write every file of the evaluation into `out` (default RUN_DIR/eval/); returns that directory.

    A figure is drawn and written only when its data changed since the last evaluation into `out` (`Figures`).
    """
    cfg, res, fig = data.cfg, results.json, results.figures
    out = Path(run_dir) / EVAL_DIR if out is None else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in RESULT_FILES:
        files.atomic_write_bytes(out / f"{name}.json", json.dumps(res[name], indent=2).encode())
    source = f"{run_dir} (chunk {data.chunk})"
    recipes = res["claims"]["recipes"]
    files.atomic_write_bytes(out / "table2.md", lattice.table2_markdown(res["table2"], recipes, source).encode())
    files.atomic_write_bytes(out / "claims.md", report.claims_markdown(res["claims"], source).encode())
    files.atomic_write_bytes(out / "quality.md", movement.quality_markdown(res["quality"], source).encode())
    pngs = Figures(out)
    pngs.draw("impedance.png", figures.impedance, res["impedance"], fig.gains, data.learners, cfg)
    pngs.draw("fig4.png", paper_figures.fig4, fig.panels, fig.starts, fig.targets, fig.start_corner, cfg)
    pngs.draw("fig5.png", paper_figures.fig5, fig.panels, fig.start_corner, cfg)
    pngs.draw("learning_curves.png", figures.learning_curves, data.metrics, cfg)
    if res["adaptation"] is not None:
        files.atomic_write_bytes(out / "adaptation.json", json.dumps(res["adaptation"], indent=2).encode())
        files.atomic_write_bytes(out / "adaptation.md", adaptation.markdown(res["adaptation"], source).encode())
        pngs.draw("adaptation.png", figures.adaptation, res["adaptation"], cfg)
    pngs.close()
    return out


def evaluate(run_dir: Path, checkpoint_path: Path | None = None, out: Path | None = None) -> dict:
    """Evaluate a run at its newest (or the given) checkpoint and write every file into `out` (default RUN_DIR/eval).

    Returns the JSON-ready results, keyed by file: table2, aftereffect, quality, impedance, claims, and adaptation
    (None for a run without protocol learners and a per-trial log).
    Raises CheckpointError (one line, naming the bad file) before anything is written.
    """
    run = run_dir_io.load(run_dir, checkpoint_path)
    results = evaluate_run(run)
    write_results(run_dir, run, results, out)
    return results.json
