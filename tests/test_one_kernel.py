"""The training step loop compiles as one XLA:CPU kernel (a "small call"), with and without the per-trial log.

XLA:CPU compiles a while loop as one function only when the loop holds no scatter, dot, custom call or collective
and its state is below `xla_options.ONE_KERNEL_BYTES`; a scatter that slips into the step (an indexed update under
vmap) silently brings back a kernel call per fusion. These tests read the optimised HLO of a compiled chunk.
"""

from __future__ import annotations

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from reach_jax.config import Config
from reach_jax.config.schema import DEFAULT_SPEED
from reach_jax.engine import batch, xla_options
from reach_jax.engine.chunk import chunk_body, make_chunk

pytestmark = pytest.mark.skipif(jax.default_backend() != "cpu", reason="an XLA:CPU compiler pass")


def computations(hlo: str) -> dict[str, list[str]]:
    """The instruction lines of each computation of an HLO text module, by name."""
    found, current = {}, None
    for line in hlo.splitlines():
        head = re.match(r"^(?:ENTRY )?%(\S+) \(.*\{$", line)
        if head:
            current = found.setdefault(head.group(1), [])
        elif line.strip() == "}":
            current = None
        elif current is not None:
            current.append(line)
    return found


def called(lines: list[str]) -> set[str]:
    """The computations that these instructions call, run as loop bodies or fuse."""
    return {m for line in lines for m in re.findall(r"(?:to_apply|body|condition|calls)=%([\w.\-]+)", line)}


def unhoisted(hlo: str, op: str) -> tuple[int, int]:
    """(instructions `op` inside one-kernel calls, instructions `op` elsewhere) of an optimised HLO module."""
    comps = computations(hlo)
    inside, todo = (
        set(),
        [c for lines in comps.values() for line in lines if "xla_cpu_small_call" in line for c in called([line])],
    )
    while todo:
        name = todo.pop()
        if name not in inside:
            inside.add(name)
            todo.extend(called(comps.get(name, [])))
    count = {True: 0, False: 0}
    for name, lines in comps.items():
        count[name in inside] += sum(f" {op}(" in line for line in lines)
    return count[True], count[False]


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
    hlo = compiled_chunk(every)
    inside, outside = unhoisted(hlo, "sine")
    assert inside > 0 and outside == 0, (inside, outside)
    assert unhoisted(hlo, "scatter")[0] == 0 and unhoisted(hlo, "dot")[0] == 0


def test_the_check_sees_a_scatter_keep_a_loop_out():
    def loop(x, rows):
        def step(x, _):
            x = jnp.sin(x)
            return jax.vmap(lambda v, r: v.at[r].add(1.0))(x, rows), None  # a scatter per learner

        return jax.lax.scan(step, x, None, length=50)[0]

    def clean(x, rows):
        return jax.lax.scan(lambda x, _: (jnp.sin(x) + 1.0, None), x, None, length=50)[0]

    args = (jnp.ones((4, 8)), jnp.arange(4))
    assert unhoisted(jax.jit(loop).lower(*args).compile().as_text(), "sine") == (0, 1)
    assert unhoisted(jax.jit(clean).lower(*args).compile().as_text(), "sine") == (1, 0)


def test_a_learner_rounds_the_same_alone_as_in_a_batch():
    # With fused multiply-adds LLVM contracts a*b+c as each loop's shape lets it, and a learner trained in a batch of
    # 4 left the rounding of one trained alone within 5 steps; `xla_options.NO_FMA_FLAG` keeps them bit-identical.
    cfg = Config()
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, seeds=1))
    group = batch.init_batch(cfg)
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    chunk = make_chunk(cfg, 600, jax.devices()[:1])
    together = chunk(jax.tree.map(jnp.copy, group.states), group.plans, group.hypers, budget)[0]
    for i in (0, 3):
        alone = jax.tree.map(lambda a, i=i: a[i : i + 1], group)
        mine = chunk(jax.tree.map(jnp.copy, alone.states), alone.plans, alone.hypers, budget)[0]
        for a, b in zip(jax.tree.leaves(together), jax.tree.leaves(mine), strict=True):
            np.testing.assert_array_equal(np.asarray(a)[i], np.asarray(b)[0])
