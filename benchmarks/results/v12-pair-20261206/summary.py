"""The median time of one batch step at 8 learners in each training run under loop/, from its metrics' wall times."""

import sys
from pathlib import Path

import numpy as np

from reach_jax.store import run_dir as run_dir_io

TRIALS = 30_000  # pair.sh's --trials


def batch_step_us(run: Path) -> tuple[float, int]:
    """Median wall time [us] of one batch step over the chunks that all 8 learners ran, and how many."""
    by_chunk: dict[int, list[dict]] = {}
    for row in run_dir_io.read_metrics(run):
        by_chunk.setdefault(row["chunk"], []).append(row)
    chunks = [by_chunk[c] for c in sorted(by_chunk)]
    wall = np.array([c[0]["wall_s"] for c in chunks])
    steps = np.array([max(r["steps"] for r in c) for c in chunks])
    full = [i for i, c in enumerate(chunks[1:]) if all(r["trials"] < TRIALS for r in c)]
    per_step = np.diff(wall)[full] / np.diff(steps)[full]
    return float(np.median(per_step) * 1e6), len(full)


if __name__ == "__main__":
    root = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "loop")
    for run in sorted(root.iterdir()):
        us, n = batch_step_us(run)
        print(f"{run.name:10s} {us:6.2f} us a batch step (median of {n} chunks)")
