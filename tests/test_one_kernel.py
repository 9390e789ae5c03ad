"""The training step loop compiles as one XLA:CPU kernel (a "small call"), with and without the per-trial log.

XLA:CPU compiles a while loop as one function only when the loop holds no scatter, dot, custom call or collective
and its state is below `xla_options.ONE_KERNEL_BYTES`; a scatter that slips into the step (an indexed update under
vmap) silently brings back a kernel call per fusion. These tests read the optimised HLO of a compiled chunk.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax.config import Config
from reach_jax.config.schema import DEFAULT_SPEED
from reach_jax.engine import batch, xla_options
from reach_jax.engine.chunk import chunk_body, make_chunk
from reach_jax.physics import arm
from reach_jax.testing import hlo

pytestmark = pytest.mark.skipif(jax.default_backend() != "cpu", reason="an XLA:CPU compiler pass")


def compiled_chunk(every: int) -> str:
    """The optimised HLO of a 128-step chunk of 4 learners (every paper condition), with a trial log every `every`."""
    cfg = Config()
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=1, trial_log_every=every))
    group = batch.init_batch(cfg)
    chunk = jax.jit(chunk_body(cfg, 128, DEFAULT_SPEED))
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    return chunk.lower(group.states, group.plans, group.hypers, budget).compile().as_text()


def test_the_one_kernel_option_is_set():
    assert xla_options.CPU_XLA_FLAGS[-1].endswith(
        f"xla_cpu_small_while_loop_byte_threshold={xla_options.ONE_KERNEL_BYTES}"
    )
    assert xla_options.add_xla_flags() is True  # set at the session's start (conftest), as the command lines do


@pytest.mark.parametrize("every", [0, 1])
def test_the_step_loop_is_one_kernel(every):
    # The arm's RK4 takes sines and cosines every step: every one of them runs inside a one-kernel call.
    text = compiled_chunk(every)
    inside, outside = hlo.count(text, "sine")
    assert inside > 0 and outside == 0, (inside, outside)
    assert hlo.count(text, "scatter")[0] == 0 and hlo.count(text, "dot")[0] == 0


def test_the_check_sees_a_scatter_keep_a_loop_out():
    def loop(x, rows):
        def step(x, _):
            x = jnp.sin(x)
            return jax.vmap(lambda v, r: v.at[r].add(1.0))(x, rows), None  # a scatter per learner

        return jax.lax.scan(step, x, None, length=50)[0]

    def clean(x, rows):
        return jax.lax.scan(lambda x, _: (jnp.sin(x) + 1.0, None), x, None, length=50)[0]

    args = (jnp.ones((4, 8)), jnp.arange(4))
    assert hlo.count(jax.jit(loop).lower(*args).compile().as_text(), "sine") == (0, 1)
    assert hlo.count(jax.jit(clean).lower(*args).compile().as_text(), "sine") == (1, 0)


def test_a_learner_rounds_the_same_alone_as_in_a_batch():
    # With fused multiply-adds LLVM contracts a*b+c as each loop's shape lets it, and a learner trained in a batch of
    # 4 left the rounding of one trained alone within 5 steps; `xla_options.NO_FMA_FLAG` keeps them bit-identical.
    cfg = Config()
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=1))
    group = batch.init_batch(cfg)
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    chunk = make_chunk(cfg, 600, jax.devices()[:1], speed=dataclasses.replace(DEFAULT_SPEED, engine="jax"))
    together = chunk(jax.tree.map(jnp.copy, group.states), group.plans, group.hypers, budget)[0]
    for i in (0, 3):
        alone = jax.tree.map(lambda a, i=i: a[i : i + 1], group)
        mine = chunk(jax.tree.map(jnp.copy, alone.states), alone.plans, alone.hypers, budget)[0]
        for a, b in zip(jax.tree.leaves(together), jax.tree.leaves(mine), strict=True):
            np.testing.assert_array_equal(np.asarray(a)[i], np.asarray(b)[0])


def test_the_stop_share_rounds_as_the_program_that_uses_it():
    # The impact's share M12/M11 is a constant computed while tracing; cached once under jax.enable_x64 (the physics
    # tests), it carried float64 rounding into every float32 program traced after, and training in a test process
    # left the bits of the same run trained by the command line.
    cfg = Config().arm
    state = jnp.array([0.3, cfg.theta2_stop + 0.01, 0.2, 1.7], jnp.float32)
    with jax.enable_x64(True):
        arm.elbow_stop(state.astype(jnp.float64), cfg)
    m = np.asarray(arm.mass_matrix(jnp.array([0.0, cfg.theta2_stop], jnp.float32), cfg))
    assert m.dtype == np.float32
    want = np.float32(0.2) + np.float32(m[0, 1] / m[0, 0]) * np.float32(1.7)
    assert np.asarray(arm.elbow_stop(state, cfg))[2] == want
