"""What the installed libraries would give in place of our own code (issue 50; docs/development.md's table).

`python benchmarks/libraries.py [--json PATH]`

- Checkpoints: writing and reading `runs/table2`'s final checkpoint (8 learners) with `store.checkpoint` and with
  orbax's StandardCheckpointer, in the same process, median of REPEATS each, and the bytes on disk.
- The progress bar's estimate: on the clocks of committed runs (each chunk's `wall_s`), the time left that a
  rate-based bar (tqdm's and rich's: items left over the recent rate, here trials over the last RATE_CHUNKS chunks)
  would show, against the truth, at 25%, 50% and 75% of the run; `train.progress.LearnerEta`'s errors on the same
  runs are in tests/test_progress.py and docs/how-it-works.md.
Writes benchmarks/results/libraries-<UTC time>.json unless --json names one.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np
import orbax.checkpoint as ocp

from reach_jax.store import checkpoint
from reach_jax.store import run_dir as run_dir_io

ROOT = Path(__file__).resolve().parent.parent
REPEATS = 5
RATE_CHUNKS = 20  # the recent window of a rate-based bar (tqdm smooths over a similar span)
RUNS = ("table2", "heldout", "heldout_round2", "dev_gain", "search_heldout")
AT = (0.25, 0.5, 0.75)  # shares of the run's wall time


def _median_time(fn) -> float:
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def checkpoints() -> dict:
    """Write and read times [s] and sizes [bytes] of one run's checkpoint, ours and orbax's."""
    run = ROOT / "runs" / "table2"
    path = checkpoint.list_checkpoints(run)[-1]
    tree = {k: v for k, v in np.load(path).items() if k != "__meta__"}
    with tempfile.TemporaryDirectory() as tmp:
        ours, theirs = Path(tmp) / "ours", Path(tmp) / "orbax"
        orbax = ocp.StandardCheckpointer()
        counter = iter(range(10**6))

        def orbax_save():
            orbax.save(theirs / f"c{next(counter)}", tree)
            orbax.wait_until_finished()

        out = {
            "ours_write_s": _median_time(lambda: checkpoint.save(ours, 1, tree, {})),
            "orbax_write_s": _median_time(orbax_save),
        }
        saved = ours / checkpoint.CHECKPOINT_DIR / "chunk_0000001.npz"
        out["ours_read_s"] = _median_time(lambda: dict(np.load(saved)))
        first = theirs / "c0"
        out["orbax_read_s"] = _median_time(lambda: orbax.restore(first))
        out["ours_bytes"] = saved.stat().st_size
        out["orbax_bytes"] = sum(p.stat().st_size for p in first.rglob("*") if p.is_file())
        out["orbax_files"] = sum(1 for p in first.rglob("*") if p.is_file())
    out["leaves"] = len(tree)
    return out


def rate_eta(run: str) -> dict:
    """A rate-based bar's relative error (estimate / truth - 1) at each share of a committed run's wall time."""
    rows = run_dir_io.read_metrics(ROOT / "runs" / run)
    cfg = run_dir_io.read_config(ROOT / "runs" / run)
    chunks: dict[int, list[dict]] = {}
    for r in rows:
        chunks.setdefault(r["chunk"], []).append(r)
    order = sorted(chunks)
    wall = np.array([chunks[c][0]["wall_s"] for c in order])
    done = np.array([sum(min(r["trials"], cfg.train.trials) for r in chunks[c]) for c in order], dtype=float)
    total = cfg.train.trials * len(chunks[order[0]])
    errors = {}
    for share in AT:
        i = int(np.searchsorted(wall, share * wall[-1]))
        j = max(0, i - RATE_CHUNKS)
        rate = (done[i] - done[j]) / (wall[i] - wall[j])
        errors[str(share)] = float(((total - done[i]) / rate) / (wall[-1] - wall[i]) - 1.0)
    return errors


def main(argv=None) -> int:
    """Measure and write the JSON."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    result = {
        "checkpoint": checkpoints(),
        "rate_eta_error": {run: rate_eta(run) for run in RUNS},
        "jax": jax.__version__,
        "orbax": ocp.__version__ if hasattr(ocp, "__version__") else None,
    }
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    out = args.json or ROOT / "benchmarks" / "results" / f"libraries-{stamp}.json"
    out.write_text(json.dumps(result, indent=1) + "\n")
    json.dump(result, sys.stdout, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
