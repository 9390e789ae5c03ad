"""TS actor-critic learning: targets of eq. 1-2, N_max of eq. 3, and one backprop update (model §5).

Units: critic and actor values are network outputs in (-0.5, 0.5); N_max and trial lengths are steps.
The update for the transition x(t-1) -> x(t) runs at step t, once p(t) is known. A trial's last
transition is updated at the first step of the next trial, so every step does exactly one backprop.

Hot-path economy: the layer-1 pre-activation of x(t-1) under W(t) is carried in `Pending.u1` instead of
being recomputed. At step t-1 the forward pass computed u1 = x(t-1) W1(t-1) + b1(t-1); the only change
since is the rank-1 SGD step W1 -= lr x(t-2) delta1^T, b1 -= lr delta1, so
u1 under W(t) = u1 - lr delta1 (x(t-2) . x(t-1) + 1). The biggest matrix product then runs once a step.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from reach_jax.agent import network
from reach_jax.config import Config, LearnerConfig


class Pending(NamedTuple):
    """The previous step, waiting for its TS update."""

    x: jax.Array  # (125,) masked input at t-1
    out: jax.Array  # (3,) outputs [p, m1, m2] at t-1, as used to act
    rnd: jax.Array  # (2,) exploration noise added at t-1
    valid: jax.Array  # () bool: False at the first step of a run or after a capped trial
    terminal: jax.Array  # () bool: the transition ended its trial at the goal or a limit
    reward: jax.Array  # () reinforcement that ended the trial, 0 otherwise
    u1: jax.Array | None = None  # (hidden,) layer-1 pre-activation of x under the current weights; None: recompute
    gain: jax.Array | float = 1.0  # () factor on the actor's signal for this step (`exploration.actor_gain`)


def empty_pending(n_in: int, n_hidden: int | None = None) -> Pending:
    """A Pending that triggers no update.

    Args:
      n_in: number of network inputs (125).
      n_hidden: width of the first hidden layer (30); None leaves `u1` unset (recomputed when needed).
    """
    return Pending(
        x=jnp.zeros(n_in),
        out=jnp.zeros(3),
        rnd=jnp.zeros(2),
        valid=jnp.array(False),
        terminal=jnp.array(False),
        reward=jnp.zeros((), float),  # strong-typed, as the step (and the native kernel) returns it
        u1=None if n_hidden is None else jnp.zeros(n_hidden),
        gain=jnp.ones(()),  # strong-typed, as the chunk returns it
    )


def ts_targets(
    pending: Pending,
    p_now: jax.Array,
    n_max: jax.Array,
    cfg: LearnerConfig,
    baseline: jax.Array = 0.0,
    bound: jax.Array = 0.0,
) -> jax.Array:
    """Training signal (3,) for the input x(t-1), from eq. 1 (critic) and eq. 2 (actor).

    At a trial's end the reinforcement stands in for p(t). Non-terminal critic targets are floored at
    cfg.critic_floor, above the out penalty, so crossing a joint limit always lowers the value (anti-collapse
    guard; docs/model.md §11, "critic floor").

    Args:
      pending: the step t-1.
      p_now: () critic output p(t).
      n_max: () N_max [steps].
      cfg: learner constants.
      baseline: () share of P_range/N_max taken from dp in the actor's signal (hyper `actor_baseline`): 0 is
        eq. 2 as written, 1 the TD error of eq. 1 (a departure from the paper, model §5).
      bound: () the actor's targets clipped to [-bound, bound] when it is positive (hyper `actor_target_bound`);
        0 is eq. 2 as written.
    """
    p_next = jnp.where(pending.terminal, pending.reward, p_now)
    step_cost = cfg.p_range / n_max
    critic = p_next - step_cost
    critic = jnp.where(pending.terminal, critic, jnp.maximum(critic, cfg.critic_floor))
    actor = pending.out[1:] + pending.rnd * pending.gain * (p_next - pending.out[0] - baseline * step_cost)
    actor = jnp.where(bound > 0, jnp.clip(actor, -bound, bound), actor)
    return jnp.concatenate([critic[None], actor])


def update_n_max(n_max: jax.Array, n_steps: jax.Array, lam: jax.Array) -> jax.Array:
    """Eq. 3 after a trial that reached the goal in n_steps."""
    return jnp.where(n_steps > lam * n_max, n_steps.astype(n_max.dtype), lam * n_max)


def _squash_slope(y: jax.Array) -> jax.Array:
    """f'(u) written through y = f(u): (0.5 + y)(0.5 - y), as in the oracle."""
    return (0.5 + y) * (0.5 - y)


def _layer1_input_product(x: jax.Array, w1: jax.Array, rows: jax.Array | None, n_visual: int) -> jax.Array:
    """x @ w1 (30,), reading only the visual rows and the coded `rows` when they are given."""
    # Per-learner matrix-vector product as multiply-and-reduce: under vmap XLA fuses it into one loop
    # instead of a batched dot with a tiny matrix per learner.
    if rows is None:
        return jnp.sum(x[:, None] * w1, axis=0)
    total = jnp.sum(x[:n_visual, None] * w1[:n_visual], axis=0)
    # A chain of adds, not a reduction over the gathered rows: XLA:CPU rounds such a reduction differently
    # for one learner per device than for several, and sharded runs must equal unsharded ones bit for bit.
    xs, ws = x[rows], w1[rows]
    for k in range(rows.shape[0]):
        total = total + xs[k] * ws[k]
    return total


def _layer1_sgd(w1: jax.Array, x: jax.Array, scaled: jax.Array):
    """w1 - outer(x, scaled) over every row.

    The rows where x is 0 come out unchanged, so this equals an update of the non-zero rows alone bit for bit;
    written densely, because an update of chosen rows is a scatter, which keeps XLA:CPU from compiling the step
    loop as one kernel (`xla_options.CPU_XLA_FLAGS`).
    """
    return w1 - x[:, None] * scaled


def _forward_pair(layers, x_now: jax.Array, pending: Pending, rows_now: jax.Array | None, n_visual: int):
    """The inputs of every layer for x(t) and x(t-1) under W(t), and x(t)'s layer-1 pre-activation.

    Args:
      layers: the dense layers [(w, b)] of W(t), input layer first (`network.dense_layers`).
      x_now: (125,) input x(t).
      pending: the step t-1; its `u1`, if set, stands in for x(t-1)'s layer-1 product.
      rows_now: optional (20,) int32 rows holding every non-zero coded unit of x(t).
      n_visual: the visual rows, the first of the input.

    Returns:
      (acts, u1_now): acts[i] = (input of layer i for x(t), for x(t-1)), the last pair the outputs (3,);
      u1_now (hidden,).
    """
    w1, b1 = layers[0]
    u1_now = _layer1_input_product(x_now, w1, rows_now, n_visual) + b1
    u1_prev = pending.u1 if pending.u1 is not None else _layer1_input_product(pending.x, w1, None, n_visual) + b1
    # The raw input row of x(t) is not needed again. Each row is its own multiply-and-reduce over the leading
    # axis: a stacked (2, n) @ W as one reduction over the middle axis compiled to a far slower kernel on CPU
    # (measured, layer 2 alone cost more than layer 1).
    acts = [(x_now, pending.x), (network.squash(u1_now), network.squash(u1_prev))]
    for w, b in layers[1:]:
        acts.append(tuple(network.squash(jnp.sum(a[:, None] * w, axis=0) + b) for a in acts[-1]))
    return acts, u1_now


def _backprop_sgd(layers, acts, delta: jax.Array, step: jax.Array):
    """Backprop on the x(t-1) row through the old weights, each layer's SGD step taken as the signal passes it.

    Args:
      layers: the dense layers [(w, b)] of W(t), input layer first.
      acts: each layer's inputs for (x(t), x(t-1)) (`_forward_pair`).
      delta: (3,) the output layer's error signal, -err f'(u).
      step: () the step size; 0 leaves every weight as it is.

    Returns:
      (the layers of W(t+1), the layer-1 error signal delta1 (hidden,)).
    """
    new_layers = [None] * len(layers)
    for i in range(len(layers) - 1, -1, -1):
        w, b = layers[i]
        below = acts[i][1]
        scaled = step * delta
        if i > 0:
            new_layers[i] = (w - below[:, None] * scaled, b - scaled)
            delta = jnp.sum(w * delta, axis=1) * _squash_slope(below)
        else:
            new_layers[i] = (_layer1_sgd(w, below, scaled), b - scaled)
    return new_layers, delta


def ts_step(
    params,
    x_now: jax.Array,
    pending: Pending,
    n_max: jax.Array,
    lr: jax.Array,
    cfg: Config,
    rows_now: jax.Array | None = None,
    baseline: jax.Array = 0.0,
    bound: jax.Array = 0.0,
):
    """Forward x(t), then one TS backprop step on x(t-1) by hand-written SGD; the rollout's hot path.

    Args:
      params: network parameters W(t) (flax layout of `network.ActorCritic`).
      x_now: (125,) input x(t).
      pending: the step t-1; its `u1` (hidden,), if set, is x(t-1)'s layer-1 pre-activation under W(t),
        and its `rows`, if set, hold every non-zero coded unit of x(t-1).
      n_max: () N_max [steps].
      lr: () learning rate; 0 freezes the weights exactly.
      cfg: model config.
      rows_now: optional (20,) int32 rows holding every non-zero coded unit of x(t)
        (`encoding.coded_support`); the layer-1 products then skip the rows that are 0, about 2/3 of them.
      baseline: () the actor signal's baseline (`ts_targets`).
      bound: () the actor targets' bound (`ts_targets`).

    Returns:
      (params W(t+1), outputs (3,) at x(t) computed with W(t), squared-error loss (),
      (hidden,) layer-1 pre-activation of x(t) under W(t+1), to carry as the next Pending.u1; hidden is 30,
      or 32 inside the compiled loops (`chunk.widen_hidden`)).
    """
    layers = network.dense_layers(params)
    n_visual = cfg.sensor.n_cells**2
    acts, u1_now = _forward_pair(layers, x_now, pending, rows_now, n_visual)
    out_now, out_prev = acts[-1]

    target = ts_targets(pending, out_now[0], n_max, cfg.learner, baseline, bound)
    err = jnp.where(pending.valid, target - out_prev, 0.0)
    loss = 0.5 * jnp.sum(err**2)
    step = jnp.where(pending.valid, lr, 0.0)
    new_layers, delta = _backprop_sgd(layers, acts, -err * _squash_slope(out_prev), step)
    bias_input = 1.0 if cfg.network.use_bias else 0.0
    u1_next = u1_now - step * delta * (jnp.sum(pending.x * x_now) + bias_input)
    return network.with_dense_layers(params, new_layers), out_now, loss, u1_next


def ts_update(
    params,
    x_now: jax.Array,
    pending: Pending,
    n_max: jax.Array,
    lr: jax.Array,
    cfg: Config,
    baseline: jax.Array = 0.0,
    bound: jax.Array = 0.0,
):
    """The TS step by its readable definition: flax forward, autodiff backprop, optax SGD.

    `ts_step` is the hand-written fast path used in training; tests hold the two equal.

    Args:
      params: network parameters W(t).
      x_now: (125,) input x(t).
      pending: the step t-1.
      n_max: () N_max [steps].
      lr: () learning rate.
      cfg: model config.
      baseline: () the actor signal's baseline (`ts_targets`).
      bound: () the actor targets' bound (`ts_targets`).

    Returns:
      (params W(t+1), outputs (3,) at x(t) computed with W(t), squared-error loss ()).
    """

    def loss_fn(p):
        out = network.apply(p, jnp.stack([x_now, pending.x]), cfg)
        target = jax.lax.stop_gradient(ts_targets(pending, out[0, 0], n_max, cfg.learner, baseline, bound))
        err = target - out[1]
        return 0.5 * jnp.where(pending.valid, jnp.sum(err**2), 0.0), out[0]

    (loss, out_now), grads = jax.value_and_grad(loss_fn, has_aux=True)(params)
    tx = optax.sgd(lr)
    updates, _ = tx.update(grads, tx.init(params), params)
    return optax.apply_updates(params, updates), out_now, loss
