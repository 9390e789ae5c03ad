"""The batch of learners a run trains: who each one is (condition, seed, hyperparameters) and its first state.

A learner's place in the batch is fixed by the config: conditions, then sweep points, then seeds
(`learner_table`). Every array of a Batch has that learner axis first.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from reach_jax.config import Config, TrainConfig, blocks_of, hyper
from reach_jax.engine import learner_state
from reach_jax.env import curriculum, protocol, task


class Batch(NamedTuple):
    """Everything a chunk needs, learner axis first."""

    states: learner_state.LearnerState
    conds: task.Condition  # the condition each learner ends in: its own, or its protocol's last block's
    hypers: hyper.Hyper
    plans: protocol.Plan  # what each learner runs, trial by trial


def hyper_grid(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameter combinations of a sweep, keyed like hyper.Hyper; the learner defaults when nothing is swept.

    The grids are crossed, or with `train.zip_grids` paired point by point (a grid left empty repeats the default).
    """
    n = n_sweep_points(cfg.train)
    if cfg.train.zip_grids:
        axes = [getattr(cfg.train, h.grid) or (getattr(cfg.learner, h.name),) * n for h in hyper.TABLE]
        return [dict(zip(hyper.NAMES, combo, strict=True)) for combo in zip(*axes, strict=True)]
    axes = [getattr(cfg.train, h.grid) or (getattr(cfg.learner, h.name),) for h in hyper.TABLE]
    return [dict(zip(hyper.NAMES, combo, strict=True)) for combo in itertools.product(*axes)]


def n_sweep_points(train: TrainConfig) -> int:
    """Recipes of a sweep: the grids' lengths multiplied, or with `zip_grids` the common length (1 without grids)."""
    lengths = [len(getattr(train, h.grid)) for h in hyper.TABLE if getattr(train, h.grid)]
    if train.zip_grids:
        return max(lengths, default=1)
    return math.prod(lengths)


def learner_hypers(cfg: Config) -> list[dict[str, float]]:
    """Hyperparameters of every learner, aligned with learner_table."""
    return [h for _ in learner_names(cfg.train) for h in hyper_grid(cfg) for _ in range(cfg.train.seeds)]


def learner_names(train: TrainConfig) -> tuple[str, ...]:
    """The conditions, then the protocols, that learners run."""
    return train.conditions + train.protocols


def hyper_columns(cfg: Config) -> hyper.Hyper:
    """hyper.Hyper with one value per learner: (L,) arrays in batch order."""
    hypers = learner_hypers(cfg)
    return hyper.Hyper(**{name: jnp.asarray([float(h[name]) for h in hypers]) for name in hyper.NAMES})


def learner_table(train: TrainConfig) -> list[tuple[str, int]]:
    """(condition or protocol, seed index) of every learner, in batch order: name, then sweep point, then seed."""
    n_grid = n_sweep_points(train)
    return [(c, s) for c in learner_names(train) for _ in range(n_grid) for s in range(train.seeds)]


def learner_key(seed: int, index: int) -> jax.Array:
    """Key of seed index `index`; shared across conditions, so each seed starts from the same weights."""
    return jax.random.fold_in(jax.random.PRNGKey(seed), index)


def conditions(cfg: Config) -> task.Condition:
    """Every learner's final condition (its protocol's last block's), stacked in batch order."""
    return task.stack_conditions([blocks_of(cfg, c)[-1].condition for c, _ in learner_table(cfg.train)], cfg)


def learner_configs(cfg: Config) -> list[Config]:
    """Every learner's config in batch order: the run's, with the learner's own sensor (`task.learner_sensor`)."""
    sensors = [task.learner_sensor(cfg, h) for h in learner_hypers(cfg)]
    by_sensor = {s: dataclasses.replace(cfg, sensor=s) for s in dict.fromkeys(sensors)}
    return [by_sensor[s] for s in sensors]


def plans(cfg: Config) -> protocol.Plan:
    """Every learner's plan, in its own geometry, stacked in batch order."""
    return protocol.stack_plans([c for c, _ in learner_table(cfg.train)], learner_configs(cfg))


def fresh_states(cfg: Config, plan: protocol.Plan | None = None) -> learner_state.LearnerState:
    """Every learner's first state, learner axis first: compiled as one program, bit for bit what runs begun before
    that got op by op (tests/test_train.py), and seconds sooner.

    Args:
      cfg: the run's config.
      plan: `plans(cfg)`, when the caller has it.
    """
    keys = jnp.stack([learner_key(cfg.train.seed, s) for _, s in learner_table(cfg.train)])
    return _init_learners(keys, plans(cfg) if plan is None else plan, cfg)


@functools.partial(jax.jit, static_argnames="cfg")
def _init_learners(keys: jax.Array, plan: protocol.Plan, cfg: Config) -> learner_state.LearnerState:
    """`learner_state.init_learner` of every learner: keys (L, 2) and plan's leaves learner axis first."""
    return jax.vmap(lambda k, p: learner_state.init_learner(k, p, cfg))(keys, plan)


def init_batch(cfg: Config) -> Batch:
    """Fresh learners for cfg.train's conditions and protocols x seeds."""
    plan = plans(cfg)
    # Fresh buffers: init may alias leaves, which the donating chunk cannot accept.
    return Batch(*jax.tree.map(jnp.copy, (fresh_states(cfg, plan), conditions(cfg), hyper_columns(cfg), plan)))


def source_indices(source_table: list[tuple[str, int]], cfg: Config) -> list[int]:
    """Index in the source run (train.init_from) of each learner's starting network; ValueError if one is missing."""
    picks = []
    for name, seed in learner_table(cfg.train):
        wanted = (blocks_of(cfg, name)[0].condition, seed)
        if wanted not in source_table:
            raise ValueError(
                f"train.init_from: {cfg.train.init_from} has no network of condition {wanted[0]} and seed {seed}"
            )
        picks.append(source_table.index(wanted))
    return picks


def start_from(states: learner_state.LearnerState, source, source_table: list[tuple[str, int]], cfg: Config):
    """Fresh learner states that take the trained networks of another run (train.init_from, model §12).

    Learner (name, seed) takes the network of the source's learner with the same seed index in the condition of
    its first block (the first such learner of a sweep): its weights, N_max, curriculum distance and recent failure
    share (the drift gate's measure). Its trials, steps, key and first trial stay its own.

    Args:
      states: fresh states, learner axis first (`init_batch`).
      source: the source run's LearnerState at its last checkpoint, learner axis first.
      source_table: the source's (condition, seed index) per learner.
      cfg: this run's config.
    """
    picks = source_indices(source_table, cfg)
    taken = jax.tree.map(lambda a: jnp.asarray(a)[jnp.asarray(picks)], source)
    cur = curriculum.Curriculum(
        distance=taken.env.curriculum.distance,
        full_at=jnp.where(taken.env.curriculum.full_at >= 0, 0, -1).astype(jnp.int32),
        failure=taken.env.curriculum.failure,
    )
    return states.replace(
        agent=states.agent.replace(params=jax.tree.map(jnp.copy, taken.agent.params), n_max=taken.agent.n_max),
        env=states.env.replace(curriculum=cur),
    )
