"""Is training the same bit for bit: a short run of every kind of learner, and two such runs compared.

    python benchmarks/bits.py make OUT [-- TRAIN_FLAGS...]   # e.g. -- --config recipes/round4_pick.json
    python benchmarks/bits.py compare A B

`make` trains the four paper conditions x 2 networks and a three-block protocol (null, viscous with catch trials,
null) for 600 trials each, in 2,000-step chunks, with a snapshot after every chunk and a trial log: every code
path of the training step, the protocol switch and the logs, in about a minute. Run it with two versions of the
code (a `git worktree` of the older one, started from its folder) and `compare` the two folders: every checkpoint
file's every leaf, every metrics row (wall time aside) and every trial-log file must be equal.
"""

from __future__ import annotations

import argparse
import gzip
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

PROTOCOL = [
    {"trials": 200, "condition": "none"},
    {"trials": 200, "condition": "viscous", "catch": 0.1},
    {"trials": 200, "condition": "none"},
]
FLAGS = [
    "--trials", "600", "--seeds", "2", "--conditions", "none,viscous,random,random_nopast",
    "--protocol", "three", "--set", f"protocols.three={json.dumps(PROTOCOL)}",
    "--keep-every", "1", "--trial-log-every", "7", "--chunk-steps", "2000", "--quiet",
]  # fmt: skip


def make(out: Path, extra: list[str]) -> None:
    """Train the short run into `out` with the code importable from the working directory."""
    cmd = [sys.executable, "-m", "reach_jax.train", *FLAGS, *extra, "--out", str(out)]
    subprocess.run(cmd, check=True)


def _metrics(run: Path) -> list[list]:
    """Every metrics row of a run as its (column, value) pairs in the file's order, wall time dropped."""
    rows, columns = [], None
    with gzip.open(run / "metrics.jsonl.gz", "rt") as f:
        for line in f:
            r = json.loads(line)
            if isinstance(r, dict):
                columns = r.get("columns", columns)
                continue
            rows.append([(k, v) for k, v in zip(columns, r, strict=True) if k != "wall_s"])
    return rows


def compare(a: Path, b: Path) -> list[str]:
    """The differences between two runs' checkpoints, metrics and trial logs; empty when they are equal."""
    diffs, leaves = [], 0
    names = sorted(p.name for p in (a / "checkpoints").glob("*.npz"))
    if names != sorted(p.name for p in (b / "checkpoints").glob("*.npz")):
        diffs.append("different checkpoint files")
    for name in names:
        with np.load(a / "checkpoints" / name) as x, np.load(b / "checkpoints" / name) as y:
            keys = set(x.files) - {"__meta__"}
            if keys != set(y.files) - {"__meta__"}:
                only = sorted(keys ^ (set(y.files) - {"__meta__"}))
                diffs.append(f"{name}: leaves in one run only: {', '.join(only)}")
            for k in sorted(keys & set(y.files)):
                leaves += 1
                if not np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f"):
                    diffs.append(f"{name}: {k}")
    ma, mb = _metrics(a), _metrics(b)
    if ma != mb:
        diffs.append(
            f"metrics: {sum(x != y for x, y in zip(ma, mb, strict=False)) + abs(len(ma) - len(mb))} rows differ"
        )
    trials = sorted(p.relative_to(a) for p in (a / "trials").rglob("*") if p.is_file())
    for t in trials:
        if not (b / t).is_file() or (a / t).read_bytes() != (b / t).read_bytes():
            diffs.append(f"trial log {t}")
    print(f"{len(names)} checkpoints ({leaves} leaves), {len(ma)} metrics rows, {len(trials)} trial files compared")
    return diffs


def main(argv=None) -> int:
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    m = sub.add_parser("make", help="train the short run")
    m.add_argument("out", type=Path)
    m.add_argument("train_flags", nargs=argparse.REMAINDER, help="after --: more flags for reach_jax.train")
    c = sub.add_parser("compare", help="compare two short runs")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = p.parse_args(argv)
    if args.command == "make":
        make(args.out, [f for f in args.train_flags if f != "--"])
        return 0
    diffs = compare(args.a, args.b)
    print("identical" if not diffs else "DIFFERENT:\n  " + "\n  ".join(diffs[:40]))
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
