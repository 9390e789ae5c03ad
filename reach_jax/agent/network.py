"""The 125-30-10-3 actor-critic network (section 4.2, model §4), on flax.

Units: inputs are coded signals in [0, 1]; every neuron outputs f(u) = sigmoid(u) - 0.5 in (-0.5, 0.5).
Output 0 is the critic p; outputs 1-2 are the actor m, mapped to torques [N m] by `torque`.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from reach_jax.config import Config, NetworkConfig, n_inputs


def squash(u: jax.Array) -> jax.Array:
    """The paper's neuron output f(u) = 1 / (1 + exp(-u)) - 0.5."""
    return jax.nn.sigmoid(u) - 0.5


def symmetric_uniform(scale: float):
    """Initializer drawing from U(-scale, scale)."""

    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -scale, scale)

    return init


class ActorCritic(nn.Module):
    """Layered sigmoid network; all outputs share the hidden layers."""

    cfg: NetworkConfig

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.cfg.hidden:
            x = squash(
                nn.Dense(width, use_bias=self.cfg.use_bias, kernel_init=symmetric_uniform(self.cfg.hidden_init))(x)
            )
        return squash(
            nn.Dense(self.cfg.n_out, use_bias=self.cfg.use_bias, kernel_init=symmetric_uniform(self.cfg.output_init))(x)
        )


def init_params(key: jax.Array, cfg: Config):
    """Fresh parameter pytree for one network."""
    return ActorCritic(cfg.network).init(key, jnp.zeros(n_inputs(cfg)))


def apply(params, x: jax.Array, cfg: Config) -> jax.Array:
    """Network outputs (..., 3) [critic, actor1, actor2] for inputs (..., 125)."""
    return ActorCritic(cfg.network).apply(params, x)


def dense_layers(params) -> list[tuple[jax.Array, jax.Array]]:
    """(kernel (..., n_in, n_out), bias (..., n_out)) per layer from the flax tree; a missing bias reads as zeros."""
    p = params["params"]
    out = []
    for i in range(len(p)):
        d = p[f"Dense_{i}"]
        kernel = d["kernel"]
        bias = d["bias"] if "bias" in d else jnp.zeros(kernel.shape[:-2] + kernel.shape[-1:], kernel.dtype)
        out.append((kernel, bias))
    return out


def with_dense_layers(params, layers) -> dict:
    """The flax tree of `params` holding new (kernel, bias) per layer; biases stay absent if they were."""
    new = {}
    for i, (kernel, bias) in enumerate(layers):
        old = params["params"][f"Dense_{i}"]
        new[f"Dense_{i}"] = {"kernel": kernel, **({"bias": bias} if "bias" in old else {})}
    return {**params, "params": new}


def pad_hidden(params, multiple: int):
    """params with the first hidden layer widened to a multiple of `multiple` by units with zero weights in and out.

    The extra units compute f(0) = 0 and pass 0 on; their backprop error is 0 (their outgoing weights are 0),
    so SGD keeps every added weight exactly 0 and the network computes the same function. Only the first
    hidden layer is padded: its (125, 30) kernel dominates the step, while padding the 10-unit layer to 16
    as well made the step slower (a development measurement, README "Performance"). Works on batched trees
    (leading axes), kernels being (..., n_in, n_out) and biases (..., n_out).

    Args:
      params: flax parameter tree (`dense_layers` layout) of at least two layers.
      multiple: the first hidden width is rounded up to a multiple of it; 1 leaves it unchanged.
    """
    (w1, b1), (w2, b2), *rest = dense_layers(params)
    grow = -w1.shape[-1] % multiple
    w1 = jnp.pad(w1, [(0, 0)] * (w1.ndim - 1) + [(0, grow)])
    b1 = jnp.pad(b1, [(0, 0)] * (b1.ndim - 1) + [(0, grow)])
    w2 = jnp.pad(w2, [(0, 0)] * (w2.ndim - 2) + [(0, grow), (0, 0)])
    return with_dense_layers(params, [(w1, b1), (w2, b2), *rest])


def unpad_hidden(params, cfg: Config):
    """Inverse of `pad_hidden`: the first hidden layer cut back to the config's width (exact: the cut weights are 0)."""
    width = cfg.network.hidden[0]
    (w1, b1), (w2, b2), *rest = dense_layers(params)
    return with_dense_layers(params, [(w1[..., :width], b1[..., :width]), (w2[..., :width, :], b2), *rest])


def torque(m: jax.Array, rnd: jax.Array, cfg: Config) -> jax.Array:
    """tau_i = 2 tau_max_i (m_i + rnd_i), clipped to +-tau_max_i: (2,) actor + noise -> (2,) [N m]."""
    tau_max = jnp.asarray(cfg.arm.tau_max)
    return jnp.clip(2.0 * tau_max * (m + rnd), -tau_max, tau_max)
