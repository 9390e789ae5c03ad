"""The claims of each recipe from the evaluation's results, with its impedance cells; gains [N/m], [N s/m].

The glue between the measures (`lattice`, `pulls`, `impedance`) and the verdicts (`claims`, `stats`): both the
full evaluation and `redecide` (from the committed eval/ files) decide through `decide`.
"""

from __future__ import annotations

from reach_jax.config import Config
from reach_jax.evaluate import claims, collapse, plausibility, pulls, stats
from reach_jax.train.health import is_setback, tail_rows


def impedance_cells(summary: dict, nets: list[int], level: float) -> list[dict]:
    """Mean over networks (with its interval) of each network's median gains, per learning x test cell.

    The interval is on the log scale where every network's gain is positive, else plain (`stats.positive_ci`).

    Args:
      summary: `impedance.summarize` results.
      nets: the networks to pool (indices into the learner table).
      level: confidence level of the t-intervals.
    """
    rows = [r for r in summary["per_network"] if r["learner"] in nets]
    names = [k for k in rows[0] if k.startswith(("stiffness_", "damping_", "passive_")) and "per_m" not in k]
    cells = []
    for learning, test in dict.fromkeys((r["learning"], r["test"]) for r in rows):
        sub = [r for r in rows if r["learning"] == learning and r["test"] == test and r["states"] > 0]
        cells.append(
            {
                "learning": learning,
                "test": test,
                **{n: stats.positive_ci([r[n]["median"] for r in sub], level) for n in names},
            }
        )
    return cells


def decide(
    table: dict, per_seed: list[dict], imp: dict, recipes: list[dict], recipe_of: list[int], metrics: list[dict], cfg
) -> list[dict]:
    """The claims of each recipe, from the Table-2 counts, the after-effect per seed, the impedance and the metrics.

    Args:
      table: `lattice.table2` results (its per-network counts).
      per_seed: the after-effect measures per (recipe, seed) (`pulls.aftereffect`).
      imp: `impedance.summarize` results, each per-network row with its recipe.
      recipes: each recipe's hyperparameters (`lattice.recipe_index`).
      recipe_of: (N,) recipe index per network.
      metrics: the run's metrics.jsonl rows up to the evaluated checkpoint.
      cfg: model config.
    """
    level = cfg.claims.level
    verdicts = []
    for k, hypers in enumerate(recipes):
        nets = [i for i in range(len(recipe_of)) if recipe_of[i] == k]
        rows = [r for r in table["per_network"] if r["recipe"] == k]
        cells = claims.Cells(rows, table["pairs_per_network"])
        after_k = pulls.pool_aftereffect([a for a in per_seed if a["recipe"] == k], level)
        collapsed = collapse.of_table(table, cfg, recipe=k)
        table_cells = claims.table_cells(cells, cfg.claims)
        verdicts.append(
            {
                "hypers": hypers,
                "level": level,
                "informative_networks": cfg.claims.informative_networks,
                "networks_per_condition": cfg.train.seeds,
                "claims": [collapse.with_collapsed(c, collapsed) for c in claims.recipe_claims(cells, after_k, cfg)],
                "collapsed": collapsed,
                "collapse_success": cfg.claims.collapse_success,
                "aftereffect": after_k,
                "cells": table_cells,
                "D": plausibility.distance(table_cells),
                "plausibility": plausibility.judge(table_cells, level),
                "impedance": impedance_cells(imp, nets, level),
                "curriculum": curriculum_stability(metrics, nets, cfg.train.trials, cfg),
            }
        )
    return verdicts


def curriculum_stability(metrics: list[dict], learners: list[int], trials: int, cfg: Config) -> dict:
    """Setbacks of the curriculum in the last cfg.claims.curriculum_tail of each learner's trials.

    A chunk counts when the learner ended at least one trial in it and its trial count lies in the tail; it is a
    setback when the curriculum distance is below curriculum_min_fraction of the whole field.
    """
    c = cfg.claims
    per = []
    for i in learners:
        rows = tail_rows([r for r in metrics if r["learner"] == i], trials, c.curriculum_tail)
        setbacks = sum(is_setback(r, cfg) for r in rows)
        fraction = setbacks / len(rows) if rows else None
        per.append(
            {
                "learner": i,
                "tail_chunks": len(rows),
                "setback_chunks": setbacks,
                "setback_fraction": fraction,
                "stable": fraction is not None and fraction <= c.curriculum_max_setbacks,
            }
        )
    judged = [p for p in per if p["tail_chunks"]]
    return {
        "learners": per,
        "judged": len(judged),
        "all_stable": bool(per) and len(judged) == len(per) and all(p["stable"] for p in per),
    }
