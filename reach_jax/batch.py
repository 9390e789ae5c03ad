"""The batch of learners a run trains: who each one is (condition, seed, hyperparameters) and its first state.

A learner's place in the batch is fixed by the config: conditions, then sweep points, then seeds
(`learner_table`). Every array of a Batch has that learner axis first.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from reach_jax import rollout, task
from reach_jax.config import Config, TrainConfig


class Batch(NamedTuple):
    """Everything a chunk needs, learner axis first."""

    states: rollout.LearnerState
    conds: task.Condition
    hypers: rollout.Hyper


# rollout.Hyper field -> the TrainConfig grid that sweeps it (its default is the LearnerConfig field of that name).
HYPER_GRIDS = {
    "lr": "lr_grid",
    "noise": "noise_grid",
    "lam": "lam_grid",
    "noise_final_ratio": "noise_final_ratio_grid",
    "noise_anneal_delay": "noise_anneal_delay_grid",
    "noise_anneal_trials": "noise_anneal_trials_grid",
}


def hyper_grid(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameter combinations of a sweep, keyed like rollout.Hyper; the learner defaults when nothing is swept."""
    axes = [getattr(cfg.train, grid) or (getattr(cfg.learner, name),) for name, grid in HYPER_GRIDS.items()]
    return [dict(zip(HYPER_GRIDS, combo, strict=True)) for combo in itertools.product(*axes)]


def learner_hypers(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameters of every learner, aligned with learner_table."""
    return [h for _ in cfg.train.conditions for h in hyper_grid(cfg) for _ in range(cfg.train.seeds)]


def hyper_columns(cfg: Config) -> rollout.Hyper:
    """rollout.Hyper with one value per learner: (L,) arrays in batch order."""
    hypers = learner_hypers(cfg)
    return rollout.Hyper(**{name: jnp.asarray([float(h[name]) for h in hypers]) for name in HYPER_GRIDS})


def learner_table(train: TrainConfig) -> list[tuple[str, int]]:
    """(condition, seed index) of every learner, in batch order: condition, then sweep point, then seed."""
    n_grid = math.prod(max(len(getattr(train, grid)), 1) for grid in HYPER_GRIDS.values())
    return [(c, s) for c in train.conditions for _ in range(n_grid) for s in range(train.seeds)]


def learner_key(seed: int, index: int) -> jax.Array:
    """Key of seed index `index`; shared across conditions, so each seed starts from the same weights."""
    return jax.random.fold_in(jax.random.PRNGKey(seed), index)


def conditions(cfg: Config) -> task.Condition:
    """Every learner's condition, stacked in batch order."""
    return task.stack_conditions([c for c, _ in learner_table(cfg.train)], cfg)


def init_batch(cfg: Config) -> Batch:
    """Fresh learners for cfg.train's conditions x seeds."""
    table = learner_table(cfg.train)
    conds = conditions(cfg)
    keys = jnp.stack([learner_key(cfg.train.seed, s) for _, s in table])
    states = jax.vmap(lambda k, c: rollout.init_learner(k, c, cfg))(keys, conds)
    # Fresh buffers: init may alias leaves, which the donating chunk cannot accept.
    return Batch(*jax.tree.map(jnp.copy, (states, conds, hyper_columns(cfg))))
