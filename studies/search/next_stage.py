"""The next stage's recipes and training config, picked from a stage's ranking by the rule of studies/search/PLAN.md.

    python studies/search/next_stage.py studies/search/stage1_ranking.json --design studies/search/stage1.json \
        --best 4 --with-default --seeds 4 --out studies/search/stage2
    python studies/search/next_stage.py studies/search/stage2_ranking.json --design studies/search/stage2.json \
        --best 1 --seeds 8 --out studies/search/stage3

Reads the ranking (`objective.py --out`) and the design whose recipes the ranked run trained (stage 1's draws, or a
file this script wrote); writes OUT.json (the recipes, best first, with their ranks) and OUT_config.json (the
training config: zipped grids, the default first when asked). With --best 1 and no --with-default it is the pick:
the best draw, unless the default ranks above every draw, which ends the round (exit status 3, no files written).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from reach_jax.config import hyper

ROUND_DEFAULTS = hyper.defaults(8)  # the default recipe while the rounds ran: config version 8, before round 4's pick

SCRIPT = "studies/search/next_stage.py"
ROUND_ENDS = 3  # exit status when the default outranks every draw (PLAN.md, stage 2's rule)


def design_recipes(design: dict) -> list[dict[str, float]]:
    """The recipes of a design in batch order: stage 1's default then its draws, or a written stage's recipes."""
    if "draws" in design:
        space = [s["name"] for s in design["space"]]
        return [{n: ROUND_DEFAULTS[n] for n in space}, *(d["hypers"] for d in design["draws"])]
    return [r["hypers"] for r in design["recipes"]]


def value_in_label(label: dict[str, float], name: str) -> float:
    """A hyperparameter's value in a recipe label (`hyper.label` leaves out those at their neutral value)."""
    return float(label[name]) if name in label else float(hyper.BY_NAME[name].neutral)


def match(label: dict[str, float], recipes: list[dict[str, float]]) -> int:
    """The index of the design recipe that a ranked recipe's label (values read back as float32) names."""
    same = [
        k
        for k, r in enumerate(recipes)
        if all(np.float32(value_in_label(label, n)) == np.float32(v) for n, v in r.items())
    ]
    if len(same) != 1:
        raise ValueError(f"{len(same)} design recipes match the ranked recipe {label}")
    return same[0]


def pick(ranking: dict, recipes: list[dict[str, float]], best: int) -> tuple[list[dict], int | None]:
    """The best `best` draws (the default left out), each {"rank", "D", "hypers"}, and the default's rank or None."""
    chosen, default_rank = [], None
    for place, rec in enumerate(ranking["ranked"], start=1):
        recipe = recipes[match(rec["hypers"], recipes)]
        if not hyper.changed(recipe, ROUND_DEFAULTS):
            default_rank = place
        elif len(chosen) < best:
            chosen.append({"rank": place, "D": rec["D"], "hypers": recipe})
    return chosen, default_rank


def training_config(recipes: list[dict[str, float]], seeds: int) -> dict:
    """A --config training the recipes point by point (`train.zip_grids`) on every condition, `seeds` networks each."""
    names = list(recipes[0])
    return {"train": {"zip_grids": True, "seeds": seeds, **{f"{n}_grid": [r[n] for r in recipes] for n in names}}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("ranking", type=Path, help="a stage's ranking, objective.py's OUT.json")
    p.add_argument("--design", type=Path, required=True, help="the design of the ranked run (its recipes in order)")
    p.add_argument("--best", type=int, required=True, help="how many draws to carry on")
    p.add_argument("--seeds", type=int, required=True, help="networks per condition and recipe in the next stage")
    p.add_argument("--with-default", action="store_true", help="train the default too, as recipe 0")
    p.add_argument("--out", type=Path, required=True, help="output stem: writes OUT.json and OUT_config.json")
    args = p.parse_args(argv)
    ranking = json.loads(args.ranking.read_text())
    recipes = design_recipes(json.loads(args.design.read_text()))
    chosen, default_rank = pick(ranking, recipes, args.best)
    if not args.with_default and default_rank is not None and default_rank < chosen[0]["rank"]:
        print(f"the default ranks {default_rank}, above every draw: the round ends and the default stays")
        return ROUND_ENDS
    stage = [{"source": "the default", "hypers": {n: ROUND_DEFAULTS[n] for n in recipes[0]}}] * bool(args.with_default)
    stage += [{"source": f"rank {c['rank']} of {args.ranking} (D {c['D']:.1f})", "hypers": c["hypers"]} for c in chosen]
    command = f"python {SCRIPT} " + " ".join(sys.argv[1:] if argv is None else argv)
    written = {"command": command, "seeds": args.seeds, "default_rank": default_rank, "recipes": stage}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{args.out}.json").write_text(json.dumps(written, indent=1) + "\n")
    config = training_config([r["hypers"] for r in stage], args.seeds)
    Path(f"{args.out}_config.json").write_text(json.dumps(config, indent=1) + "\n")
    print(f"wrote {args.out}.json and {args.out}_config.json: {len(stage)} recipes x {args.seeds} networks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
