"""What a real training run cost, chunk by chunk, and whether it reproduces a committed run bit for bit.

`python benchmarks/table2_run.py RUN [--against COMMITTED_RUN] [--json PATH]`

Reads RUN's metrics.jsonl: the wall time, and the time of one batch step in each chunk (the chunk's wall time
over its steps [us]), grouped by the batch the chunk ran (`progress.pow2_batch` of the learners unfinished at
its start). With --against it compares RUN's newest checkpoint leaf by leaf and its metrics row by row (wall
time aside) with the committed run: the leaves that its checkpoint stores (an older layout lacks the fields added
since), and the metrics on the fields both rows hold, at float32. Writes
benchmarks/results/table2-run-<UTC time>.json unless --json names one.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

from reach_jax.config import compat
from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io
from reach_jax.train.progress import pow2_batch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import throughput  # noqa: E402  (the sibling benchmark's results folder and code version)

IGNORED = ("wall_s",)  # metrics fields that may differ between equal runs: time


def parse(argv=None) -> argparse.Namespace:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", type=Path, help="the training run to read")
    p.add_argument("--against", type=Path, help="a committed run that RUN should equal bit for bit")
    p.add_argument("--json", type=Path, help="write the results here (default: a new file in benchmarks/results)")
    return p.parse_args(argv)


def step_times(rows: list[dict], budget: int) -> dict[str, dict]:
    """Per batch size: chunks run, median and total time of one batch step [us, s], from the metrics rows."""
    chunks: dict[int, list[dict]] = {}
    for r in rows:
        chunks.setdefault(r["chunk"], []).append(r)
    by_size: dict[int, list[tuple[float, int]]] = {}  # batch size -> (wall time [s], steps) per chunk
    wall, trials = 0.0, None
    for c in sorted(chunks):
        rs = sorted(chunks[c], key=lambda r: r["learner"])
        steps = max(r["steps"] for r in rs) - (0 if trials is None else max(trials[1]))
        unfinished = len(rs) if trials is None else int(np.sum(np.asarray(trials[0]) < budget))
        took = rs[0]["wall_s"] - wall
        if steps > 0:
            by_size.setdefault(pow2_batch(unfinished, len(rs)), []).append((took, steps))
        wall, trials = rs[0]["wall_s"], ([r["trials"] for r in rs], [r["steps"] for r in rs])
    return {
        str(n): {
            "chunks": len(v),
            "median_us": statistics.median(t / s * 1e6 for t, s in v),
            "total_s": sum(t for t, _ in v),
            "steps": sum(s for _, s in v),
        }
        for n, v in sorted(by_size.items())
    }


def stored_leaves(path: Path, leaves: dict) -> list[str]:
    """The names among `leaves` (today's) that the checkpoint at `path` stores, under today's name or an older one."""
    with np.load(path) as data:
        names = set(data.files)
        version = json.loads(data["__meta__"].tobytes().decode())["format_version"]
    return [k for k in leaves if k in names or any(a in names for a in compat.state_aliases(k, version))]


def same_row(mine: dict, theirs: dict) -> bool:
    """Whether two metrics rows agree on every field both hold but IGNORED, floats at float32 (older writers spelled
    a float32 as its float64 expansion, and lack the columns added since)."""

    def stored(v):
        return np.float32(v) if isinstance(v, float) else v

    return all(stored(mine[k]) == stored(theirs[k]) for k in mine.keys() & theirs.keys() if k not in IGNORED)


def main(argv=None) -> int:
    """Measure RUN, compare it if asked, write the JSON."""
    args = parse(argv)
    cfg = run_dir_io.read_config(args.run)
    rows = run_dir_io.read_metrics(args.run)
    result = {"run": str(args.run), "wall_s": max(r["wall_s"] for r in rows), "chunks": max(r["chunk"] for r in rows)}
    result["batch_step_us"] = step_times(rows, cfg.train.trials)
    if args.against:
        # Both read through load_batch, which maps the leaf names of earlier checkpoint layouts onto today's and
        # fills the fields added since with a fresh learner's values: only the leaves the older file holds compare.
        loaded = [run_dir_io.load_batch(d, run_dir_io.read_config(d)) for d in (args.run, args.against)]
        (mine, mine_chunk), (theirs, theirs_chunk) = loaded
        a, b = checkpoint.flatten({"states": mine.states}), checkpoint.flatten({"states": theirs.states})
        held = stored_leaves(checkpoint.list_checkpoints(args.against)[-1], b)
        differ = sorted(k for k in held if k not in a or not np.array_equal(a[k], b[k]))
        old = run_dir_io.read_metrics(args.against)
        unequal = sum(not same_row(x, y) for x, y in zip(rows, old, strict=False)) + abs(len(rows) - len(old))
        result["against"] = {
            "run": str(args.against),
            "checkpoint_chunks": [mine_chunk, theirs_chunk],
            "checkpoint_leaves": len(held),
            "checkpoint_leaves_filled": len(b) - len(held),
            "checkpoint_leaves_differing": differ,
            "metrics_rows": [len(rows), len(old)],
            "metrics_rows_differing": unequal,
        }
    result["code"] = throughput.code_version()
    throughput.write_result(result, "table2-run", args.json)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
