"""What each speed lever gives: the trainer with one lever switched off at a time, all in one run.

`python benchmarks/levers.py [--json PATH] [--devices N] [--reps N]`

Units: learner-steps per second (median of the timed calls of `throughput.time_chunk`). Levers switched off:
- `dense_layer1`: the layer-1 product and SGD step over all 125 input rows instead of the 45 that can be
  non-zero (`Speed.sparse_layer1` off, the dense path of `learner.ts_step`; the support is still computed, as
  the pending step carries it: not the variant in results/levers.json, which patched the support out);
- `draws_per_step`: random draws made one step at a time inside the step body (`Speed.draw_block` = 1)
  instead of 64 steps at a time;
- `one_device`: the learner axis on one device instead of sharded over all of them;
- `unpadded_hidden`: the first hidden layer at its 30 units instead of padded to 32 (`Speed.hidden_pad` = 1);
- `no_donation`: each chunk writes new state buffers instead of reusing its input's (`Speed.donate` off);
- `short_chunks`: SHORT_CHUNK steps per compiled call instead of ~0.4 s worth, so the host syncs more often.
The variants are interleaved over `--reps` rounds, so that the machine's drift hits them alike; the JSON
holds every round and the medians.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
from pathlib import Path

from reach_jax.config.schema import DEFAULT_SPEED
from reach_jax.engine import distribute

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (the sibling benchmark's timing helpers)

BATCHES = (8, 128)  # the Table-2 batch and a large one
VARIANTS = (
    "all_levers",
    "dense_layer1",
    "draws_per_step",
    "one_device",
    "unpadded_hidden",
    "no_donation",
    "short_chunks",
)
SHORT_CHUNK = 1000  # steps per call of the short_chunks variant
SPEED_OFF = {  # variant -> the reach_jax.speed.Speed settings that switch its lever off
    "dense_layer1": {"sparse_layer1": False},
    "draws_per_step": {"draw_block": 1},
    "unpadded_hidden": {"hidden_pad": 1},
    "no_donation": {"donate": False},
}


def parse(argv=None) -> argparse.Namespace:
    """Command line of the lever benchmark."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    p.add_argument("--devices", type=int, default=os.cpu_count(), help="CPU host devices (default: one per core)")
    p.add_argument("--reps", type=int, default=3, help="interleaved rounds over the variants")
    return p.parse_args(argv)


def measure(variant: str, n_learners: int, cfg) -> float:
    """Learner-steps/s of one variant at one batch size."""
    import jax

    devices, n_steps = jax.devices(), None
    # The levers are the JAX engine's: the native kernel has no draw block, and pads and skips rows its own way.
    speed = dataclasses.replace(DEFAULT_SPEED, engine="jax", **SPEED_OFF.get(variant, {}))
    if variant == "one_device":
        devices = devices[:1]
    elif variant == "short_chunks":
        n_steps = SHORT_CHUNK
    return throughput.time_chunk(n_learners, devices, cfg, False, n_steps, speed)["steps_per_s"]


def main(argv=None) -> int:
    """Measure every variant, print the table, write the JSON."""
    args = parse(argv)
    distribute.setup_backend(args.devices)
    import jax

    from reach_jax.config import Config

    cfg = Config()
    rounds = {v: {n: [] for n in BATCHES} for v in VARIANTS}
    for r in range(args.reps):
        for n in BATCHES:
            for v in VARIANTS:
                rounds[v][n].append(measure(v, n, cfg))
        print(f"round {r + 1}/{args.reps} done", file=sys.stderr, flush=True)
    medians = {v: {n: statistics.median(x) for n, x in by.items()} for v, by in rounds.items()}
    print(f"jax {jax.__version__}, {jax.default_backend()}, {len(jax.devices())} devices")
    print("{:>16} ".format("variant") + " ".join(f"{n:>10} learners {'':>8}" for n in BATCHES))
    for v in VARIANTS:
        cells = [f"{medians[v][n]:14,.0f} ({medians['all_levers'][n] / medians[v][n]:.2f}x)" for n in BATCHES]
        print(f"{v:>16} " + " ".join(f"{c:>27}" for c in cells))
    result = {
        "learner_steps_per_s": {v: {str(n): m for n, m in by.items()} for v, by in medians.items()},
        "rounds": {v: {str(n): x for n, x in by.items()} for v, by in rounds.items()},
        "devices": len(jax.devices()),
        "code": throughput.code_version(),
        "jax": jax.__version__,
    }
    throughput.write_result(result, "levers", args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
