"""The Table-2 test lattice and pairs, outcome counts, and Table 2 with its Markdown; positions [m], times [s].

Every (start, target) pair x network x test condition is one test episode (`episodes.run_episodes`). Each
episode ends in one outcome: success (`task.goal_reached`), out (`arm.is_out`, checked first) or fail (neither
within cfg.eval.max_time). The mean time is taken over all pairs, with out and fail counted as cfg.eval.max_time.

Why exactly 1040 pairs per network. The 8 x 8 lattice runs edge to edge over the visual field:
x_k = x_min + k W / 7, k = 0..7 (W = 0.2 m, spacing 28.6 mm), and the same in y. The hand and the target are
squares one cell (40 mm) wide, and both must be wholly on the sensor, so the points on the border of the
lattice are dropped: a square centred there sticks half out of the field. That leaves the inner 6 x 6 = 36
points and 36^2 = 1296 ordered (start, target) pairs. A pair is excluded when the hand already touches the
target, i.e. |dx| and |dy| are both below the goal half-width (one cell, 40 mm). On this lattice that is
the case exactly for lattice offsets of at most one step per axis (28.6 mm < 40 mm < 57.1 mm): per axis
6 + 2 x 5 = 16 of the 36 ordered index pairs, so 16^2 = 256 pairs, including the 36 with start = target.
1296 - 256 = 1040. (Reading the lattice as the centres of an 8 x 8 grid of W / 8 squares gives the same
inner 6 x 6 and the same 1040.) The paper says the start and the target lie on "one of the 8 x 8 = 64"
lattice points; using only the 36 points whose squares fit in the field is our reading, not its literal
text. It is the only construction we found that yields the paper's 1040: on all 64 points the touching
rule leaves 64^2 - 22^2 = 3612 ordered pairs, and no distance threshold gives 1040.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config, hyper
from reach_jax.config.paper import PAPER_NETWORKS, PAPER_TABLE2
from reach_jax.env import task
from reach_jax.env.environment import OUTCOME_NAMES, SUCCESS
from reach_jax.evaluate import frames, plausibility
from reach_jax.evaluate.report import collapsed_words, interval_text
from reach_jax.physics import fields, sensor


def lattice_points(cfg: Config) -> np.ndarray:
    """Test lattice points whose one-cell square lies wholly in the visual field: (36, 2) [m], x fastest.

    Args:
      cfg: model config; cfg.eval.lattice points per side run edge to edge over the field.
    """
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    half = 0.5 * cfg.sensor.cell_size
    k = np.arange(cfg.eval.lattice) / (cfg.eval.lattice - 1)
    xs, ys = x0 + k * (x1 - x0), y0 + k * (y1 - y0)
    xs = xs[(xs - half >= x0) & (xs + half <= x1)]
    ys = ys[(ys - half >= y0) & (ys + half <= y1)]
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def test_pairs(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """Ordered (start, target) lattice pairs where the hand does not touch the target: two (1040, 2) [m]."""
    pts = lattice_points(cfg)
    starts = np.repeat(pts, len(pts), axis=0)
    targets = np.tile(pts, (len(pts), 1))
    keep = ~np.asarray(task.touching(jnp.asarray(starts), jnp.asarray(targets), task.goal_half_width(cfg)))
    return starts[keep], targets[keep]


def test_fields(cfg: Config) -> fields.Field:
    """The hand-force fields of the test columns (`frames.test_columns`), stacked along a leading axis."""
    conditions = (task.make_condition(n, cfg) for n in frames.test_columns(cfg))
    return jax.tree.map(lambda *f: jnp.stack(f), *(c.field for c in conditions))


def trial_times(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> np.ndarray:
    """Reaching time per episode [s]: steps x dt for a success, cfg.eval.max_time for out and fail (model §8)."""
    return np.where(np.asarray(outcome) == SUCCESS, np.asarray(steps) * cfg.arm.dt, cfg.eval.max_time)


def count(outcome: np.ndarray, steps: np.ndarray, cfg: Config) -> dict:
    """success / out / fail counts and mean time over all given episodes (any shape)."""
    outcome = np.asarray(outcome)
    return {
        **{name: int(np.sum(outcome == code)) for code, name in enumerate(OUTCOME_NAMES)},
        "mean_time_s": float(np.mean(trial_times(outcome, steps, cfg))),
    }


def recipe_index(hypers) -> tuple[list[dict], list[int]]:
    """The distinct hyperparameter sets (recipes) of a batch, in batch order, and each learner's recipe index.

    Args:
      hypers: hyper.Hyper with a leading learner axis.

    Returns:
      (each recipe's hyperparameters that name it, `hyper.label`; each learner's recipe index).
    """
    columns = [np.asarray(getattr(hypers, n)) for n in hyper.NAMES]
    values = [tuple(float(v) for v in row) for row in zip(*columns, strict=True)]
    distinct = list(dict.fromkeys(values))
    named = [hyper.label(dict(zip(hyper.NAMES, v, strict=True))) for v in distinct]
    return named, [distinct.index(v) for v in values]


def learning_conditions(learners: list[tuple[str, int]], cfg: Config) -> list[str]:
    """The learning conditions that have networks: those of cfg.train.conditions in its order (the paper's, whichever
    frame its field trains in), then the others in the order of the config's conditions table."""
    names = {name for name, _ in learners}
    order = dict.fromkeys([*cfg.train.conditions, *(c.name for c in cfg.conditions)])
    return [name for name in order if name in names]


def table2(outcome: np.ndarray, steps: np.ndarray, learners: list[tuple[str, int]], recipe_of, cfg: Config) -> dict:
    """Table 2 as a JSON-ready dict: counts summed over each learning condition's networks, and per network.

    Args:
      outcome: (N, C, 1040) outcome codes, networks in `learners` order, tests in `frames.test_columns` order.
      steps: (N, C, 1040) episode lengths [steps].
      learners: (learning condition, seed index) per network.
      recipe_of: (N,) recipe index per network (`recipe_index`).
      cfg: model config.

    Returns:
      {"rows": sums over every network of a condition, "first_two": sums over seeds 0 and 1 per recipe,
      "per_network": one row per network and test, "pairs_per_network"}.
    """
    rows, first_two, per_network = [], [], []
    present = learning_conditions(learners, cfg)
    for learning in present:
        nets = [i for i, (name, _) in enumerate(learners) if name == learning]
        for j, test in enumerate(frames.test_columns(cfg)):
            cell = count(outcome[nets, j], steps[nets, j], cfg)
            rows.append({"learning": learning, "test": test, "networks": len(nets), **cell})
    for k in sorted(set(recipe_of)):
        for learning in present:
            nets = [i for i, (name, s) in enumerate(learners) if name == learning and s < 2 and recipe_of[i] == k]
            for j, test in enumerate(frames.test_columns(cfg)):
                cell = count(outcome[nets, j], steps[nets, j], cfg)
                first_two.append({"learning": learning, "test": test, "recipe": k, "networks": len(nets), **cell})
    for i, (learning, seed) in enumerate(learners):
        for j, test in enumerate(frames.test_columns(cfg)):
            cell = count(outcome[i, j], steps[i, j], cfg)
            per_network.append(
                {"learner": i, "learning": learning, "seed": seed, "recipe": recipe_of[i], "test": test, **cell}
            )
    return {
        "rows": rows,
        "first_two": first_two,
        "pairs_per_network": int(outcome.shape[-1]),
        "per_network": per_network,
    }


def _cell(success: int, out: int, fail: int, mean_time: float) -> str:
    return f"{success}-{out}-{fail} ({mean_time:.3g} s)"


def _recipe_name(hypers: dict) -> str:
    return ", ".join(f"{k} {v:g}" for k, v in hypers.items())


def _table2_row(cell: dict, first: dict | None, few: int, frame: str | None, pairs: dict | None) -> str:
    """One Table-2 cell as a Markdown row: our intervals, our networks 0-1 summed (`first`), the paper's, near it,
    and the range of our pairs with whether the paper lies in it (`pairs`, the cell's `plausibility` record); the
    cell's conditions named as in the run (`frames.shown`)."""
    ours01 = _cell(first["success"], first["out"], first["fail"], first["mean_time_s"]) if first else "–"
    key = (cell["learning"], cell["test"])
    paper = _cell(*PAPER_TABLE2[key]) if key in PAPER_TABLE2 else "–"
    near = "–"
    if cell["near_paper"]:
        near = " / ".join("yes" if cell["near_paper"][n] else "no" for n in ("success", "out", "mean_time_s"))
    spread, inside = "–", "–"
    if pairs is not None:
        spread = " / ".join(f"{100 * pairs[k]['low']:.1f}–{100 * pairs[k]['high']:.1f}" for k in plausibility.RATES)
        inside = " / ".join("yes" if pairs[k]["inside"] else "no" for k in plausibility.RATES)
    return (
        f"| {frames.shown(cell['learning'], frame)} → {frames.shown(cell['test'], frame)} | "
        f"{interval_text(cell['success'], few, 100.0)} | "
        f"{interval_text(cell['out'], few, 100.0)} | {interval_text(cell['mean_time_s'], few, 1.0, 2)} | "
        f"{ours01} | {paper} | {near} | {spread} | {inside} |"
    )


def table2_markdown(table: dict, recipes: list[dict], source: str) -> str:
    """Table 2 in Markdown per recipe: mean per network with its interval, our networks 0-1 summed, the paper's.

    Args:
      table: `table2` results.
      recipes: each recipe's verdicts (`verdicts.decide`), with its cells' intervals.
      source: the run and chunk named in the title.
    """
    return frames_markdown({None: (table, recipes)}, source)


def frames_markdown(judged: dict, source: str) -> str:
    """Table 2 in Markdown for each frame of the paper's field (`frames`) and recipe: mean per network with its
    interval, our networks 0-1 summed, the paper's.

    Args:
      judged: {frame: (the `table2` results in its view (`frames.table_view`), each recipe's verdicts)}, the main
        frame first; frame None for a run without frames.
      source: the run and chunk named in the title.
    """
    table, recipes = next(iter(judged.values()))
    level = recipes[0]["level"] if recipes else 0.95
    lines = [
        f"# Table 2 — {source}",
        "",
        f"Mean per network with its {level:.0%} t-interval over networks (on the logit scale for success and out, the"
        " log scale for time),"
        f" {table['pairs_per_network']} (start, target) pairs per network; out and fail count as 4.0 s in the mean"
        " time. Beside it, success-out-fail (mean time) summed over our networks of seeds 0 and 1, and the paper's"
        f" sum over its {PAPER_NETWORKS}"
        ' networks. "near paper": success and out within the target\'s percentage points, time within its'
        f' fraction (S / O / T). "our pairs": the range of success / out % over every pair of our networks of the'
        f" condition summed as the paper's {PAPER_NETWORKS} are (its 2.5–97.5 percentiles, or lowest to highest"
        ' where there are fewer than 40 pairs); "paper in it": whether the paper\'s success / out lie in that range'
        " (docs/claims.md).",
    ]
    few = recipes[0].get("informative_networks", 0) if recipes else 0
    if recipes and recipes[0]["networks_per_condition"] < few:
        lines[-1] += (
            f" With {recipes[0]['networks_per_condition']} networks a condition (fewer than {few}) an interval says"
            " little, so each network's value stands beside the mean instead."
        )
    if len(judged) > 1:
        lines[-1] += " " + frames.FRAMES_WORDS
    for frame, (table, recipes) in judged.items():
        sums = {(r["learning"], r["test"], r["recipe"]): r for r in table["first_two"]}
        for k, recipe in enumerate(recipes):
            lines += _recipe_section(frame, k, recipe, sums, few)
    return "\n".join(lines) + "\n"


def _recipe_section(frame: str | None, k: int, recipe: dict, sums: dict, few: int) -> list[str]:
    """The lines of one frame's Table 2 for recipe k: its heading, its rows, its plausibility and its collapses."""
    lines = [
        "",
        f"## {frames.heading(frame)}Recipe {k}: {_recipe_name(recipe['hypers'])} "
        f"({recipe['networks_per_condition']} networks per condition)",
        "",
        "| learning → test | success % | out % | mean time [s] | ours, seeds 0–1 | paper | near paper "
        "| our pairs S / O % | paper in it |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    record = recipe.get("plausibility")
    pairs = {(r["learning"], r["test"]): r for r in record["cells"]} if record else {}
    for cell in recipe["cells"]:
        key = (cell["learning"], cell["test"])
        lines.append(_table2_row(cell, sums.get((*key, k)), few, frame, pairs.get(key)))
    if "D" in recipe:
        lines += ["", "Plausibility: " + plausibility.words(record, recipe["D"])]
    if "collapsed" in recipe:
        lines += ["", collapsed_words(recipe)]
    return lines
