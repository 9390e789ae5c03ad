"""Stage 1's draws: a scrambled Sobol design over the search space of studies/search/PLAN.md, as a --config file.

    python studies/search/design.py --out studies/search/stage1

Writes OUT.json (the space, the generator's seed and every draw, unit-cube coordinates beside the values) and
OUT_config.json, the training config: the default recipe first, then the draws, paired point by point
(`train.zip_grids`) on every learning condition, one network each.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from reach_jax.config import hyper

ROUND_DEFAULTS = hyper.defaults(8)  # the default recipe while the rounds ran: config version 8, before round 4's pick

SCRIPT = "studies/search/design.py"

# (hyperparameter, low, high, scale): the space fixed in PLAN.md. "log" draws log(value) uniformly; "log1m" draws
# log(1 - value) uniformly (lambda: its horizon 1 / (1 - lambda) on a log scale).
SPACE = (
    ("lr", 0.5, 2.0, "log"),
    ("noise", 0.15, 0.3, "linear"),
    ("noise_final_ratio", 0.4, 1.0, "linear"),
    ("noise_anneal_delay", 0, 1_000_000, "linear"),
    ("noise_value_ratio", 0.25, 1.0, "linear"),
    ("actor_signal_gain", 0.25, 1.0, "log"),
    ("noise_corr", 0.0, 0.8, "linear"),
    ("lam", 0.99, 0.999, "log1m"),
    ("drift_gate", 0.0, 0.5, "linear"),
)
DRAWS = 32  # a power of two keeps the Sobol sequence balanced
DESIGN_SEED = 38  # the scrambling's seed: the number, fixed in PLAN.md
SIGNIFICANT = 3  # values are rounded to this many significant digits, so that recipe labels stay readable


def value(u: float, low: float, high: float, scale: str, integer: bool) -> float:
    """The hyperparameter value at unit coordinate u of [low, high] on its scale."""
    if scale == "log":
        v = math.exp(math.log(low) + u * (math.log(high) - math.log(low)))
    elif scale == "log1m":
        v = 1.0 - math.exp(math.log(1.0 - low) + u * (math.log(1.0 - high) - math.log(1.0 - low)))
    else:
        v = low + u * (high - low)
    if integer:
        return int(round(v, -3))  # whole thousands of trials
    return float(f"{v:.{SIGNIFICANT}g}") if scale != "log1m" else round(v, 5)


def draws(n: int = DRAWS, seed: int = DESIGN_SEED) -> tuple[np.ndarray, list[dict[str, float]]]:
    """(n, d) unit-cube points of the scrambled Sobol sequence and the recipes they map to."""
    unit = qmc.Sobol(d=len(SPACE), scramble=True, seed=seed).random(n)
    recipes = [
        {
            name: value(u, lo, hi, scale, hyper.BY_NAME[name].integer)
            for u, (name, lo, hi, scale) in zip(row, SPACE, strict=True)
        }
        for row in unit
    ]
    return unit, recipes


def training_config(recipes: list[dict[str, float]]) -> dict:
    """The --config of stage 1: the default recipe, then the draws, zipped, on every condition, one network each."""
    points = [{name: ROUND_DEFAULTS[name] for name, *_ in SPACE}, *recipes]
    grids = {f"{name}_grid": [p[name] for p in points] for name, *_ in SPACE}
    return {"train": {"zip_grids": True, "seeds": 1, **grids}}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="output stem: writes OUT.json and OUT_config.json")
    args = p.parse_args(argv)
    unit, recipes = draws()
    space = [{"name": n, "low": lo, "high": hi, "scale": s} for n, lo, hi, s in SPACE]
    design = {
        "command": f"python {SCRIPT} --out {args.out}",
        "generator": "scipy.stats.qmc.Sobol(scramble=True)",
        "seed": DESIGN_SEED,
        "space": space,
        "draws": [
            {"unit": [round(float(u), 6) for u in row], "hypers": r} for row, r in zip(unit, recipes, strict=True)
        ],
        "recipe_0": "the default (every knob at its default), then draw k as recipe k + 1",
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{args.out}.json").write_text(json.dumps(design, indent=1) + "\n")
    Path(f"{args.out}_config.json").write_text(json.dumps(training_config(recipes), indent=1) + "\n")


if __name__ == "__main__":
    main()
