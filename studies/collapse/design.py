"""The recipes and training config of issue 49's development batch (studies/collapse/PLAN.md), picked by code.

    python studies/collapse/design.py --stage1 runs/search_stage1 --design studies/search/stage1.json \
        --pick recipes/round4_pick.json --out studies/collapse/dev

Four recipes, each with the fix (`actor_target_bound`): the default of config version 10 (the control), round 4's
pick, and the two stage-1 recipes with the least exploration late in learning (the bound after its anneal,
noise x noise_final_ratio) among those whose every learner reached the whole field in `runs/search_stage1`.
Writes OUT.json (the recipes, with why each was chosen) and OUT_config.json (zipped grids, the plan's seed).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from reach_jax.config import hyper
from reach_jax.engine import batch
from reach_jax.store import run_dir
from reach_jax.train.health import whole_field

KNOBS = [h.name for h in hyper.TABLE]
BOUND = 0.45  # the fix's value: train.saturated_output, where the metrics count an actor output as saturated
SEED, NETWORKS, TRIALS, CHUNK = 15, 4, 2_000_000, 400_000  # PLAN.md: a development master seed no run has used
CAP = 4.0  # the learning cap of round 4 (studies/search/PLAN.md): the batch runs in lockstep


def stage1_recipes(run: Path, design: dict) -> list[dict]:
    """Stage 1's recipes in batch order (the default, then the draws), each with its late bound and whether every
    one of its learners reached the whole field."""
    cfg = run_dir.read_config(run)
    rows = run_dir.read_metrics(run)
    full = {r["learner"] for r in rows if r["distance_m"] >= whole_field(cfg) * (1.0 - 1e-6)}
    n_points, seeds = len(design["draws"]) + 1, cfg.train.seeds
    table = batch.learner_table(cfg.train)
    hypers = [{n: hyper.defaults(8)[n] for n in design["draws"][0]["hypers"]}, *(d["hypers"] for d in design["draws"])]
    recipes = []
    for k, h in enumerate(hypers):
        learners = [i for i in range(len(table)) if (i // seeds) % n_points == k]
        full_h = {**hyper.defaults(8), **h}
        late = full_h["noise"] * full_h["noise_final_ratio"]
        recipes.append({"stage1_recipe": k, "hypers": h, "late_bound": late, "all_reached": set(learners) <= full})
    return recipes


def main(argv=None) -> int:
    """Write OUT.json and OUT_config.json."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--stage1", type=Path, required=True)
    p.add_argument("--design", type=Path, required=True)
    p.add_argument("--pick", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    design = json.loads(args.design.read_text())
    draws = [r for r in stage1_recipes(args.stage1, design)[1:] if r["all_reached"]]
    least = sorted(draws, key=lambda r: r["late_bound"])[:2]
    pick = json.loads(args.pick.read_text())["learner"]
    chosen = [
        {"source": "the default of config version 10 (the control)", "hypers": {}},
        {"source": f"round 4's pick ({args.pick})", "hypers": pick},
        *(
            {
                "source": f"stage 1's recipe {r['stage1_recipe']}: late bound {r['late_bound']:.4f}, the "
                f"{'least' if i == 0 else 'second least'} of the {len(draws)} draws whose learners all reached the "
                "whole field",
                "hypers": r["hypers"],
            }
            for i, r in enumerate(least)
        ),
    ]
    base = hyper.defaults(11)  # the default of config versions 10-11, the control
    recipes = [{**c, "hypers": {**base, **c["hypers"], "actor_target_bound": BOUND}} for c in chosen]
    varied = [n for n in KNOBS if len({r["hypers"][n] for r in recipes}) > 1]
    train = {f"{n}_grid": [r["hypers"][n] for r in recipes] for n in varied}
    train.update(
        zip_grids=True, seeds=NETWORKS, trials=TRIALS, chunk_steps=CHUNK, seed=SEED,
        conditions=["none", "viscous", "random", "random_nopast"],
    )  # fmt: skip
    config = {"learner": {"actor_target_bound": BOUND}, "task": {"max_trial_time": CAP}, "train": train}
    command = f"python studies/collapse/design.py --stage1 {args.stage1} --design {args.design} --pick {args.pick} "
    command += f"--out {args.out}"
    out = {"command": command, "recipes": recipes}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{args.out}.json").write_text(json.dumps(out, indent=1) + "\n")
    Path(f"{args.out}_config.json").write_text(json.dumps(config, indent=1) + "\n")
    for r in recipes:
        print(r["source"], "|", hyper.describe(r["hypers"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
