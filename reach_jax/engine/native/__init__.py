"""The native CPU engine: the training step loop as one C++ kernel (`kernel.cc`) over every learner of a device, called
from the compiled chunk through XLA's FFI, bit-identical to the JAX step under "cpu-exact" (docs/performance.md).

Counts are steps or trials. The chunk draws each block's uniforms in JAX (`random_stream`), packs the learners into
rows (`layout`) and calls the kernel once a block; sharding, checkpoints and the Python API are those of the JAX
engine. `build` compiles the kernel on first use.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from reach_jax.config import Config
from reach_jax.config.schema import Speed
from reach_jax.engine import random_stream, xla_options
from reach_jax.engine.native import build, layout

BLOCK = 512  # steps a kernel call: their draws are drawn in one vectorised call before it

__all__ = ["BLOCK", "build", "chunk_body", "layout", "resolve", "target", "unsupported"]


def unsupported(cfg: Config, speed: Speed) -> str | None:
    """Why the kernel does not cover learners of `cfg` run at `speed` (they train on the JAX engine), or None."""
    if cfg.train.trial_log_every:
        return "it does not write the per-trial log (--trial-log-every) yet"
    if len(cfg.network.hidden) != 2:
        return "it covers networks of two hidden layers only"
    if not speed.sparse_layer1:
        return "it computes the sparse layer 1 only"
    if jax.default_backend() != "cpu":
        return f"it runs on CPU only, not {jax.default_backend()}"
    if xla_options.engine() != "cpu-exact":
        return f"it rounds as cpu-exact, and this process runs {xla_options.engine()}"
    return None


def resolve(cfg: Config, speed: Speed) -> tuple[Speed, str | None]:
    """(speed with its engine decided, "jax" or "native"; the one-line notice of a native engine not used, or None).

    "auto" and "native" take the native kernel where it covers the learners and builds (`build.load`, on first use);
    elsewhere they fall back to the JAX engine with a notice. "jax" always runs the JAX engine, silently.
    """
    if speed.engine == "jax":
        return speed, None
    why = unsupported(cfg, speed)
    if why is None:
        try:
            target(cfg, speed)
        except build.Failure as e:
            why = str(e)
    if why is None:
        return dataclasses.replace(speed, engine="native"), None
    return dataclasses.replace(speed, engine="jax"), f"training on the JAX engine: the native engine is not used ({why})"


def target(cfg: Config, speed: Speed) -> str:
    """The FFI target of the kernel for `cfg`, built and registered on first use; raises build.Failure."""
    return build.load(layout.header(cfg, speed.hidden_pad))[1]


def chunk_body(cfg: Config, n_steps: int, speed: Speed):
    """Uncompiled chunk of one device on the native kernel: (states, plans, hypers, budget) -> (states, None).

    The same function as `chunk.chunk_body` without a per-trial log, bit for bit. Stats are reset at its start.
    """
    from reach_jax.engine import chunk as jax_chunk  # the JAX chunk's state layout helpers

    name = target(cfg, speed)
    consts = layout.consts_vector(cfg)

    def chunk(states, plans, hypers, budget):
        counters = states.counters
        states = states.replace(counters=counters.replace(stats=jax.tree.map(jnp.zeros_like, counters.stats)))
        wide = jax_chunk.widen_hidden(states, speed.hidden_pad)
        f, i = layout.pack_state(wide)
        pf, pi, n_blocks, n_cond = layout.pack_plan(plans)
        hy = layout.pack_hyper(hypers)
        keys = states.key
        call = jax.ffi.ffi_call(
            name,
            (jax.ShapeDtypeStruct(f.shape, jnp.float32), jax.ShapeDtypeStruct(i.shape, jnp.int32)),
            input_output_aliases={1: 0, 2: 1},
        )
        step_col = len(layout.INT_FIELDS) - 1

        def run_block(carry, n: int):
            f, i = carry
            u = jax.vmap(lambda k, first: random_stream.step_uniforms(k, first, n, cfg))(keys, i[:, step_col])
            u = jnp.swapaxes(u, 0, 1)
            return call(jnp.asarray(consts), f, i, hy, pf, pi, u, jnp.reshape(budget, (1,)).astype(jnp.int32),
                        nb=np.int64(n_blocks), ncond=np.int64(n_cond))  # fmt: skip

        block = jax_chunk.block_size(n_steps, BLOCK)
        n_full, rest = divmod(n_steps, block)
        carry = jax.lax.scan(lambda c, _: (run_block(c, block), None), (f, i), None, length=n_full)[0]
        if rest:
            carry = run_block(carry, rest)
        out = layout.unpack_state(*carry, wide)
        return jax_chunk.narrow_hidden(out, cfg), None

    return chunk
