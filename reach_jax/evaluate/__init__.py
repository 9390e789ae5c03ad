"""Table-2 test protocol, Fig. 4-5 movements, after-effect and movement quality (section 4.4, model §8-10).

`evaluate(run_dir)` (or `python -m reach_jax.evaluate RUN_DIR`) loads the newest checkpoint of a run and writes
RUN_DIR/eval/: table2.json, table2.md, fig4.png, fig5.png, aftereffect.json, quality.json, anatomy.json, .md, .png
and learning_curves.png; figures.json keeps the digest of each PNG's data, so that a figure is drawn again only
when its data changed.

Units: positions [m] in the shoulder frame, speeds [m/s], times [s], angles in the JSON files [deg]
(directions measured counter-clockwise from +x), torques [N m]. Trial lengths are steps of cfg.arm.dt.

Protocol. Every (start, target) pair x network x test condition is one episode of one jitted, vmapped
`lax.scan` over cfg.eval.max_time / cfg.arm.dt = 200 steps; there is no Python loop over pairs. There is
no learning, no exploration noise, no random force and no target drift. The arm starts at rest at the
inverse kinematics of the start. A network sees its *learning* condition's input mask (random_nopast
networks never see the past inputs); only the force field comes from the test condition.

The evaluator is policy-agnostic: a policy is any function (params, Obs) -> (2,) torque [N m], clipped by
the evaluator to +-tau_max (the actuator limit of Table 1). The network policy uses only Obs.x, the
masked 125-input, and applies the actor without noise: tau = network.torque(m, 0).

Modules: `lattice` (the 1040 test pairs, outcome counts, Table 2), `anatomy` and `anatomy_report` (where each out
and fail ends, per cell), `pulls` (the after-effect), `movement` (movement quality), `verdicts` (the claims),
`plausibility` (D, and the paper as a two-network draw from ours), `run` (the evaluation of a run and its files),
`report` (the claims in Markdown and the command's closing screen), `compare` (evaluated runs side by side,
`python -m reach_jax.evaluate.compare RUN...`). Fig. 4 movements: the start and the target are two of the centres of
the four corner cells of the sensor, all 12 ordered pairs (`paper_figures`).
"""

from reach_jax.evaluate.figure_files import FIGURE_DIGESTS
from reach_jax.evaluate.judgements import redecide
from reach_jax.evaluate.lattice import (
    count,
    lattice_points,
    learning_conditions,
    recipe_index,
    table2,
    table2_markdown,
    test_fields,
    test_pairs,
    trial_times,
)
from reach_jax.evaluate.movement import (
    bell_correlation,
    count_peaks,
    minimum_jerk_episodes,
    minimum_jerk_speed,
    movement_quality,
    quality,
    quality_markdown,
    straightness,
)
from reach_jax.evaluate.pulls import aftereffect, line_deviation, pool_aftereffect, pull_vectors
from reach_jax.evaluate.run import (
    EVAL_DIR,
    RESULT_FILES,
    FigureData,
    Results,
    evaluate,
    evaluate_fields,
    evaluate_run,
    write_results,
)
from reach_jax.evaluate.verdicts import decide, impedance_cells

__all__ = [
    "EVAL_DIR",
    "FIGURE_DIGESTS",
    "RESULT_FILES",
    "FigureData",
    "Results",
    "aftereffect",
    "bell_correlation",
    "count",
    "count_peaks",
    "decide",
    "evaluate",
    "evaluate_fields",
    "evaluate_run",
    "impedance_cells",
    "lattice_points",
    "learning_conditions",
    "line_deviation",
    "minimum_jerk_episodes",
    "minimum_jerk_speed",
    "movement_quality",
    "pool_aftereffect",
    "pull_vectors",
    "quality",
    "quality_markdown",
    "recipe_index",
    "redecide",
    "straightness",
    "table2",
    "table2_markdown",
    "test_fields",
    "test_pairs",
    "trial_times",
    "write_results",
]
