"""The native CPU engine: the training step loop as one C++ kernel (`kernel.cc`) over every learner of a device, called
from the compiled chunk through XLA's FFI, bit-identical to the JAX step under "cpu-exact" (docs/performance.md).

Counts are steps or trials. Its chunk (`chunk.native_chunk_body`) packs the learners into rows (`layout`) and calls
the kernel once, which runs every step and makes the random draws of `random_stream` itself; sharding, checkpoints
and the Python API are those of the JAX engine. `build` compiles the kernel on first use.
"""

from __future__ import annotations

import dataclasses

import jax

from reach_jax.config import Config
from reach_jax.config.schema import Speed
from reach_jax.engine import xla_options
from reach_jax.engine.native import build, layout

__all__ = ["build", "layout", "resolve", "target", "unsupported"]


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
    notice = f"training on the JAX engine: the native engine is not used ({why})"
    return dataclasses.replace(speed, engine="jax"), notice


def target(cfg: Config, speed: Speed) -> str:
    """The FFI target of the kernel for `cfg`, built and registered on first use; raises build.Failure."""
    return build.load(layout.header(cfg, speed.hidden_pad))[1]
