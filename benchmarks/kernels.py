"""Kernels that XLA runs for one training step: the instructions of the compiled step loop's body, by kind.

`python benchmarks/kernels.py [--learners N] [--json PATH]`

XLA:CPU runs each fusion, copy, dot or concatenation of the step loop's body as a separate kernel, one after
another, so at small batches their number sets the step's latency (README "Performance"). The script compiles a
chunk with XLA's optimised HLO dumped to a temporary folder, takes the largest loop body of the chunk (the
step; the loops of the random draws are smaller) and counts its instructions, leaving out those that run no
kernel (parameters, tuples and their elements, constants, bitcasts). Writes
benchmarks/results/kernels-<UTC time>.json unless --json names one.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import sys
import tempfile
from pathlib import Path

from reach_jax.engine import chunk as chunk_lib
from reach_jax.engine import distribute

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (the sibling benchmark's batches, results folder and code version)

NO_KERNEL = ("parameter", "tuple", "get-tuple-element", "constant", "bitcast")  # instructions that launch nothing
STEPS = 128  # steps of the compiled chunk: two draw blocks, so the step loop is a loop


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--learners", type=int, default=1, help="batch size, on one device (default 1)")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    return p.parse_args(argv)


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


def step_kernels(hlo: str) -> collections.Counter:
    """Kernel-launching instructions of the largest while-loop body in `hlo`, by opcode."""
    comps = computations(hlo)
    bodies = [
        m.group(1) for lines in comps.values() for line in lines for m in [re.search(r"body=%([^,\s]+)", line)] if m
    ]
    body = max(bodies, key=lambda name: len(comps[name]))
    kinds = collections.Counter()
    for line in comps[body]:
        op = re.search(r"=\s*\S+\s+([a-z][a-z-]*)\(", line)
        if op and op.group(1) not in NO_KERNEL:
            kinds[op.group(1)] += 1
    return kinds


def main(argv=None) -> int:
    """Compile with the HLO dumped, count, print, write the JSON."""
    args = parse(argv)
    with tempfile.TemporaryDirectory() as dump:
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_dump_to={dump} --xla_dump_hlo_as_text"
        distribute.setup_backend(1)
        import jax
        import jax.numpy as jnp

        from reach_jax.config import Config

        cfg = Config()
        learners = throughput.batch_of(args.learners, cfg)
        chunk = chunk_lib.make_chunk(cfg, STEPS, jax.devices()[:1])
        budget = jnp.asarray(2**31 - 1, jnp.int32)
        jax.block_until_ready(chunk(learners.states, learners.plans, learners.hypers, budget))
        modules = list(Path(dump).glob("*jit_chunk*cpu_after_optimizations.txt"))
        kinds = step_kernels(max(modules, key=lambda p: p.stat().st_size).read_text())
    result = {
        "kernels_per_step": sum(kinds.values()),
        "by_kind": dict(kinds.most_common()),
        "learners": args.learners,
        "code": throughput.code_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
    }
    print(json.dumps(result, indent=2))
    throughput.write_result(result, "kernels", args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
