"""The XLA:CPU compiler options that every command line sets before JAX starts, and the arithmetic they make.

Nothing here runs at import: `distribute.setup_backend` (the command lines, the test suite) calls `add_xla_flags`.
XLA aborts a process on a flag it does not know, so each is first tried in a child process.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import warnings

import jax

# XLA:CPU options; every command line and the test suite set them before JAX starts, and other
# backends ignore them. Each changes which code runs, so a run and its resumption must both have them.
# - YNNPACK for real dots only: it made the per-learner 30x10 and 10x3 products ~1.6x slower at 128 learners.
# - No fused multiply-add: the AVX instruction set, which has none. With FMA, LLVM contracts a*b+c wherever the
#   code's shape lets it, so a learner's rounding depended on the batch it ran in and on how the step was cut into
#   kernels; without, it is the same in any batch, sharded or not, as one kernel or many (`engine`).
# - A while loop with less state than ONE_KERNEL_BYTES compiles as one kernel ("small call") instead of a call per
#   fusion (~160 a step at 40-50 ns each), if it holds no scatter, dot, custom call or collective: the step loop
#   (tests/test_one_kernel.py). Results do not depend on it (docs/performance.md).
ONE_KERNEL_BYTES = 1 << 30  # [bytes] of loop state
NO_FMA_FLAG = "--xla_cpu_max_isa=AVX"
CPU_XLA_FLAGS = (
    "--xla_cpu_experimental_ynn_fusion_type=LIBRARY_FUSION_TYPE_INDIVIDUAL_DOT",
    NO_FMA_FLAG,
    f"--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={ONE_KERNEL_BYTES}",
)
PROBE_TIMEOUT = 120  # [s] for the child process that checks this jaxlib accepts CPU_XLA_FLAGS


def jax_started() -> bool:
    """Whether JAX has created its backends, after which XLA_FLAGS and the CPU device count are fixed."""
    # JAX has no public query for this (jax-ml/jax#23320); its config refuses a new CPU device count once the
    # backends exist, so ask for one and put the old value back.
    count = jax.config.jax_num_cpu_devices
    try:
        jax.config.update("jax_num_cpu_devices", count + 1)
    except RuntimeError:
        return True
    jax.config.update("jax_num_cpu_devices", count)
    return False


@functools.cache
def flags_accepted(flags: tuple[str, ...]) -> bool:
    """Whether this jaxlib starts with `flags` in XLA_FLAGS; XLA aborts a process on an unknown flag, so a child
    process tries them."""
    env = {**os.environ, "XLA_FLAGS": " ".join((os.environ.get("XLA_FLAGS", ""), *flags)).strip()}
    probe = "import jax, jax.numpy as jnp; jnp.zeros(1).block_until_ready()"
    try:
        done = subprocess.run(
            [sys.executable, "-c", probe], env=env, capture_output=True, timeout=PROBE_TIMEOUT, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def add_xla_flags(flags: tuple[str, ...] = CPU_XLA_FLAGS) -> bool:
    """Append each of `flags` that this jaxlib accepts to XLA_FLAGS unless it is there; returns whether all are set.

    Warns, and leaves XLA_FLAGS alone, when JAX has already started (they would not take effect); warns for the
    flags the jaxlib rejects (a future version may drop an option) and sets the others: training then runs, a
    little slower, or under another `engine`.
    """
    current = os.environ.get("XLA_FLAGS", "")
    missing = tuple(f for f in flags if f.split("=")[0] not in current)
    if not missing:
        return True
    if jax_started():
        warnings.warn(f"JAX already started; XLA_FLAGS {' '.join(missing)} not applied", stacklevel=2)
        return False
    accepted = missing if flags_accepted(missing) else tuple(f for f in missing if flags_accepted((f,)))
    if len(accepted) < len(missing):
        rejected = " ".join(f for f in missing if f not in accepted)
        warnings.warn(f"this jaxlib rejects XLA_FLAGS {rejected}; running without them", stacklevel=2)
    if accepted:
        os.environ["XLA_FLAGS"] = " ".join((current, *accepted)).strip()
    return len(accepted) == len(missing)


def engine() -> str:
    """The arithmetic of this process, which a run stores and resumes only under (docs/performance.md, "Engines").

    "cpu-exact": XLA:CPU without fused multiply-add (NO_FMA_FLAG), a learner's rounding the same in any batch;
    "cpu-fma": XLA:CPU where the jaxlib refused it; on other backends their platform ("gpu", "tpu").
    """
    platform = jax.default_backend()
    if platform != "cpu":
        return platform
    return "cpu-exact" if NO_FMA_FLAG in os.environ.get("XLA_FLAGS", "").split() else "cpu-fma"
