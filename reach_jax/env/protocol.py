"""Protocols as per-learner data: blocks of trials, each in a condition, learning or not, with catch trials (model §12).

A learner's `Plan` holds every condition of the config's table, its blocks and its task geometry. At each trial
boundary the trial's condition is picked from the block that the trial index falls in; with the block's catch
probability the trial runs in the catch condition instead. A learner of a plain condition has a one-block plan, so
every learner of a batch runs the same compiled step whatever its protocol.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import BlockConfig, Config, blocks_of
from reach_jax.env import task

ENDLESS = 2**31 - 1  # end of the last block: a learner stays in it until its budget stops it


@struct.dataclass
class Plan:
    """One learner's protocol; B blocks (padded to the batch's longest protocol), C conditions."""

    conds: task.Condition  # every condition of the config's table, leading axis C
    ends: jax.Array  # (B,) int32 trial index at which each block ends (cumulative); the last is ENDLESS
    cond: jax.Array  # (B,) int32 index into `conds` of each block's condition
    catch_cond: jax.Array  # (B,) int32 index of each block's catch condition
    catch: jax.Array  # (B,) probability that a trial of the block is a catch trial
    learning: jax.Array  # (B,) bool: the block updates the weights
    geometry: task.Geometry  # where the learner's visual field sits, the same in every block


def _plan_arrays(blocks: tuple[BlockConfig, ...], n_blocks: int, cfg: Config) -> dict:
    names = [c.name for c in cfg.conditions]
    blocks = blocks + (blocks[-1],) * (n_blocks - len(blocks))  # padding repeats the last block
    ends, total = [], 0
    for i, b in enumerate(blocks):
        total += b.trials
        ends.append(ENDLESS if i >= n_blocks - 1 or total >= ENDLESS else total)
    return dict(
        ends=jnp.asarray(ends, jnp.int32),
        cond=jnp.asarray([names.index(b.condition) for b in blocks], jnp.int32),
        catch_cond=jnp.asarray([names.index(b.catch_condition) for b in blocks], jnp.int32),
        catch=jnp.asarray([b.catch for b in blocks], jnp.float32),
        learning=jnp.asarray([b.learning for b in blocks]),
    )


def make_plan(name: str, cfg: Config, n_blocks: int | None = None) -> Plan:
    """Plan of a protocol or a condition (one block) of the config, padded to n_blocks (default its own), in the
    geometry of the config's sensor (a learner's own: `task.learner_sensor`, in the config it returns)."""
    blocks = blocks_of(cfg, name)
    table = task.stack_conditions([c.name for c in cfg.conditions], cfg)
    return Plan(conds=table, geometry=task.geometry(cfg), **_plan_arrays(blocks, n_blocks or len(blocks), cfg))


def stack_plans(names, cfgs: list[Config]) -> Plan:
    """Batch of plans (leading axis = learner) for a list of protocol or condition names, each in its learner's
    config (the run's, with the learner's sensor, `task.learner_sensor`)."""
    n_blocks = max(len(blocks_of(cfg, n)) for n, cfg in zip(names, cfgs, strict=True))
    plans = [make_plan(n, cfg, n_blocks) for n, cfg in zip(names, cfgs, strict=True)]
    return jax.tree.map(lambda *xs: jnp.stack(xs), *plans)


@struct.dataclass
class BlockState:
    """A trial's place in its learner's protocol."""

    index: jax.Array  # () int32 the block the trial runs in
    learning: jax.Array  # () bool: the block updates the weights
    catch: jax.Array  # () bool: the trial is a catch trial


def block_index(plan: Plan, trial: jax.Array) -> jax.Array:
    """() int32 block that trial index `trial` (0-based, counted over the learner's life) belongs to."""
    return jnp.minimum(jnp.sum(trial >= plan.ends), plan.ends.shape[0] - 1).astype(jnp.int32)


def trial_condition(plan: Plan, trial: jax.Array, catch_draw: jax.Array):
    """The condition a trial runs in.

    Args:
      plan: the learner's plan.
      trial: () int32 index of the trial.
      catch_draw: () uniform draw in [0, 1) of the trial (`task.TrialDraws.catch`).

    Returns:
      (task.Condition, BlockState).
    """
    block = block_index(plan, trial)
    catch = catch_draw < plan.catch[block]
    index = jnp.where(catch, plan.catch_cond[block], plan.cond[block])
    cond = jax.tree.map(lambda a: a[index], plan.conds)
    return cond, BlockState(index=block, learning=plan.learning[block], catch=catch)
