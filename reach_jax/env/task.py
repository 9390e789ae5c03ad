"""The reaching task: conditions, its geometry, trial sampling and placement, goal test and target drift (model §2,
§5, §6).

Units: positions and distances [m], speeds [m/s], forces [N], time [s]; fields are `fields.Field` data.
A learner's geometry (`Geometry`: where its visual field sits, its cell, and the lengths counted in cells) is data,
so that one batch trains several geometries; the config's sensor, moved and scaled by the learner's hyperparameters
`sensor_dx`, `sensor_dy` and `sensor_scale`, gives it.
Randomness enters only through uniform draws in [0, 1) (`TrialDraws`), so a NumPy oracle can replay a run.
The curriculum distance (`curriculum`) bounds the start-target offset in each axis (an L-inf box).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import Config, SensorConfig, condition, workspace
from reach_jax.physics import arm, encoding, fields, sensor


@struct.dataclass
class Condition:
    """One learner's environment and inputs: per-learner data, never a Python branch."""

    field: fields.Field  # the hand-force field
    input_mask: jax.Array  # (125,) 1 keeps an input, 0 withholds it


def make_condition(name: str, cfg: Config) -> Condition:
    """Condition of the config's conditions table called `name` (the paper's: none, viscous, random, random_nopast)."""
    spec = condition(cfg, name)
    return Condition(field=fields.make_field(spec), input_mask=encoding.input_mask(spec.past_inputs, cfg))


def stack_conditions(names, cfg: Config) -> Condition:
    """Batch of conditions (leading axis = learner) for a list of names."""
    conds = [make_condition(n, cfg) for n in names]
    return jax.tree.map(lambda *xs: jnp.stack(xs), *conds)


@struct.dataclass
class Geometry:
    """One learner's task geometry: its visual field, and the lengths counted in its cells (model §2, §5)."""

    sensor: sensor.Placement  # where the visual field sits, and its cell
    goal_half: jax.Array  # () half side of the goal square [m]
    start_distance: jax.Array  # () initial and smallest curriculum distance [m]
    full_distance: jax.Array  # () the curriculum distance that spans the whole field [m]
    inv_full_distance: jax.Array  # () its float32 reciprocal [1/m]: a fraction of it is a product, as XLA made the
    # division by a constant


def learner_sensor(cfg: Config, values: dict) -> SensorConfig:
    """The sensor of a learner whose hyperparameters are `values` (name -> value, `hyper.Hyper`'s names)."""
    return workspace.moved_sensor(cfg.sensor, *(values[name] for name in workspace.GEOMETRY_HYPERS))


def geometry(cfg: Config) -> Geometry:
    """The geometry of the config's sensor as data, each length rounded once from float64 as a constant would be."""
    cell = cfg.sensor.cell_size
    lengths = (cfg.task.goal_half_width_cells * cell, cfg.task.curriculum_init_cells * cell, cfg.sensor.n_cells * cell)
    goal_half, start, full = (jnp.asarray(v, dtype=float) for v in lengths)
    return Geometry(
        sensor=sensor.placement(cfg.sensor),
        goal_half=goal_half,
        start_distance=start,
        full_distance=full,
        inv_full_distance=1.0 / full,
    )


class TrialDraws(NamedTuple):
    """Uniform [0, 1) draws that fix a new trial."""

    start: jax.Array  # (2,) start position within the field
    target: jax.Array  # (K, 2) candidate targets within the curriculum box
    force: jax.Array  # (2,) constant force
    catch: jax.Array  # () whether the trial is a catch trial (`protocol.trial_condition`)


def draw_trial(key: jax.Array, cfg: Config) -> TrialDraws:
    """Fresh uniform draws for one trial."""
    k1, k2, k3 = jax.random.split(key, 3)
    last = jax.random.uniform(k3, (3,))  # the force's two draws are those of a (2,) draw: runs before catch trials
    return TrialDraws(
        start=jax.random.uniform(k1, (2,)),
        target=jax.random.uniform(k2, (cfg.task.target_candidates, 2)),
        force=last[:2],
        catch=last[2],
    )


def goal_half_width(cfg: Config) -> float:
    """Half side of the goal square around the target [m], for the config's sensor."""
    return cfg.task.goal_half_width_cells * cfg.sensor.cell_size


def touching(hand: jax.Array, target: jax.Array, goal_half: jax.Array | float) -> jax.Array:
    """True when the hand centre lies inside the goal square (side 2 cells, half side `goal_half` [m]) of the target."""
    return jnp.all(jnp.abs(hand - target) < goal_half, axis=-1)


def goal_reached(hand: jax.Array, hand_vel: jax.Array, target: jax.Array, geom: Geometry, cfg: Config) -> jax.Array:
    """Goal of section 4.2: the hand touches the target and its speed is below cfg.task.goal_speed."""
    return touching(hand, target, geom.goal_half) & (jnp.linalg.norm(hand_vel) < cfg.task.goal_speed)


def place_trial(draws: TrialDraws, distance: jax.Array, field: fields.Field, geom: Geometry, cfg: Config):
    """Start state, target and force of a new trial.

    The start is uniform over the field. Each target candidate is uniform over the field intersected
    with the box of half side `distance` around the start; the first that the hand does not already
    touch is taken (the last one if all do).

    Args:
      draws: uniform draws of the trial.
      distance: () curriculum distance [m].
      field: the learner's field, which bounds the trial's random force.
      geom: the learner's geometry: its visual field and goal square.
      cfg: model config.

    Returns:
      ((4,) start arm state at rest, (2,) target [m], (2,) the trial's random force [N]).
    """
    lo, hi = geom.sensor.lo, geom.sensor.hi
    start = lo + draws.start * (hi - lo)
    box_lo = jnp.maximum(lo, start - distance)
    box_hi = jnp.minimum(hi, start + distance)
    candidates = box_lo + draws.target * (box_hi - box_lo)
    ok = ~touching(start, candidates, geom.goal_half)
    first = jnp.where(jnp.any(ok), jnp.argmax(ok), cfg.task.target_candidates - 1)
    target = candidates[first]
    state = jnp.concatenate([arm.inverse_kinematics(start, cfg.arm), jnp.zeros(2)])
    force = fields.trial_force(field, draws.force)
    return state, target, force


def drift_target(target: jax.Array, hand: jax.Array, step_in_trial: jax.Array, cfg: Config, gate=True):
    """Move the target toward the hand once the trial has lasted cfg.task.drift_after, if the drift gate is open.

    Args:
      target: (2,) [m].
      hand: (2,) [m].
      step_in_trial: () steps the trial has taken.
      cfg: model config.
      gate: () bool, the learner's drift gate is open (`curriculum.drift_open`).

    Returns:
      ((2,) new target [m], () bool whether it moved).
    """
    moving = (step_in_trial * cfg.arm.dt >= cfg.task.drift_after) & gate
    gap = hand - target
    dist = jnp.linalg.norm(gap)
    move = jnp.minimum(cfg.task.drift_per_step, dist)
    shifted = target + gap * (move / jnp.maximum(dist, 1e-12))
    moved = moving & (dist > 0)
    return jnp.where(moved, shifted, target), moved


def observe(state, prev_state, prev_tau, target, mask, geom: Geometry, cfg: Config) -> jax.Array:
    """Masked (125,) network input from the arm, its previous step and the target, seen by `geom`'s visual field."""
    visual = sensor.render(arm.hand_position(state[:2], cfg.arm), target, geom.sensor, cfg.sensor.n_cells)
    return encoding.encode(visual, state, prev_state, prev_tau, cfg) * mask
