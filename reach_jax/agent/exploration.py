"""The exploration noise rnd of eq. 2 (model §5): its bound's schedule, and the optional forms of it.

The paper says only that rnd is a random number. Our reading is rnd ~ U(-b, b) per step and joint, with b a
per-learner hyperparameter (`hyper.TABLE`). The optional forms below are off at their neutral values, where
the noise is b (2u - 1) exactly as before they existed:
- an anneal of b once the curriculum has reached the whole field (`schedule`);
- b scaled by the critic's value, smallest where it expects the goal, from the start or from the first full
  field, relaxed while the curriculum falls short of the whole field or once a trial runs long (`value_scale`);
- trials without noise, the correlated share included (`quiet`);
- AR(1) noise correlated from step to step, with the stationary spread of the white noise (`noise`);
- the actor's signal scaled up where the value scaling shrinks the noise, and by a constant actor-only gain g
  (`actor_gain`), departures from eq. 2.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config.hyper import Hyper


def schedule(h: Hyper, trials: jax.Array, full_at: jax.Array) -> jax.Array:
    """() bound b after `trials` trials: `noise`, then a linear anneal to noise * noise_final_ratio.

    The anneal starts `noise_anneal_delay` trials after the curriculum first reached the whole field and lasts
    `noise_anneal_trials` trials; before the field is first full there is no anneal, however long that takes.

    Args:
      h: the learner's hyperparameters.
      trials: () trials ended so far.
      full_at: () trial count when the curriculum first reached its maximum distance; negative before.
    """
    done = (trials - full_at - h.noise_anneal_delay) / jnp.maximum(h.noise_anneal_trials, 1.0)
    frac = jnp.where(full_at < 0, 0.0, jnp.clip(done, 0.0, 1.0))
    return h.noise * (1.0 + (h.noise_final_ratio - 1.0) * frac)


def value_scale(h: Hyper, p: jax.Array, full_at: jax.Array, shortfall: jax.Array = 0.0, t: jax.Array = 0) -> jax.Array:
    """() factor in [noise_value_ratio, 1] on the bound at a state whose critic value is p.

    1 where p <= noise_value_lo (far from the goal, or failing), noise_value_ratio where p >= noise_value_hi
    (the critic expects the goal soon), linear between; 1 everywhere before the curriculum first reached the
    whole field (full_at < 0) when noise_value_after_full is on. With noise_value_gate g > 0 the smallest
    factor rises linearly from noise_value_ratio at the whole field to 1 at a shortfall of g: a learner whose
    curriculum falls back explores with the whole bound again. With noise_value_steps n > 0 the factor is 1 from
    step n of a trial on: a hand held off the target, as by a constant force, is shaken loose.

    Args:
      h: the learner's hyperparameters.
      p: () the critic's value of the step's input.
      full_at: () trial count when the curriculum first reached the whole field; negative before.
      shortfall: () 1 - curriculum distance / the whole field's, in [0, 1).
      t: () steps taken in the trial before this one.
    """
    ratio = jnp.where((h.noise_value_after_full > 0) & (full_at < 0), 1.0, h.noise_value_ratio)
    gated = h.noise_value_gate > 0
    relax = jnp.where(gated, jnp.clip(shortfall / jnp.where(gated, h.noise_value_gate, 1.0), 0.0, 1.0), 0.0)
    relax = jnp.where((h.noise_value_steps > 0) & (t >= h.noise_value_steps), 1.0, relax)
    ratio = ratio + (1.0 - ratio) * relax
    far = jnp.clip((h.noise_value_hi - p) / (h.noise_value_hi - h.noise_value_lo), 0.0, 1.0)
    return ratio + (1.0 - ratio) * far


def actor_gain(h: Hyper, scale: jax.Array) -> jax.Array:
    """() factor on the actor's signal of a step explored at `value_scale` factor `scale`: g scale^-actor_gain_power.

    The expected actor step E[rnd dp] grows with the bound squared, so power 2 keeps the whole bound's expected step
    where the value scaling shrinks the noise, and power 1 the spread of the step's noise (model §5). g is the
    constant actor-only gain `actor_signal_gain`, which leaves the critic's step as it is. 1 at power 0 and g = 1.
    """
    on = (h.actor_gain_power > 0) & (scale > 0)
    return h.actor_signal_gain * jnp.where(on, jnp.where(on, scale, 1.0) ** -h.actor_gain_power, 1.0)


def quiet(h: Hyper, trials: jax.Array) -> jax.Array:
    """() bool: trial number `trials` (counted from 0) is one of the every-n-th trials run without noise."""
    every = jnp.maximum(h.quiet_every, 1.0)
    return (h.quiet_every > 0) & (jnp.mod(trials + 1, every) == 0)


def noise(unit: jax.Array, h: Hyper, trials: jax.Array, full_at: jax.Array, scale: jax.Array, prev: jax.Array):
    """(2,) rnd of this step, as (carried, fresh): rnd = carried + fresh.

    `carried` is the AR(1) share of the previous step's noise, `fresh` this step's draw. The actor adds them in
    that order (`network.torque(m + carried, fresh)`), which with white noise rounds as m + b (2u - 1) always did.

    Args:
      unit: (2,) this step's draws, uniform in [-1, 1).
      h: the learner's hyperparameters.
      trials: () trials ended before this one.
      full_at: () trial count when the curriculum first reached the whole field; negative before.
      scale: () `value_scale`'s factor on the bound at this step.
      prev: (2,) the previous step's rnd (0 at the start of training).
    """
    silent = quiet(h, trials)
    b = jnp.where(silent, 0.0, schedule(h, trials, full_at) * scale)
    # A bare product: with a select between rho * prev and the actor's m + carried, XLA:CPU contracted the two into
    # an FMA in some batch shapes and not in others, so a learner's bits depended on its batch. At rho = 0 both are m.
    return jnp.where(silent, 0.0, h.noise_corr) * prev, jnp.sqrt(1.0 - h.noise_corr**2) * b * unit
