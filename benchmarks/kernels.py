"""What the training step loop compiles to on XLA:CPU: one kernel or a call per fusion, and how long compiling takes.

`python benchmarks/kernels.py [--learners N ...] [--ir N ...] [--json PATH]`

For each batch size (on one device) the script compiles a chunk of 128 steps, with and without the per-trial log,
and reads its optimised HLO (`reach_jax.testing.hlo`): how many while loops run as one kernel ("small calls",
`xla_options.CPU_XLA_FLAGS`), whether every instruction of the step (the arm's sines among them) runs inside one,
what the one-kernel loops hold by opcode, and what stays outside them (with the per-trial log, the block loop
that writes the log, whose scatter keeps it out). Before the one-kernel step each fusion of the step loop's body
was a separate call, about 160 a step (`kernels-20261124*.json`). With --ir, for each batch size given, it also reads
the LLVM IR that XLA emits for the one-kernel step loop (`ir_counts`): how many of its float instructions work on one
value and how many on a SIMD vector, and which transcendental functions it calls one value at a time. Writes
benchmarks/results/kernels-<UTC time>.json unless --json names one.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import re
import sys
import tempfile
import time
from pathlib import Path

from reach_jax.engine import distribute

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (the sibling benchmark's batches, results folder and code version)

STEPS = 128  # steps of the compiled chunk: two draw blocks, so the step loop is a loop


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--learners", type=int, nargs="+", default=[1, 8], help="batch sizes, one device (default 1 8)")
    p.add_argument("--ir", type=int, nargs="*", default=[], help="batch sizes whose step loop's LLVM IR to read")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    return p.parse_args(argv)


FLOAT_OP = re.compile(r"= (fmul|fadd|fsub|fdiv)(?: [a-z]+)* (float|<(\d+) x float>) ")
CALL = re.compile(r"call [^@]*@(llvm\.)?([a-z]+)\.?(v\d+)?f32")
TRANSCENDENTAL = ("sin", "cos", "exp", "log", "tanh", "pow")


def ir_counts(ll: str) -> dict:
    """Static counts in optimised LLVM IR: float arithmetic by width (1: scalar), and transcendental calls by
    function and width. Each counts an instruction of the code, not how often it runs."""
    arith = collections.Counter()
    for op, _, lanes in FLOAT_OP.findall(ll):
        arith[f"{op} x{lanes or 1}"] += 1
    calls = collections.Counter()
    for _, name, vector in CALL.findall(ll):
        if name in TRANSCENDENTAL:
            calls[f"{name} x{vector[1:] if vector else 1}"] += 1
    scalar = sum(n for k, n in arith.items() if k.endswith(" x1"))
    return {
        "float_arithmetic": dict(sorted(arith.items())),
        "scalar_share": scalar / max(1, sum(arith.values())),
        "transcendental_calls": dict(sorted(calls.items())),
    }


def lowered_chunk(n_learners: int, every: int):
    """A lowered chunk of STEPS steps of n_learners with a trial log every `every` trials (0: none), on one device."""
    import jax
    import jax.numpy as jnp

    from reach_jax.config import Config
    from reach_jax.config.schema import DEFAULT_SPEED
    from reach_jax.engine.chunk import chunk_body

    cfg = Config()
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, trial_log_every=every))
    learners = throughput.batch_of(n_learners, cfg)
    budget = jnp.asarray(2**31 - 1, jnp.int32)
    chunk = jax.jit(chunk_body(cfg, STEPS, DEFAULT_SPEED))
    return chunk.lower(learners.states, learners.plans, learners.hypers, budget)


def ir_report(n_learners: int) -> dict:
    """`ir_counts` of the one-kernel step loop of a chunk of n_learners without a trial log, on one device."""
    with tempfile.TemporaryDirectory() as folder:
        lowered_chunk(n_learners, 0).compile(compiler_options={"xla_dump_to": folder})
        # The step loop is the largest function XLA emits for the chunk (the other kernels are its set-up).
        ll = max(Path(folder).glob("*chunk*ir-with-opt.ll"), key=lambda p: p.stat().st_size)
        return {"learners": n_learners, "module": ll.name, **ir_counts(ll.read_text())}


def report(n_learners: int, every: int) -> dict:
    """What a chunk of n_learners with a trial log every `every` trials (0: none) compiles to, and its compile time."""
    from reach_jax.testing import hlo

    lowered = lowered_chunk(n_learners, every)
    t0 = time.perf_counter()
    text = lowered.compile().as_text()
    compile_s = time.perf_counter() - t0
    inside, outside = hlo.count(text, "sine")
    return {
        "learners": n_learners,
        "trial_log_every": every,
        "compile_s": compile_s,
        "one_kernel_loops": text.count("xla_cpu_small_call"),
        "step_in_one_kernel": inside > 0 and outside == 0,
        "inside_by_opcode": dict(hlo.opcodes(text, inside=True).most_common()),
        "outside_by_opcode": dict(hlo.opcodes(text, inside=False).most_common()),
    }


def main(argv=None) -> int:
    """Compile, read, print, write the JSON."""
    args = parse(argv)
    distribute.setup_backend(1)
    import jax

    rows = [report(n, every) for n in args.learners for every in (0, 1)]
    for r in rows:
        print(
            f"{r['learners']} learners, trial log {'on' if r['trial_log_every'] else 'off'}: "
            f"{r['one_kernel_loops']} one-kernel loops, step in one kernel: {r['step_in_one_kernel']}, "
            f"{sum(r['inside_by_opcode'].values())} instructions inside, outside: {r['outside_by_opcode']}, "
            f"compiled in {r['compile_s']:.1f} s"
        )
    ir = [ir_report(n) for n in args.ir]
    for r in ir:
        print(
            f"{r['learners']} learners, the step loop's LLVM IR: {100 * r['scalar_share']:.0f}% of its float "
            f"arithmetic instructions scalar, {r['float_arithmetic']}; transcendental calls {r['transcendental_calls']}"
        )
    result = {
        "rows": rows,
        "ir": ir,
        "code": throughput.code_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
    }
    throughput.write_result(result, "kernels", args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
